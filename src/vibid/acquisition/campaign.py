"""The campaign runner: executes the stepped-sine plan on a stand and records the session.

:func:`run_campaign` drives the commands of :func:`vibid.acquisition.plan.stepped_sine`
through the stand's protocols (:mod:`vibid.acquisition.protocols`) and appends each step to
the session file as soon as it is complete (the writer makes every append atomic, so a
process killed at any instant leaves a valid file; :mod:`vibid.session.writer`).

Per step:

1. the generator plays the step's frequency (the drive level is carried from the step
   before), the stand waits the plan's settle time and records the step; the step before
   is written to the file during this settle (its time counts towards the settle), so the
   file costs the stand no time of its own. A step is in the file, and reported, once the
   next frequency plays; a process killed before that loses it (resume measures it again),
   Ctrl-C and faults write it before closing;
2. **base-amplitude control**: while the base amplitude is off the target by more than the
   tolerance, the drive is scaled by ``target / measured`` (never above ``max_vpp``, at most
   ×10 per move), the stand settles again and measures with a short record (a quarter of
   ``min_record_s``, whole cycles, at least 4); once within tolerance the step is recorded
   again. If the maximum drive cannot reach the target, the step is recorded there and its
   ``vibid_note`` attribute says so (the AFC is a ratio and stays valid);
3. the record is fitted by the signal stage (:func:`vibid.signal.afc_from_records`) for the
   progress line and for the plan's settle rule (an unsettled record is recorded again after
   the damping settle). Unsettled: the signal stage's ``unsettled`` flag, or its
   ``ringing`` flag (a free vibration a few hertz off the drive frequency that dies out
   and leaks more than 3 std into a channel's phasor: the halves test misses it, since the
   ring raises the noise it is judged against);
4. **abort limit**: any record whose response peak exceeds ``abort_response_m_s2`` switches
   the output off at once; that record is written as an ``aborted`` step and the session is
   closed ``aborted`` with the reason;
5. a record with an overloaded input is written with status ``overload``.

How a campaign ends (``run_status`` of the session): ``complete``; ``interrupted`` by Ctrl-C,
SIGTERM (where the platform has it), a ``stop`` request or an unexpected error (the partial
step is not written; ``--resume`` continues); ``aborted`` by the abort limit or a stand fault
(a :class:`~vibid.errors.VibidError` from a driver). The generator output is off on every
one of these paths, and is switched off first thing at the start and on resume.

Each written step carries vibid's own attributes ``vibid_drive_vpp`` (the drive of its
record), ``vibid_settle_s`` (time since the frequency change when the record began, s),
``vibid_unsettled_first`` (its first record was unsettled: the next step settles longer),
``vibid_resettled`` (it was recorded again after the damping settle) and, where needed,
``vibid_note``; a resumed campaign starts from the last step's drive and settle state, so it
makes the same commands as an uninterrupted one.
"""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from vibid.acquisition.plan import (
    Pause,
    PlanError,
    StepCommand,
    StepOutcome,
    StepSource,
    plan_summary,
    record_samples,
    stepped_sine,
)
from vibid.acquisition.protocols import Reading, Stand
from vibid.acquisition.stand_config import StandConfig
from vibid.errors import VibidError
from vibid.session import SessionWriter, read_session
from vibid.setup_model import Setup

log = logging.getLogger(__name__)

__all__ = ["CampaignError", "CampaignResult", "StepProgress", "run_campaign"]

#: Moves of the drive before a step is recorded at the level reached.
MAX_CONTROL_MOVES = 8
#: The drive moves by at most this factor at once (a silent base channel must not jump to max).
MAX_DRIVE_FACTOR = 10.0


class CampaignError(VibidError):
    """A campaign that cannot start or resume (one line naming the file)."""


