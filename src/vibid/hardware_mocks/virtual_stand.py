"""The virtual stand: the real drivers in front of a simulated generator, a fake DAQ task
and the virtual specimen.

:func:`open_simulated_stand` builds a :class:`~vibid.acquisition.protocols.Stand` whose
generator is the real SCPI driver (:mod:`vibid.acquisition.generator`) on
``serial_for_url("vibidsim://NAME")`` and whose DAQ is the real NI-DAQmx driver
(:mod:`vibid.acquisition.daq`) on a :class:`~vibid.hardware_mocks.fake_daq.FakeTask`. What
the task records is :meth:`VirtualStand.record`: the generator's *current* state (the
frequency it really plays, its amplitude, output on or off) through the shaker and the
virtual specimen, so a wrong command gives a wrong record.

Record model (all in m/s²; :func:`~vibid.hardware_mocks.records.synthetic_step` does the
synthesis, as for ``vibid simulate``):

* base amplitude ``shaker_m_s2_per_v × Vpp`` (0 with the output off: noise only);
  response ``H(f_played) ×`` base, ``H`` from the :class:`~vibid.hardware_mocks.specimen.
  VirtualSpecimen` (the true parameters and undeclared effects of ``simulated``);
* white noise of ``noise × drive.target_base_m_s2`` on each channel, DC, drift and
  harmonics as :class:`~vibid.hardware_mocks.simulated_session.StandConditions`;
* IEPE settling: an offset of :attr:`VirtualStand.iepe_offset_m_s2` on both channels when
  the DAQ task is created, decaying with :attr:`VirtualStand.iepe_settle_s` (given to the
  record as the offset and slope at its start);
* a transient when the last change of the generator (frequency, amplitude, output) is less
  than ~30 decay times of the nearest mode ago: the free vibration of that mode, at its
  natural frequency and decay rate, starting with the jump of the mode's steady response
  (a one-mode resonance ``|H(f_n)| iβ f² / (f_n² − f² + iβ f_n²)`` times the base
  amplitude, before and after the change) and decayed over the time since the change;
* clipping at each DAQ channel's range (in the fake task), which reports an overload;
* injected faults (``simulated.faults``): the generator's (``no_reply``, ``error``,
  ``drop``: :meth:`~vibid.hardware_mocks.sim_generator.SimulatedGenerator.sim_schedule`) and
  the DAQ's ``overload``: a shock on the response channel (a knock on the table: a 2 ms
  half-sine of :data:`SHOCK_RANGES` times the channel's range, in the middle of the record),
  which the fake task clips and reports, in the first record after the ``at_step``-th
  frequency command, or of the campaign's step ``at_index``. Each fires once.

Randomness is seeded per acquisition from (``simulated.seed``, the step index, the number
of acquisitions in the step) when the campaign announces its steps
(:meth:`SimulatedStand.begin_step`), else from (seed, the commanded frequency in mHz, the
number of acquisitions since the last frequency command), so a resumed campaign that plays
the same steps draws the same noise. The transient depends on the generator's state before
the step (see above): a resumed step equals the uninterrupted one to the last bit only when
its settle lets the transient fall below ``exp(-30)`` (:data:`TRANSIENT_DECAYS`). The clock is a :class:`VirtualClock`
(sleeping advances it, no real waiting) unless ``realtime``.

Notes (where this differs from a real stand): the shaker's gain is flat and has no phase,
the base has no transient, only the nearest mode rings after a change, and (without
``begin_step``) two steps at the same frequency draw the same noise.
"""

from __future__ import annotations

import math
import urllib.parse
from dataclasses import dataclass

import numpy as np

from vibid.acquisition.daq import NiDaq
from vibid.acquisition.generator import open_generator
from vibid.acquisition.protocols import Clock, Stand, WallClock
from vibid.acquisition.stand_config import StandConfig, StandConfigError
from vibid.errors import VibidError
from vibid.hardware_mocks.fake_daq import G_M_S2, DeviceLimits, FakeTask
from vibid.hardware_mocks.records import Transient, synthetic_step
from vibid.hardware_mocks.sim_generator import (
    FAULT_KINDS,
    ScheduledFault,
    SimulatedGenerator,
    register,
)
from vibid.hardware_mocks.simulated_session import StandConditions
from vibid.hardware_mocks.specimen import VirtualSpecimen
from vibid.setup_model import Setup

