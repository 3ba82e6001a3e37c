"""The stepped-sine plan: which frequency, how long to settle, how many samples to record.

A plan is a plain generator (Bluesky's shape): it yields one :class:`StepCommand` per
acquisition and receives back, through ``send``, a :class:`StepOutcome` saying whether the
record was settled. It touches no hardware, so it can be *dry-run* (:func:`plan_summary`) for
the command list and the campaign's duration; the runner (:mod:`vibid.acquisition.campaign`)
executes the commands.

Settle rule. A linear specimen driven at ``f`` after a change of frequency or drive carries a
free vibration that decays with the time constant ``τ = Q / (π f_n)`` of the mode it excites,
``Q = 1 / η`` (η the expected loss factor of the stand configuration). Away from resonances
that vibration is small and the setup's ``excitation.settle_s`` is enough; near one it is not.
The plan has no model of where the resonances are (the declared bounds are too wide to say),
so it finds them by measurement, conservatively:

* every step first settles ``excitation.settle_s`` (its own value when the setup lists one
  per step: a planned test, :mod:`vibid.planner`);
* a record the signal stage finds *unsettled* (its two halves disagree beyond noise,
  :mod:`vibid.signal.flags`) is recorded again after waiting until
  ``settle_time_constants · Q / (π f)`` — the damping settle — has passed since the frequency
  changed; if it is still unsettled, again at the next whole multiple of that time, and so on
  until the time since the change would pass ``max_settle_s`` (the cap): a high
  signal-to-noise ratio shows a transient longer than a fixed number of time constants hides;
* the step after an unsettled one (a resonance spans neighbouring steps) settles
  ``max(excitation.settle_s, damping settle)`` from the start.

Record length: the smallest whole number of cycles that lasts at least ``min_record_s`` (or
the step's ``excitation.record_s``, if longer) and holds at least ``min_cycles`` cycles,
rounded to whole samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Generator, Iterator

from vibid.acquisition.stand_config import StandConfig, TimingConfig
from vibid.errors import VibidError
from vibid.setup_model import Setup

__all__ = [
    "PlanSummary", "StepCommand", "StepOutcome", "damping_settle_s", "plan_summary",
    "record_samples", "stepped_sine",
]


@dataclass(frozen=True)
class StepCommand:
    """One acquisition: play ``frequency_hz``, wait ``settle_s``, record ``n_samples``.

    ``attempt`` is 0 for a step's first record and k ≥ 1 for its k-th re-record after a
    longer settle (the frequency is then unchanged and ``settle_s`` is the extra wait).
    """

    index: int
    n_steps: int
    frequency_hz: float
    settle_s: float
    n_samples: int
    sample_rate_hz: float
    attempt: int = 0

    @property
    def record_s(self) -> float:
        """Record duration, s."""
        return self.n_samples / self.sample_rate_hz


@dataclass(frozen=True)
class StepOutcome:
    """What the runner tells the plan after executing a command."""

    settled: bool


def record_samples(frequency_hz: float, sample_rate_hz: float, timing: TimingConfig,
                   min_record_s: float | None = None) -> int:
    """Samples of a record of whole cycles: at least ``min_record_s`` (default the timing's;
    a planned step's own, never below the timing's) and ``min_cycles``."""
    shortest_s = max(timing.min_record_s, min_record_s or 0.0)
    cycles = max(int(timing.min_cycles), math.ceil(shortest_s * frequency_hz - 1e-9), 1)
    return max(1, int(round(cycles * sample_rate_hz / frequency_hz)))


def damping_settle_s(frequency_hz: float, timing: TimingConfig) -> float:
    """``settle_time_constants · Q / (π f)`` with ``Q = 1 / expected_loss_factor``, capped at
    ``max_settle_s``, s: the wait for a free vibration near ``frequency_hz`` to die out."""
    return float(min(timing.max_settle_s, _time_constants_s(frequency_hz, timing)))


def _time_constants_s(frequency_hz: float, timing: TimingConfig) -> float:
    q = 1.0 / timing.expected_loss_factor if timing.expected_loss_factor > 0 else math.inf
    return timing.settle_time_constants * q / (math.pi * frequency_hz)


def stepped_sine(setup: Setup, config: StandConfig, *, start: int = 0,
                 near_resonance: bool = False) -> Generator[StepCommand, StepOutcome | None, None]:
    """The plan of ``setup``'s stepped sine from step ``start`` (resume) on.

    ``near_resonance`` says the step before ``start`` was unsettled (so a resumed campaign
    makes the same decisions as an uninterrupted one). Sending ``None`` (a dry run) means
    "settled". Arguments are checked now, not at the first ``next``.
    """
    if setup.excitation is None:
        raise VibidError("the setup has no excitation: nothing to play")
    n = len(setup.excitation.frequencies_hz)
    if not 0 <= start <= n:
        raise VibidError(f"cannot start at step {start} of {n}")
    t = config.timing
    if not (t.expected_loss_factor > 0 and t.max_settle_s >= 0 and t.min_record_s > 0
            and t.min_cycles >= 1 and t.settle_time_constants >= 0):
        raise VibidError("stand configuration timing: expected_loss_factor, min_record_s and "
                         "min_cycles must be positive, max_settle_s and settle_time_constants "
                         "zero or positive")
    return _plan(setup, t, start, near_resonance)


def _plan(setup: Setup, t: TimingConfig, start: int, near: bool) -> Generator[StepCommand, StepOutcome | None, None]:
    exc = setup.excitation
    fs = setup.daq.sample_rate_hz
    n = len(exc.frequencies_hz)
    for i in range(start, n):
        f = exc.frequencies_hz[i]
        damping = damping_settle_s(f, t)
        settle = max(exc.settle_at(i), damping) if near else exc.settle_at(i)
        samples = record_samples(f, fs, t, exc.record_at(i))
        outcome = yield StepCommand(i, n, f, settle, samples, fs)
        near = outcome is not None and not outcome.settled
        since_change_s = settle + samples / fs
        attempt = 0
        tau_s = _time_constants_s(f, t)
        while outcome is not None and not outcome.settled and tau_s > 0:
            attempt += 1
            # wait until the next whole multiple of the damping settle since the change, within the cap
            until_s = min(t.max_settle_s, (math.floor(since_change_s / tau_s) + 1) * tau_s)
            if until_s <= since_change_s:
                break  # the cap is reached: the signal stage flags what is left
            outcome = yield StepCommand(i, n, f, until_s - since_change_s, samples, fs, attempt=attempt)
            since_change_s = until_s + samples / fs


@dataclass(frozen=True)
class PlanSummary:
    """A dry run: the commands of a plan with every record settled, and their durations."""

    commands: tuple[StepCommand, ...]

    @property
    def settle_s(self) -> float:
        return sum(c.settle_s for c in self.commands)

    @property
    def record_s(self) -> float:
        return sum(c.record_s for c in self.commands)

    @property
    def duration_s(self) -> float:
        """Settle and record time of the whole plan, s (the least a campaign can take)."""
        return self.settle_s + self.record_s


def plan_summary(setup: Setup, config: StandConfig = StandConfig(), *, start: int = 0) -> PlanSummary:
    """Dry-run the plan: every command, as if every record were settled."""
    return PlanSummary(tuple(_dry(stepped_sine(setup, config, start=start))))


def _dry(plan) -> Iterator[StepCommand]:
    yield from plan  # iterating sends None: "settled"