@dataclass(frozen=True)
class StepProgress:
    """What the runner reports after each written step.

    ``h_abs`` and ``phase_deg`` are the signal stage's |H| and phase of H (degrees, positive
    when the response leads), ``h_std`` its standard uncertainty per real and imaginary
    part; ``eta_s`` the estimated wall time left, s; ``settle_s`` and ``record_s`` the time
    the specimen was driven for this step (its share of the session's ``stand_time_s``).
    """

    index: int
    n_steps: int
    frequency_hz: float
    h_abs: float
    phase_deg: float
    eta_s: float
    status: str = "ok"
    base_m_s2: float = math.nan
    drive_vpp: float = math.nan
    note: str = ""
    h_std: float = math.nan
    settle_s: float = math.nan
    record_s: float = math.nan


@dataclass(frozen=True)
class CampaignResult:
    """How a campaign ended: the file, ``run_status`` (``complete``, ``interrupted``,
    ``aborted``), its one-line reason (empty when complete), the steps the file holds and
    the seconds the specimen was driven over all of them (``stand_time_s`` of the session:
    every step's settle and record time, re-records and earlier runs of a resumed campaign
    included; None if no step says how long it settled); for an adaptive campaign, the
    line its plan stopped with."""

    path: str
    run_status: str
    reason: str
    n_steps: int
    stand_time_s: float | None = None
    #: why a campaign that chooses its steps stopped (target reached, stand-time cap), or ""
    stopped_because: str = ""


class _Stop(KeyboardInterrupt):
    """Raised in the main thread by the SIGTERM handler: ends the campaign like Ctrl-C."""


class _WriteError(VibidError):
    """The session file could not take a step (not a stand fault)."""


@dataclass
class _Measured:
    """One executed command: the record to write and what was learnt."""

    reading: Reading
    status: str
    h: complex
    settled: bool
    base_m_s2: float
    drive_vpp: float
    settle_s: float
    note: str = ""
    abort_reason: str = ""
    h_std: float = math.nan


@dataclass
class _State:
    drive_vpp: float
    output_on: bool = False
    since_change_s: float = 0.0  #: time since the frequency last changed, s
    last_settle_s: float = 0.0  #: ... when the last record began, s


def run_campaign(
    setup: Setup,
    stand: Stand,
    out_path: str | os.PathLike,
    config: StandConfig,
    *,
    resume: bool = False,
    progress: Callable[[StepProgress], Any] | None = None,
    operator: str | None = None,
    notes: str | None = None,
    temperature_c: float | None = None,
    stop: Any = None,
    chooser: StepSource | None = None,
) -> CampaignResult:
    """Run (or with ``resume`` continue) ``setup``'s stepped sine on ``stand`` into ``out_path``.

    Parameters
    ----------
    setup : the declared setup; its excitation is played (with a ``chooser``, its settle
        time is the floor and its frequencies are not played).
    chooser : a :class:`~vibid.acquisition.plan.StepSource` that chooses the steps as the
        campaign goes (an adaptive campaign): its commands are played instead of the
        setup's, the session carries its ``adaptive`` attribute, and a resume compares the
        setup without its excitation (the steps in the file are the truth).
    stand : opened instruments (the caller closes them).
    out_path : the session file: new, or with ``resume`` an interrupted (or aborted) session
        of the same setup, continued from its first missing step.
    config : the stand configuration (drive, timing).
    progress : called with a :class:`StepProgress` after every written step.
    operator, notes : the session's optional root attributes (new sessions only).
    temperature_c : specimen or room temperature, °C, written on every step.
    stop : a ``threading.Event`` or a callable returning True to end the campaign cleanly
        before the next command (``interrupted``).

    Returns
    -------
    :class:`CampaignResult`. Raises :class:`CampaignError` when the file cannot be started or
    resumed (nothing is driven then).
    """
    stand.generator.shutdown()  # a crash may have left the output on
    path = os.fspath(out_path)
    n_steps = _check_playable(setup, config)
    if resume:
        start, drive, near = resume_point(
            path, setup, None if chooser is None else chooser.attribute
        )
        writer = SessionWriter.resume(path)
        if (
            chooser is None and start >= n_steps
        ):  # stopped after its last step, before it was closed
            writer.close("complete")
            return CampaignResult(path, "complete", "", writer.n_steps)
    else:
        start, drive, near = 0, config.drive.initial_vpp, False
        writer = _new_session(path, setup, operator, notes, chooser)
    plan, nominal = _plan(setup, config, chooser, path if resume else None, start, near)
    if not (math.isfinite(drive) and drive > 0):
        drive = config.drive.initial_vpp
    runner = _Runner(stand, config, _State(drive_vpp=min(drive, config.drive.max_vpp)))
    stop_requested = _stop_test(stop)
    play = _Play(stand, runner, writer, plan, progress, nominal, temperature_c)
    play.run(stop_requested)
    return CampaignResult(
        path,
        play.run_status,
        play.reason,
        writer.n_steps,
        getattr(writer, "stand_time_s", None),
        play.stopped_because,
    )


