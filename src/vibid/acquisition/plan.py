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
from collections.abc import Generator, Iterator
from dataclasses import dataclass, replace
from typing import Any, Protocol

from vibid.acquisition.stand_config import StandConfig, TimingConfig
from vibid.errors import VibidError
from vibid.setup_model import Setup

__all__ = [
    "Pause",
    "PlanError",
    "PlanSummary",
    "StepCommand",
    "StepOutcome",
    "damping_settle_s",
    "plan_summary",
    "play_step",
    "record_samples",
    "stepped_sine",
    "StepSource",
]


class PlanError(VibidError):
    """A plan that cannot go on (an adaptive campaign whose fit failed): the campaign ends
    ``aborted`` with this reason, and is not retried as a stand fault would be."""


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
    """What the runner tells the plan after executing a command: whether the record was
    settled, and for a plan that reads the data (an adaptive campaign) the record itself
    (a :class:`~vibid.acquisition.protocols.Reading`) and the seconds since the frequency
    changed when it began."""

    settled: bool
    reading: Any = None
    settle_s: float = math.nan


@dataclass(frozen=True)
class Pause:
    """Not a record: the plan stops to think (an adaptive campaign fits what it measured).
    The runner writes every measured step, switches the output off (the specimen is not
    driven while the plan thinks) and sends ``None`` back for the plan's next command."""


class StepSource(Protocol):
    """A plan that chooses its steps as the campaign goes (an adaptive campaign:
    :mod:`vibid.planner.adaptive`). ``attribute`` is the session's ``adaptive`` root
    attribute; ``plan(session_path, start)`` yields the commands from step ``start`` on
    (with :class:`Pause` where it stops to think), given the session file holding the
    earlier steps (None for a new campaign), and returns one line saying why it stopped."""

    attribute: dict

    def plan(
        self, session_path: str | None, start: int
    ) -> Generator[StepCommand | Pause, StepOutcome | None, str]: ...


def record_samples(
    frequency_hz: float,
    sample_rate_hz: float,
    timing: TimingConfig,
    min_record_s: float | None = None,
) -> int:
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


def stepped_sine(
    setup: Setup, config: StandConfig, *, start: int = 0, near_resonance: bool = False
) -> Generator[StepCommand, StepOutcome | None, None]:
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
    if not (
        t.expected_loss_factor > 0
        and t.max_settle_s >= 0
        and t.min_record_s > 0
        and t.min_cycles >= 1
        and t.settle_time_constants >= 0
    ):
        raise VibidError(
            "stand configuration timing: expected_loss_factor, min_record_s and "
            "min_cycles must be positive, max_settle_s and settle_time_constants "
            "zero or positive"
        )
    return _plan(setup, t, start, near_resonance)


def _plan(
    setup: Setup, t: TimingConfig, start: int, near: bool
) -> Generator[StepCommand, StepOutcome | None, None]:
    exc = setup.excitation
    fs = setup.daq.sample_rate_hz
    n = len(exc.frequencies_hz)
    for i in range(start, n):
        f = exc.frequencies_hz[i]
        settle = max(exc.settle_at(i), damping_settle_s(f, t)) if near else exc.settle_at(i)
        samples = record_samples(f, fs, t, exc.record_at(i))
        near = not (yield from play_step(StepCommand(i, n, f, settle, samples, fs), t))


def play_step(
    first: StepCommand, t: TimingConfig
) -> Generator[StepCommand, StepOutcome | None, bool]:
    """The records of one step: ``first``, then, while the record is unsettled, the same
    again at the next whole multiple of the damping settle since the frequency changed,
    within the cap (the settle rule above). Returns whether the first record was settled
    (an unsettled one says a resonance is near: the next step settles longer)."""
    outcome = yield first
    first_settled = outcome is None or outcome.settled
    f, samples, fs = first.frequency_hz, first.n_samples, first.sample_rate_hz
    since_change_s = first.settle_s + samples / fs
    attempt = 0
    tau_s = _time_constants_s(f, t)
    while outcome is not None and not outcome.settled and tau_s > 0:
        attempt += 1
        # wait until the next whole multiple of the damping settle since the change, within the cap
        until_s = min(t.max_settle_s, (math.floor(since_change_s / tau_s) + 1) * tau_s)
        if until_s <= since_change_s:
            break  # the cap is reached: the signal stage flags what is left
        outcome = yield replace(first, settle_s=until_s - since_change_s, attempt=attempt)
        since_change_s = until_s + samples / fs
    return first_settled


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


def plan_summary(
    setup: Setup, config: StandConfig = StandConfig(), *, start: int = 0
) -> PlanSummary:
    """Dry-run the plan: every command, as if every record were settled."""
    return PlanSummary(tuple(_dry(stepped_sine(setup, config, start=start))))


def _dry(plan) -> Iterator[StepCommand]:
    yield from plan  # iterating sends None: "settled"