#: a transient (or the IEPE offset) below exp(-30) of its start is left out: exactly 0, so
#: that a stand reopened after a long settle records the same samples as one that ran on
TRANSIENT_DECAYS = 30.0
#: faults of the DAQ side (the rest are the generator's, ``sim_generator.FAULT_KINDS``)
DAQ_FAULT_KINDS = ("overload",)
#: an injected overload's shock peak, in multiples of the response channel's range
SHOCK_RANGES = 3.0
#: its duration (a half sine), s
SHOCK_S = 0.002


class VirtualClock:
    """Virtual time: :meth:`sleep` advances it at once (``protocols.Clock``)."""

    def __init__(self, start_s: float = 0.0):
        self._now_s = float(start_s)

    def now_s(self) -> float:
        return self._now_s

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self._now_s += float(seconds)


class VirtualStand:
    """The simulated instruments and the specimen they act on.

    Parameters
    ----------
    setup : the declared setup (the specimen's geometry, sensors, sample rate, frequencies).
    config : the stand configuration; its ``simulated`` section is the truth.
    clock : the stand's clock.
    accuracy : mesh accuracy of the virtual specimen.
    fired : the places (in ``simulated.faults``) of the faults that fired already; they are
        not scheduled again, and the ones that fire now are added.
    """

    iepe_offset_m_s2: float = 0.5  #: offset when the IEPE excitation switches on, m/s²
    iepe_settle_s: float = 0.2  #: its decay time, s

    def __init__(
        self,
        setup: Setup,
        config: StandConfig,
        *,
        clock: Clock,
        accuracy: str = "fine",
        fired: set[int] | None = None,
    ):
        sim = config.simulated
        self.setup = setup
        self.config = config
        self.clock = clock
        self.conditions = StandConditions()
        self.instrument = SimulatedGenerator(
            clock, clock_offset_ppm=sim.clock_offset_ppm, changed_at_s=clock.now_s()
        )
        if fired is not None:
            self.instrument.sim_fired = fired  # shared: a fault that fired stays fired
        known = FAULT_KINDS + DAQ_FAULT_KINDS
        #: scheduled DAQ faults (the generator's own schedule keeps the rest)
        self.daq_faults: list[ScheduledFault] = []
        for key, fault in enumerate(sim.faults):
            kind = fault.get("kind") if isinstance(fault, dict) else None
            if kind not in known:
                raise ValueError(f"unknown fault kind {kind!r}, expected one of {', '.join(known)}")
            if key in self.instrument.sim_fired:
                continue
            if kind in DAQ_FAULT_KINDS:
                self.daq_faults.append(ScheduledFault.of(fault, key))
            else:
                self.instrument.sim_schedule(fault, key=key)
        self.truth = true_parameters(config)
        freqs = (
            setup.excitation.frequencies_hz if setup.excitation else (setup.daq.sample_rate_hz / 2,)
        )
        self.specimen = VirtualSpecimen(
            setup,
            self.truth,
            f_max_hz=1.05 * max(freqs),
            accuracy=accuracy,
            effects=tuple(config.simulated.effects),
        )
        self.noise_std_m_s2 = sim.noise * config.drive.target_base_m_s2
        self.daq_opened_at_s = clock.now_s()
        self._acquisitions = 0
        self._last_frequency_commands = -1
        self._step: int | None = None

    def prefetch(self) -> None:
        """Solve the specimen now at every frequency the setup will play and at each mode's
        peak, so that recording does not have to (a paced stand keeps its timing)."""
        # the frequency as the driver sends it (12 significant digits), then as played
        played = [
            self.instrument.played_at(float(format(f, ".12g")))
            for f in self.setup.excitation.frequencies_hz
        ]
        f_n, _ = self.specimen.modes
        self.specimen.h(np.concatenate([played, f_n[f_n <= self.specimen.f_max_hz]]))

    def task_factory(self) -> FakeTask:
        """A new fake DAQ task on this stand (the ``task_factory`` of the DAQ driver)."""
        self.daq_opened_at_s = self.clock.now_s()
        return FakeTask(self, DeviceLimits(device=self.config.daq.device))

    def begin_step(self, index: int) -> None:
        """The campaign starts step ``index``: seed its acquisitions from it from now on
        (and fire the faults scheduled ``at_index`` of it)."""
        self._step, self._acquisitions = int(index), 0
        self.instrument.sim_step_index = int(index)

    def _rng(self) -> np.random.Generator:
        """This acquisition's random numbers: from (seed, step index, acquisitions in the
        step) once :meth:`begin_step` was called, else (seed, commanded frequency in mHz,
        acquisitions since the last frequency command)."""
        gen, seed = self.instrument, self.config.simulated.seed
        if self._step is not None:
            key = [seed, 0, self._step, self._acquisitions]
        else:
            if gen.frequency_commands != self._last_frequency_commands:
                self._last_frequency_commands, self._acquisitions = gen.frequency_commands, 0
            key = [seed, 1, int(round(gen.frequency_hz * 1e3)), self._acquisitions]
        self._acquisitions += 1
        return np.random.default_rng(key)

    def record(self, n_samples: int, sample_rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Both accelerometers (base, response), m/s², recorded from now."""
        gen, sim, c = self.instrument, self.config.simulated, self.conditions
        now = self.clock.now_s()
        rng = self._rng()
        f = gen.played_frequency_hz
        amplitude = sim.shaker_m_s2_per_v * gen.drive_vpp
        settled = (now - self.daq_opened_at_s) / self.iepe_settle_s
        iepe = self.iepe_offset_m_s2 * math.exp(-settled) if settled < TRANSIENT_DECAYS else 0.0
        base, response = synthetic_step(
            f,
            complex(self.specimen.h(f)[0]),
            sample_rate_hz=sample_rate_hz,
            n_samples=n_samples,
            base_amplitude_m_s2=amplitude,
            base_phase_rad=float(rng.uniform(0, 2 * np.pi)),
            dc_m_s2=(c.dc_m_s2[0] + iepe, c.dc_m_s2[1] + iepe),
            drift_m_s2_per_s=(
                c.drift_m_s2_per_s[0] - iepe / self.iepe_settle_s,
                c.drift_m_s2_per_s[1] - iepe / self.iepe_settle_s,
            ),
            harmonics_db=c.harmonics_db,
            noise_std_m_s2=(self.noise_std_m_s2,) * 2,
            transient=self._transient(now, rng),
            rng=rng,
        )
        if self._overload_due():
            response = response + self._shock(n_samples, sample_rate_hz)
        return base, response

    def _overload_due(self) -> bool:
        """Whether an injected ``overload`` fires in this record (then it has fired)."""
        command = self.instrument.frequency_commands - 1  # this instrument's frequency command
        for fault in self.daq_faults:
            if fault.due(command, self._step):
                self.daq_faults.remove(fault)
                self.instrument.sim_fired.add(fault.key)
                return True
        return False

    def _shock(self, n_samples: int, sample_rate_hz: float) -> np.ndarray:
        """A knock on the table, seen by the response: a half sine of ``SHOCK_S`` peaking at
        ``SHOCK_RANGES`` times the channel's range, in the middle of the record."""
        peak = SHOCK_RANGES * self.config.daq.range_g * G_M_S2
        t = (np.arange(n_samples) - n_samples // 2) / sample_rate_hz
        return np.where(
            (t >= 0) & (t < SHOCK_S), peak * np.sin(np.pi * np.clip(t, 0, SHOCK_S) / SHOCK_S), 0.0
        )

    def _transient(self, now_s: float, rng: np.random.Generator) -> Transient | None:
        gen = self.instrument
        f_n, gamma = self.specimen.nearest_mode(gen.played_frequency_hz)
        elapsed = now_s - gen.changed_at_s
        if not gamma > 0 or gamma * elapsed > TRANSIENT_DECAYS:
            return None
        f_old, vpp_old, on_old = gen.previous
        shaker = self.config.simulated.shaker_m_s2_per_v
        jump = abs(
            self._modal(gen.played_frequency_hz, f_n, gamma) * shaker * gen.drive_vpp
            - self._modal(f_old, f_n, gamma) * shaker * (vpp_old if on_old else 0.0)
        )
        return Transient(
            jump * math.exp(-gamma * elapsed),
            decay_s=1.0 / gamma,
            frequency_hz=f_n,
            phase_rad=float(rng.uniform(0, 2 * np.pi)),
        )

    def _modal(self, f_hz: float, f_n: float, gamma: float) -> complex:
        """The one-mode resonance of the mode at ``f_n`` (peak ``|H(f_n)|``) at ``f_hz``: base
        excitation loads a mode in proportion to ``f²``, so it vanishes at low frequency."""
        beta = gamma / (math.pi * f_n)
        peak = abs(complex(self.specimen.h(f_n)[0]))
        return peak * 1j * beta * f_hz**2 / (f_n**2 - f_hz**2 + 1j * beta * f_n**2)


def true_parameters(config: StandConfig) -> dict[str, float]:
    """The virtual specimen's parameters: ``simulated.params`` and every undeclared
    effect's, e.g. ``{"D": ..., "k_theta_N_per_rad": ...}``. An effect that may occur more
    than once (``stand_resonance``) takes a list of instances, each with its parameters
    unsuffixed (``[{"f_hz": 660, "q": 30, "theta_rad_per_m": 0.3}, ...]``); the k-th
    instance's names get the suffix ``_k``."""
    from vibid.identify.effects import EFFECTS
    from vibid.parameters import flat_values

    sim = config.simulated
    out = dict(sim.params)
    for name, values in sim.effects.items():
        where = f"simulated.effects.{name}"
        if name not in EFFECTS:
            raise StandConfigError(f"{where}: unknown effect (known: {', '.join(EFFECTS)})")
        try:
            out |= flat_values(name, values if isinstance(values, list) else [values])
        except ValueError as exc:
            raise StandConfigError(f"{where}: {exc}") from None
    return out


@dataclass
class SimulatedStand(Stand):
    """A :class:`~vibid.acquisition.protocols.Stand` on the virtual stand ``virtual``; the
    campaign may call :meth:`begin_step` (a real stand has no such method)."""

    virtual: VirtualStand | None = None

    def begin_step(self, index: int) -> None:
        """Seed the coming step's records from its index (a resumed run draws the same)."""
        self.virtual.begin_step(index)


_STANDS: dict[str, VirtualStand] = {}
#: per stand name, the faults of ``simulated.faults`` (by place) that have fired in this
#: process: a stand reopened under the same name (a campaign retried after a fault, as a
#: resume) does not fire them again, as a real instrument's glitch does not recur on cue
_FIRED: dict[str, set[int]] = {}


def lookup_stand(name: str) -> VirtualStand:
    """The virtual stand opened last as ``vibidsim://name`` (for tests and demos)."""
    return _STANDS[name]


def open_simulated_stand(
    setup: Setup, config: StandConfig, *, realtime: bool = False, accuracy: str = "fine"
) -> Stand:
    """The simulated stand: the real drivers in front of the virtual specimen.

    ``config.generator.url`` must be ``vibidsim://NAME``; ``realtime`` paces it on the wall
    clock (settle and record take their real time; the specimen is solved at every step's
    frequency first, which takes a while on a fine mesh), otherwise time is virtual. The
    :class:`VirtualStand` behind it is ``stand.virtual`` and :func:`lookup_stand` ``(NAME)``.
    Each injected fault of ``simulated.faults`` fires once per ``NAME`` in a process: a
    stand reopened under that name (a retried campaign) runs without the faults that fired,
    and finds the generator as the last one left it where its output was still on (a
    dropped link: :meth:`~vibid.hardware_mocks.sim_generator.SimulatedGenerator.sim_left_playing`).
    """
    url = config.generator.url
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "vibidsim" or not parts.netloc:
        raise StandConfigError(
            f"generator.url: the simulated stand needs vibidsim://NAME, got {url!r}"
        )
    left = _STANDS.get(parts.netloc)
    try:
        virtual = VirtualStand(
            setup,
            config,
            clock=WallClock() if realtime else VirtualClock(),
            accuracy=accuracy,
            fired=_FIRED.setdefault(parts.netloc, set()),
        )
    except StandConfigError:
        raise
    except (ValueError, VibidError) as exc:  # a bad fault or parameter of the simulated section
        raise StandConfigError(f"simulated: {exc}") from None
    virtual.specimen.modes  # noqa: B018 - solved now, not during the first record
    if realtime:
        virtual.prefetch()
    if left is not None and left.instrument.output_on:
        # the last stand of this name left its generator playing (its link dropped): the
        # reopened link finds it still driving, until the campaign switches it off
        virtual.instrument.sim_left_playing(left.instrument)
    register(parts.netloc, virtual.instrument)
    _STANDS[parts.netloc] = virtual
    generator = open_generator(
        url,
        baudrate=config.generator.baudrate,
        timeout_s=config.generator.timeout_s,
        max_vpp=config.drive.max_vpp,
    )
    try:
        daq = NiDaq.from_setup(setup, config.daq, task_factory=virtual.task_factory)
    except BaseException:
        generator.close()
        raise
    return SimulatedStand(
        generator,
        daq,
        virtual.clock,
        description=f"simulated stand {url} (virtual specimen, fake NI-DAQmx task)",
        virtual=virtual,
    )