# -- opening the session, planning -----------------------------------------------------------
def _check_playable(setup: Setup, config: StandConfig) -> int:
    """The setup's step count, once its excitation, the drive and the timing are checked
    (before any file is touched)."""
    if setup.excitation is None:
        raise CampaignError("the setup has no excitation: nothing to play")
    n_steps = len(setup.excitation.frequencies_hz)
    _check_drive(config)
    stepped_sine(setup, config)  # checks the timing before any file is touched
    return n_steps


def _new_session(path: str, setup: Setup, operator, notes, chooser) -> SessionWriter:
    """A new session file at ``path`` (never over an existing one), with the chooser's
    ``adaptive`` attribute where there is one."""
    if os.path.exists(path):
        raise CampaignError(
            f"{path}: already exists; a session file is never overwritten "
            "(use --resume to continue an interrupted one)"
        )
    return SessionWriter(
        path,
        setup,
        operator=operator,
        notes=notes,
        adaptive=None if chooser is None else chooser.attribute,
    )


def _plan(setup, config, chooser, resumed: str | None, start: int, near: bool):
    """``(the commands from step start on, each step's nominal settle + record time, s)``:
    the setup's stepped sine, or the chooser's plan (the steps to come are not known then:
    no time left to show)."""
    if chooser is not None:
        return chooser.plan(resumed, start), {}
    plan = stepped_sine(setup, config, start=start, near_resonance=near)
    nominal = {
        c.index: c.settle_s + c.record_s for c in plan_summary(setup, config, start=start).commands
    }
    return plan, nominal


