"""Tiny in-test fakes of the stand's protocols (acquisition/protocols.py) for the campaign tests.

A single-degree-of-freedom specimen on a shaker whose base acceleration is
``gain_m_s2_per_vpp(f) · drive``; a free vibration at the natural frequency follows every
frequency change and decays with ``τ = Q / (π f_n)``, weighted by how close the drive is to
resonance. Each record is seeded from ``(seed, step index, record within the step)``, so a
resumed campaign draws what an uninterrupted one does.

Run as a script it is a campaign process for the crash tests:
``python campaign_fakes.py OUT.h5 [--resume] [--slow]`` (kill points through ``VIBID_KILL_AT``;
``--slow``: each record takes 0.1 s of real time).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta

import numpy as np

from vibid.acquisition.protocols import Reading, Stand
from vibid.hardware_mocks.records import Transient, synthetic_step
from vibid.setup_model import Excitation, example_setup


def sdof_h(f_hz, fn_hz: float = 80.0, eta: float = 0.01):
    """Absolute-acceleration transmissibility of a base-driven oscillator with loss factor η."""
    r = np.asarray(f_hz, float) / fn_hz
    return (1 + 1j * eta) / (1 - r**2 + 1j * eta)


class VirtualClock:
    def __init__(self):
        self.t = 0.0
        self.slept_s = 0.0
        self.since_mark_s = 0.0  # summed from the last mark, so equal steps give equal sums

    def now_s(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.t += seconds
            self.slept_s += seconds
            self.since_mark_s += seconds

    def mark(self) -> None:
        self.since_mark_s = 0.0


class FakeGenerator:
    """Logs every command; ``max_vpp_seen`` is the largest drive ever commanded."""

    def __init__(self, clock):
        self.clock = clock
        self.log: list[tuple] = []
        self._f = 1000.0
        self._vpp = 0.0
        self._on = False
        self.max_vpp_seen = 0.0

    @property
    def frequency_hz(self):
        return self._f

    @frequency_hz.setter
    def frequency_hz(self, value):
        self.log.append(("freq", float(value)))
        self._f = float(value)
        self.clock.mark()

    @property
    def amplitude_vpp(self):
        return self._vpp

    @amplitude_vpp.setter
    def amplitude_vpp(self, value):
        self.log.append(("vpp", float(value)))
        self._vpp = float(value)
        self.max_vpp_seen = max(self.max_vpp_seen, self._vpp)

    @property
    def output_enabled(self):
        return self._on

    @output_enabled.setter
    def output_enabled(self, value):
        self.log.append(("output", bool(value)))
        self._on = bool(value)

    def shutdown(self):
        self.log.append(("shutdown",))
        self._on = False

    def close(self):
        self.shutdown()


@dataclass
class FakeDaq:
    generator: FakeGenerator
    clock: VirtualClock
    sample_rate_hz: float = 25600.0
    seed: int = 0
    fn_hz: float = 80.0
    eta: float = 0.01
    gain: object = 25.0  #: m/s² per Vpp, a number or a function of f
    noise_rel: float = 4e-4
    clock_offset_ppm: float = 40.0
    transient_scale: float = 0.5
    clip_m_s2: float | None = None
    step: int = -1
    records_in_step: int = 0
    fail_at: tuple | None = None  #: (step, exception instance) raised by acquire
    wall_delay_s: float = 0.0  #: real time each acquisition takes (signal tests)
    acquisitions: list = field(default_factory=list)

    def base_amplitude(self, f):
        g = self.gain(f) if callable(self.gain) else self.gain
        return g * self.generator.amplitude_vpp if self.generator.output_enabled else 0.0

    def acquire(self, n_samples: int) -> Reading:
        if self.fail_at is not None and self.fail_at[0] == self.step:
            raise self.fail_at[1]
        if self.wall_delay_s:
            import time

            time.sleep(self.wall_delay_s)
        g = self.generator
        f = g.frequency_hz
        h = complex(
            sdof_h(f * (1 + 1e-6 * self.clock_offset_ppm), self.fn_hz, self.eta)
        )  # as played
        amp = self.base_amplitude(f)
        tau = 1.0 / (math.pi * self.fn_hz * self.eta)
        elapsed = self.clock.since_mark_s
        closeness = 1.0 / (1.0 + ((f - self.fn_hz) / (self.fn_hz * self.eta)) ** 2)
        t_amp = self.transient_scale * abs(h) * amp * closeness * math.exp(-elapsed / tau)
        rng = np.random.default_rng([self.seed, self.step + 1, self.records_in_step])
        self.records_in_step += 1
        base, resp = synthetic_step(
            f,
            h,
            sample_rate_hz=self.sample_rate_hz,
            n_samples=n_samples,
            base_amplitude_m_s2=max(amp, 1e-9),
            base_phase_rad=float(rng.uniform(0, 2 * np.pi)),
            clock_offset_ppm=self.clock_offset_ppm,
            noise_std_m_s2=(self.noise_rel * 5.0,) * 2,
            transient=Transient(t_amp, tau, self.fn_hz) if t_amp > 0 else None,
            clip_m_s2=self.clip_m_s2,
            rng=rng,
        )
        t0 = datetime(2026, 1, 1, tzinfo=UTC) + timedelta(seconds=self.clock.now_s())
        self.clock.sleep(n_samples / self.sample_rate_hz)
        over = ()
        if self.clip_m_s2 is not None and np.max(np.abs(resp)) >= self.clip_m_s2:
            over = ("response",)
        self.acquisitions.append((self.step, f, n_samples, amp))
        return Reading(base, resp, self.sample_rate_hz, t0.isoformat(), over)

    def close(self):
        pass


class FakeStand(Stand):
    def begin_step(self, index: int) -> None:
        self.daq.step = index
        self.daq.records_in_step = 0


def fake_stand(**daq_options) -> FakeStand:
    clock = VirtualClock()
    gen = FakeGenerator(clock)
    daq = FakeDaq(gen, clock, **daq_options)
    return FakeStand(gen, daq, clock, "fake")


def short_setup(
    n_steps: int = 10,
    f_lo: float = 40.0,
    f_hi: float = 130.0,
    settle_s: float = 0.05,
    sample_rate_hz: float = 25600.0,
):
    """The example setup with ``n_steps`` frequencies from ``f_lo`` to ``f_hi`` Hz."""
    s = example_setup()
    freqs = tuple(float(f) for f in np.linspace(f_lo, f_hi, n_steps))
    from dataclasses import replace

    return replace(
        s, excitation=Excitation(freqs, settle_s), daq=replace(s.daq, sample_rate_hz=sample_rate_hz)
    )


def fast_config(**timing):
    """A stand configuration with short records (quick tests)."""
    from dataclasses import replace

    from vibid.acquisition.stand_config import StandConfig

    c = StandConfig()
    t = replace(
        c.timing, min_record_s=0.1, min_cycles=10, expected_loss_factor=0.01, max_settle_s=3.0
    )
    return replace(c, timing=replace(t, **timing))


if __name__ == "__main__":  # a campaign process for the crash tests
    import time

    import scipy.special  # noqa: F401 - imported before "ready" (the first fit would), so that

    import vibid.signal  # noqa: F401   kill instants spread over the steps
    from vibid.acquisition.campaign import run_campaign

    out = sys.argv[1]
    print("ready", flush=True)
    t = time.perf_counter()
    slow = 0.1 if "--slow" in sys.argv[2:] else 0.0
    result = run_campaign(
        short_setup(),
        fake_stand(seed=7, wall_delay_s=slow),
        out,
        fast_config(),
        resume="--resume" in sys.argv[2:],
        progress=lambda p: print(p.index, flush=True),
    )
    print("done", result.run_status, result.n_steps, time.perf_counter() - t, flush=True)