# -- playing the plan ----------------------------------------------------------------------------
class _Play:
    """One run of a plan on a stand: each command played, each measured step written to the
    file while the next one settles (and reported), and the session closed with how the run
    ended (``run_status``, ``reason``; ``stopped_because``: why a plan that chooses its steps
    stopped)."""

    def __init__(self, stand, runner, writer, plan, progress, nominal, temperature_c):
        self.stand, self.runner, self.writer, self.plan = stand, runner, writer, plan
        self.progress, self.nominal, self.temperature_c = progress, nominal, temperature_c
        self.t_start = time.monotonic()
        #: measured, not yet in the file: (command, what was measured, first record unsettled)
        self.pending: list[tuple[StepCommand, _Measured, bool]] = []
        self.run_status, self.reason, self.stopped_because = "interrupted", "stopped on request", ""
        runner.during_settle = self.flush

    def run(self, stop_requested: Callable[[], bool]) -> None:
        """Play, then close the session however the run ends: the output off on every path,
        a completely measured step still written (:func:`_finish`)."""
        try:
            with _sigterm_raises():
                self.play(stop_requested)
                self.flush()
        except _Stop:
            self.run_status, self.reason = "interrupted", "stopped by SIGTERM"
        except KeyboardInterrupt:
            self.run_status, self.reason = "interrupted", "interrupted by the operator (Ctrl-C)"
        except _WriteError as exc:
            self.pending.clear()
            self.run_status, self.reason = "aborted", str(exc)
        except PlanError as exc:
            self.run_status, self.reason = "aborted", f"the plan could not go on: {exc}"
        except VibidError as exc:
            self.run_status, self.reason = "aborted", f"stand fault: {exc}"
        except BaseException as exc:
            self.run_status, self.reason = "interrupted", f"crashed: {type(exc).__name__}: {exc}"
            _finish(self.stand, self.writer, self.run_status, self.reason, self.flush)
            raise
        _finish(self.stand, self.writer, self.run_status, self.reason, self.flush)

    def play(self, stop_requested: Callable[[], bool]) -> None:
        """The plan's commands, one after the other, until it ends (``complete``), a stop is
        requested, or a record is above the abort limit (``aborted``)."""
        first_unsettled = False
        cmd = next(self.plan, None)
        while cmd is not None and not stop_requested():
            if isinstance(cmd, Pause):
                # the plan thinks: every measured step written, the specimen at rest
                self.flush()
                self.stand.generator.shutdown()
                self.runner.state.output_on = False
                cmd = self._next(None)
                continue
            m = self.runner.execute(cmd)
            if cmd.attempt == 0:
                first_unsettled = not m.settled
            if m.abort_reason:
                self.stand.generator.shutdown()
                self.pending.append((cmd, m, first_unsettled))
                self.run_status, self.reason = "aborted", m.abort_reason
                return
            nxt = self._next(StepOutcome(settled=m.settled, reading=m.reading, settle_s=m.settle_s))
            if nxt is None or getattr(nxt, "index", None) != cmd.index:
                self.pending.append((cmd, m, first_unsettled))
            cmd = nxt
        if cmd is None:
            self.run_status, self.reason = "complete", ""

    def _next(self, outcome: StepOutcome | None):
        """The plan's next command after ``outcome``, or None when it ends (and why)."""
        try:
            return self.plan.send(outcome)
        except StopIteration as end:
            self.stopped_because = str(end.value or "")
            return None

    def flush(self) -> None:
        """Write the measured step and report it (while the next one settles)."""
        while self.pending:
            c, m, unsettled = self.pending[0]
            _write(self.writer, c, m, self.temperature_c, unsettled)
            self.pending.pop(0)
            if self.progress is not None:
                elapsed = time.monotonic() - self.t_start
                self.progress(_progress(c, m, self.nominal, elapsed))


def _finish(stand: Stand, writer: SessionWriter, run_status: str, reason: str, flush) -> None:
    """Output off, a completely measured step still in memory written, then the session
    closed with how it ended (each tried even if one before fails)."""
    try:
        stand.generator.shutdown()
    finally:
        try:
            flush()
        except VibidError:
            pass  # the file keeps every earlier step; the close says why it ended
        finally:
            writer.close(run_status, reason or None)
        log.info("campaign %s: %s %s", writer.path, run_status, reason)


# -- executing one command -----------------------------------------------------------------
class _Runner:
    def __init__(self, stand: Stand, config: StandConfig, state: _State):
        self.stand = stand
        self.gen = stand.generator
        self.drive = config.drive
        self.timing = config.timing
        self.state = state
        #: work done while a new frequency settles (writing the step before); its time on
        #: the stand's clock counts towards the settle
        self.during_settle: Callable[[], None] = lambda: None

    def execute(self, cmd: StepCommand) -> _Measured:
        st = self.state
        if cmd.attempt == 0:
            _begin_step(self.stand, cmd.index)
            self.gen.frequency_hz = cmd.frequency_hz
            if not st.output_on:
                self.gen.amplitude_vpp = st.drive_vpp
                self.gen.output_enabled = True
                st.output_on = True
            st.since_change_s = 0.0
            clock = self.stand.clock
            started = clock.now_s()
            self.during_settle()
            spent = clock.now_s() - started
            clock.sleep(max(0.0, cmd.settle_s - spent))
            st.since_change_s = max(cmd.settle_s, spent)
        else:
            self._settle(cmd.settle_s)
        reading, base, abort = self._record(cmd, cmd.n_samples)
        if not abort and cmd.attempt == 0 and not self._within(base):
            reading, base, abort = self._control(cmd, base)
        if abort:
            return self._measured(cmd, reading, base, abort_reason=abort)
        return self._measured(cmd, reading, base)

    def _settle(self, seconds: float) -> None:
        self.stand.clock.sleep(seconds)
        self.state.since_change_s += seconds

    def _record(self, cmd: StepCommand, n: int) -> tuple[Reading, float, str]:
        settled_s = self.state.since_change_s
        reading = self.stand.daq.acquire(n)
        self.state.since_change_s += n / cmd.sample_rate_hz
        self.state.last_settle_s = settled_s
        base = amplitude_m_s2(reading.base_m_s2, cmd.frequency_hz, reading.sample_rate_hz)
        peak = float(np.max(np.abs(reading.response_m_s2))) if reading.response_m_s2.size else 0.0
        abort = ""
        if not peak <= self.drive.abort_response_m_s2:
            self.gen.shutdown()
            self.state.output_on = False
            abort = (
                f"response peak {peak:.4g} m/s2 above the abort limit "
                f"{self.drive.abort_response_m_s2:g} m/s2 at {cmd.frequency_hz:g} Hz (step {cmd.index})"
            )
        return reading, base, abort

    def _within(self, base_m_s2: float) -> bool:
        d = self.drive
        return abs(base_m_s2 / d.target_base_m_s2 - 1.0) <= d.tolerance

    def _control(self, cmd: StepCommand, base: float) -> tuple[Reading, float, str]:
        """Move the drive until the base amplitude is within tolerance, then record the step."""
        d, st = self.drive, self.state
        n_short = record_samples(cmd.frequency_hz, cmd.sample_rate_hz, _short(self.timing))
        for _ in range(MAX_CONTROL_MOVES):
            if self._within(base):
                break
            factor = d.target_base_m_s2 / base if base > 0 else MAX_DRIVE_FACTOR
            new = min(
                d.max_vpp, st.drive_vpp * min(max(factor, 1 / MAX_DRIVE_FACTOR), MAX_DRIVE_FACTOR)
            )
            if new == st.drive_vpp:
                break  # at the maximum drive and still low
            st.drive_vpp = new
            self.gen.amplitude_vpp = new
            self._settle(cmd.settle_s)
            short, base, abort = self._record(cmd, n_short)
            if abort:
                return short, base, abort
        reading, base, abort = self._record(cmd, cmd.n_samples)
        return reading, base, abort

    def _measured(
        self, cmd: StepCommand, reading: Reading, base: float, abort_reason: str = ""
    ) -> _Measured:
        h, h_std, settled = _fit(cmd, reading)
        note = ""
        d = self.drive
        if not abort_reason and not self._within(base):
            note = (
                f"base {base:.4g} m/s2 off the target {d.target_base_m_s2:g} m/s2 "
                f"at drive {self.state.drive_vpp:.4g} Vpp (maximum {d.max_vpp:g} Vpp)"
            )
        if abort_reason:
            status = "aborted"
        elif reading.overloaded:
            status = "overload"
        else:
            status = "ok"
        return _Measured(
            reading,
            status,
            h,
            settled,
            base,
            self.state.drive_vpp,
            self.state.last_settle_s,
            note,
            abort_reason,
            h_std,
        )


def _short(timing):
    """Timing of the control loop's short records."""
    return replace(
        timing, min_record_s=timing.min_record_s / 4, min_cycles=max(4, timing.min_cycles // 4)
    )


#: the drive control measures the amplitude over blocks of about this length, s
AMPLITUDE_BLOCK_S = 0.25


def amplitude_m_s2(x: np.ndarray, frequency_hz: float, sample_rate_hz: float) -> float:
    """Amplitude of the sinusoid at ``frequency_hz`` in ``x``, m/s²: least squares with an
    offset over blocks of about :data:`AMPLITUDE_BLOCK_S` (at least 4 cycles), averaged.

    In blocks because the generator's and the DAQ's clocks differ (up to 200 ppm): over a
    long record the sinusoid drifts in phase against the commanded frequency, and one fit
    over all of it loses amplitude as a sinc of the drift (an 8.75 s record at 1428 Hz with a
    40 ppm offset drifts by π and read 0.64 of the true amplitude: the drive control then
    chased a base that was on target)."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3:
        return 0.0
    block = max(
        int(round(AMPLITUDE_BLOCK_S * sample_rate_hz)),
        int(math.ceil(4 * sample_rate_hz / frequency_hz)),
        3,
    )
    n_blocks = max(1, x.size // block)
    edges = np.linspace(0, x.size, n_blocks + 1).astype(int)
    amps = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        w = 2.0 * np.pi * frequency_hz * np.arange(lo, hi) / sample_rate_hz
        a = np.stack([np.cos(w), np.sin(w), np.ones_like(w)], axis=1)
        coef, *_ = np.linalg.lstsq(a, x[lo:hi], rcond=None)
        amps.append(math.hypot(coef[0], coef[1]))
    return float(np.mean(amps))


#: flags of the signal stage that say waiting would have given another record: the step is
#: recorded again after the damping settle
UNSETTLED_FLAGS = ("unsettled", "ringing")


def _fit(cmd: StepCommand, reading: Reading) -> tuple[complex, float, bool]:
    """H of the record, its std per part and whether it is settled, by the signal stage's
    harmonic fit: neither its halves disagree (``unsettled``) nor a nearby mode still rings
    into it (``ringing``, :func:`vibid.signal.flags.free_vibration`: a mode a few hertz off
    the drive frequency, which the halves test misses)."""
    from vibid.signal import StepRecord, afc_from_records

    point = afc_from_records(
        [
            StepRecord(
                cmd.frequency_hz, reading.sample_rate_hz, reading.base_m_s2, reading.response_m_s2
            )
        ]
    ).points[0]
    return point.h, point.std, not set(UNSETTLED_FLAGS) & set(point.flag_names)


def _begin_step(stand: Stand, index: int) -> None:
    """Tell the stand which step comes (a simulated stand seeds that step's noise from it)."""
    hook = getattr(stand, "begin_step", None)
    if callable(hook):
        hook(index)


def _write(
    writer: SessionWriter,
    cmd: StepCommand,
    m: _Measured,
    temperature_c: float | None,
    first_unsettled: bool,
) -> None:
    extra = {
        "vibid_drive_vpp": float(m.drive_vpp),
        "vibid_settle_s": float(m.settle_s),
        "vibid_unsettled_first": np.bool_(first_unsettled),
        "vibid_resettled": np.bool_(cmd.attempt > 0),
    }
    if m.note:
        extra["vibid_note"] = m.note
    r = m.reading
    try:
        writer.append(
            frequency_hz=cmd.frequency_hz,
            sample_rate_hz=r.sample_rate_hz,
            base=r.base_m_s2,
            response=r.response_m_s2,
            status=m.status,
            t0_utc=r.t0_utc,
            temperature_c=temperature_c,
            settle_s=float(m.settle_s),
            extra_attrs=extra,
        )
    except VibidError as exc:
        raise _WriteError(str(exc)) from None


def _check_drive(config: StandConfig) -> None:
    d = config.drive
    ok = (
        d.target_base_m_s2 > 0
        and 0 < d.tolerance < 1
        and 0 < d.initial_vpp <= d.max_vpp
        and d.abort_response_m_s2 > 0
    )
    if not ok:
        raise CampaignError(
            "stand configuration drive: target_base_m_s2, initial_vpp and "
            "abort_response_m_s2 must be positive, tolerance within (0, 1), "
            f"initial_vpp at most max_vpp (got {d})"
        )


def _progress(
    cmd: StepCommand, m: _Measured, nominal: dict[int, float], elapsed_s: float
) -> StepProgress:
    done = sum(v for k, v in nominal.items() if k <= cmd.index)
    left = sum(v for k, v in nominal.items() if k > cmd.index)
    eta = elapsed_s * left / done if done > 0 else math.nan
    h = m.h
    r = m.reading
    return StepProgress(
        cmd.index,
        cmd.n_steps,
        cmd.frequency_hz,
        abs(h),
        math.degrees(math.atan2(h.imag, h.real)),
        eta,
        m.status,
        m.base_m_s2,
        m.drive_vpp,
        m.note,
        m.h_std,
        m.settle_s,
        r.base_m_s2.size / r.sample_rate_hz,
    )


# -- resume -------------------------------------------------------------------------------------
def resume_point(
    path: str | os.PathLike, setup: Setup, adaptive: dict | None = None
) -> tuple[int, float, bool]:
    """``(first missing step, drive of the last step Vpp, last step was unsettled)`` of the
    session at ``path`` resumed with ``setup`` (``adaptive``: the adaptive campaign's
    options, as its session attribute; None for a campaign of the setup's own steps), or
    :class:`CampaignError` in one line saying why it cannot be resumed so and what to do.
    Reads the file only: a command calls it before anything slow starts."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise CampaignError(f"{path}: no such session file to resume")
    if adaptive is not None:
        return _adaptive_resume_point(path, setup, adaptive)
    with read_session(path) as s:
        if s.setup.to_dict() != setup.to_dict():
            raise CampaignError(
                f"{path}: its declared setup differs from the one given; "
                "resume a session only with the setup it was started with"
            )
        n = len(s)
        want = setup.excitation.frequencies_hz
        got = s.frequencies_hz()
        if n > len(want) or not np.array_equal(got, np.asarray(want[:n], float)):
            raise CampaignError(f"{path}: its steps do not follow the setup's frequencies")
        if n >= len(want) and s.run_status_written and s.run_status == "complete":
            raise CampaignError(
                f"{path}: the session is already complete ({n} steps): "
                "nothing to resume (vibid replay identifies it)"
            )
        return _last_step_state(s)


def _last_step_state(s) -> tuple[int, float, bool]:
    """``(steps in the open session s, drive of its last step Vpp, last step was unsettled)``:
    where a resumed campaign goes on from, as an uninterrupted one would."""
    n = len(s)
    if n == 0:
        return 0, math.nan, False
    last = s.step_attributes(n - 1)
    return (
        n,
        float(last.get("vibid_drive_vpp", math.nan)),
        bool(last.get("vibid_unsettled_first", False)),
    )


def _adaptive_resume_point(path: str, setup: Setup, adaptive: dict) -> tuple[int, float, bool]:
    """The resume point of an adaptive campaign: its file must be adaptive, of the same
    setup apart from the excitation (the file's lists the steps it recorded) and of the
    same adaptive options."""
    with read_session(path) as s:
        if s.adaptive is None:
            raise CampaignError(f"{path}: not an adaptive campaign; resume it without --adaptive")
        if replace(s.setup, excitation=None).to_dict() != replace(setup, excitation=None).to_dict():
            raise CampaignError(
                f"{path}: its declared setup differs from the one given (the "
                "excitation aside); resume a session only with its own setup"
            )
        if s.adaptive != adaptive:
            raise CampaignError(
                f"{path}: it was started with other adaptive options "
                f"({json.dumps(s.adaptive, sort_keys=True)}); resume it with those"
            )
        return _last_step_state(s)


# -- stopping ----------------------------------------------------------------------------------
def _stop_test(stop) -> Callable[[], bool]:
    if stop is None:
        return lambda: False
    if hasattr(stop, "is_set"):
        return stop.is_set
    if callable(stop):
        return lambda: bool(stop())
    raise TypeError("stop must be a threading.Event or a callable returning a bool")


@contextmanager
def _sigterm_raises():
    """While the campaign runs, SIGTERM ends it like Ctrl-C — where there is a SIGTERM that
    this thread may handle (the main thread of a POSIX or Windows process); else nothing."""
    sigterm = getattr(signal, "SIGTERM", None)
    if sigterm is None or threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise _Stop()

    try:
        previous = signal.signal(sigterm, handler)
    except (ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        try:
            signal.signal(sigterm, previous)
        except (ValueError, OSError):
            pass
