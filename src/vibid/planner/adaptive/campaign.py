"""The adaptive campaign as a :class:`~vibid.acquisition.plan.StepSource`: the coarse sweep,
then fit, decide, play a batch, pause, until it stops (:mod:`vibid.planner.adaptive`)."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vibid.acquisition.plan import (
    Pause,
    PlanError,
    StepCommand,
    StepOutcome,
    play_step,
    record_samples,
)
from vibid.acquisition.stand_config import StandConfig
from vibid.errors import VibidError
from vibid.planner.adaptive.batch import Batch, next_batch
from vibid.planner.adaptive.fit import CurrentFit, fit_steps, reached, worst_ratio
from vibid.planner.adaptive.options import AdaptiveOptions, coarse_sweep

log = logging.getLogger(__name__)

__all__ = ["AdaptiveCampaign", "stalled"]


#: the campaign stops when its last STALL_BATCHES batches together lowered the worst ratio
#: of a targeted std to its target by less than STALL_SHARE of what their information
#: predicted (in log ratio): more steps no longer buy certainty
STALL_BATCHES = 3
STALL_SHARE = 0.25


def stalled(progress, predicted) -> bool:
    """Whether the last :data:`STALL_BATCHES` batches lowered the worst ratio (``progress``,
    one per fit) by less than :data:`STALL_SHARE` of what they were predicted to
    (``predicted``: per batch after the coarse sweep, the predicted drop of its log)."""
    if len(progress) <= STALL_BATCHES or len(predicted) < STALL_BATCHES:
        return False
    got = math.log(progress[-1 - STALL_BATCHES] / progress[-1])
    expected = float(sum(predicted[-STALL_BATCHES:]))
    return expected > 0 and got < STALL_SHARE * expected


@dataclass
class _Measured:
    """The steps so far: what the fit needs of each (its record), their stand time, and
    each step's AFC point once the signal stage has fitted it (a step is fitted once, not
    at every batch)."""

    records: list = field(default_factory=list)  # StepRecord, in acquisition order
    stand_s: float = 0.0
    points: dict = field(default_factory=dict)  # step index -> AfcPoint

    @property
    def record_s(self) -> list[float]:
        return [r.base.size / r.sample_rate_hz for r in self.records]

    def afc(self):
        """The AFC of every step so far, sorted by frequency (the new steps fitted now)."""
        from vibid.signal import afc_from_records
        from vibid.signal.afc import AfcTable

        new = [r for r in self.records if r.index not in self.points]
        self.points.update((p.index, p) for p in afc_from_records(new).points)
        return AfcTable(tuple(self.points[r.index] for r in self.records)).by_frequency()


class AdaptiveCampaign:
    """The adaptive campaign as a :class:`~vibid.acquisition.plan.StepSource` (module doc).

    ``on_fit(fit, n_steps, stand_time_s)`` is called after every fit (the live AFC, the
    log); ``say(line)`` with one line per decision; ``loop``/``candidates`` are the closed
    loop's between batches.
    """

    def __init__(
        self,
        setup,
        config: StandConfig,
        options: AdaptiveOptions,
        *,
        loop: bool = True,
        candidates=None,
        restarts: int = 5,
        seed: int = 0,
        on_fit: Callable[[CurrentFit, int, float], Any] | None = None,
        say: Callable[[str], Any] | None = None,
    ):
        options.check(setup)
        #: the identification's global search, as the report runs it
        self.restarts, self.seed = int(restarts), int(seed)
        self.setup, self.config, self.options = setup, config, options
        self.loop, self.candidates = loop, candidates
        self.on_fit = on_fit or (lambda fit, n, stand_s: None)
        self.say = say or log.info
        self.attribute = options.attribute()
        self.compute_s = 0.0  #: seconds spent fitting and choosing, beside the stand time
        self.fit: CurrentFit | None = None
        #: after each fit, the worst ratio of a targeted std to its target
        self.progress: list[float] = []
        #: each decision between batches: steps and stand time so far, the effects of the
        #: fit it was made on, the resonances the residual showed where the model has none,
        #: the next batch's frequencies (Hz) and the gain its information predicted
        self.history: list[dict] = []
        exc = setup.excitation
        self.floor_s = float(min(exc.settle_s) if isinstance(exc.settle_s, tuple) else exc.settle_s)

    def describe(self) -> list[str]:
        """What a dry run prints: the coarse sweep and the rule."""
        o = self.options
        f = coarse_sweep(o)
        return [
            f"adaptive campaign: coarse sweep of {f.size} steps {f[0]:g}-{f[-1]:g} Hz "
            f"(geometric), settle {self.floor_s:g} s each",
            "  " + " ".join(f"{x:.4g}" for x in f),
            f"then batches of {o.batch_size} steps where the current fit's information per "
            "second of stand time is largest (each mode's half-power band evenly in phase; "
            "resonances the residual shows where the model has none), settled as the fit's "
            f"Q asks (at least {self.floor_s:g} s), a fit after each batch (the closed loop "
            f"{'when the residual asks for it' if self.loop else 'off'})",
            f"until {', '.join(map(str, o.targets))} (the report's standard uncertainty) or "
            f"{o.max_stand_time_s:g} s of stand time",
        ]

    def plan(
        self, session_path: str | None, start: int
    ) -> Generator[StepCommand | Pause, StepOutcome | None, str]:
        measured = _Measured()
        if session_path is not None:
            measured = _from_file(session_path)
        index = start
        batch_no = 0
        batch = None
        done = np.array([r.frequency_hz for r in measured.records], float)
        f = np.array([x for x in coarse_sweep(self.options) if not np.any(np.isclose(done, x))])
        if f.size:  # a new campaign, or one stopped in its coarse sweep: (the rest of) it first
            batch = Batch(f, np.full(f.size, self.floor_s), np.zeros(f.size))
            self.say(f"coarse sweep: {f.size} steps {f[0]:g}-{f[-1]:g} Hz")
        while True:
            coarse = batch is not None
            if batch is None:
                t0 = time.perf_counter()
                try:
                    why = self._decide(measured, batch_no)
                except VibidError as exc:
                    raise PlanError(
                        f"the fit of {len(measured.records)} steps failed: {exc}"
                    ) from None
                finally:
                    self.compute_s += time.perf_counter() - t0
                if isinstance(why, str):
                    self.say(why)
                    return why
                batch = why
            batch_no += 1
            # re-records wait the current fit's Q; the coarse sweep records once: a step still
            # ringing there is flagged and left out, and the batches measure the modes settled
            timing = replace(
                self.config.timing,
                expected_loss_factor=self._beta(),
                **({"settle_time_constants": 0.0} if coarse else {}),
            )
            fs = self.setup.daq.sample_rate_hz
            n_planned = index + len(batch)
            for f, settle, rec in zip(batch.frequency_hz, batch.settle_s, batch.record_s):
                first = StepCommand(
                    index,
                    n_planned,
                    float(f),
                    float(settle),
                    record_samples(float(f), fs, self.config.timing, float(rec) or None),
                    fs,
                )
                last = yield from _recorded(play_step(first, timing))
                if last is not None and last.reading is not None:
                    self._keep(measured, index, first, last)
                index += 1
            batch = None
            yield Pause()

    # -- between batches --------------------------------------------------------------------
    def _decide(self, measured: _Measured, batch_no: int):
        """Fit what is measured; the stop line, or the next :class:`Batch`."""
        o = self.options
        ok, where = self._fit(measured)
        n = len(measured.records)
        self.on_fit(self.fit, n, measured.stand_s)
        self.progress.append(worst_ratio(self.fit, o.targets))
        effects = [
            t.name
            for t in (self.fit.result.plate_model.effects if self.fit.result.plate_model else ())
        ]
        self.say(
            f"fit of {n} steps ({measured.stand_s:.1f} s of stand time): {where}"
            f"{'; effects ' + ', '.join(effects) if effects else ''}"
            f" ({self.fit.seconds:.1f} s)"
        )
        tail = (
            f" after {n} steps, stand time {measured.stand_s:.1f} s "
            f"(computing {self.compute_s + self.fit.seconds:.0f} s beside it)"
        )
        stop = self._stop(ok, measured.stand_s)
        if stop is not None:
            return f"{stop}: {where}{tail}"
        measured_hz = [r.frequency_hz for r in measured.records]
        batch = next_batch(
            self.setup,
            self.config,
            self.fit,
            o,
            measured_hz,
            measured.record_s,
            spent_s=measured.stand_s,
            floor_s=self.floor_s,
            seed=o.seed + batch_no,
        )
        if not len(batch):
            return f"no step left under the stand-time cap {o.max_stand_time_s:g} s: {where}{tail}"
        self._announce(batch, batch_no, n, measured.stand_s, effects)
        return batch

    def _fit(self, measured: _Measured) -> tuple[bool, str]:
        """Fit every step so far, from the last fit (:func:`fit_steps`), into ``self.fit``;
        whether the targets are reached there, and where the fit stands
        (:func:`reached`)."""
        afc = measured.afc()

        def fit(previous):
            return fit_steps(
                self.setup,
                afc,
                previous,
                loop=self.loop,
                candidates=self.candidates,
                restarts=self.restarts,
                seed=self.seed,
            )

        self.fit = fit(self.fit)
        ok, where = reached(self.fit, self.options.targets)
        if ok and self.fit.warm:
            # the stop is the report's to decide: its own identification (a global search
            # may find rival minima that widen the std a local refit does not see)
            self.fit = fit(None)
            ok, where = reached(self.fit, self.options.targets)
        return ok, where

    def _stop(self, ok: bool, stand_s: float) -> str | None:
        """Why the campaign stops after this fit (``ok``: the targets reached; ``stand_s``
        spent), None to go on: the targets, the stand-time cap, or a stall
        (:func:`stalled`)."""
        o = self.options
        if ok:
            return "target reached"
        if stand_s >= o.max_stand_time_s:
            return f"stand-time cap {o.max_stand_time_s:g} s reached"
        if stalled(self.progress, [d["predicted_gain"] for d in self.history]):
            return (
                f"the standard uncertainty no longer falls as the steps' information "
                f"says it should (the last {STALL_BATCHES} batches brought under "
                f"{100 * STALL_SHARE:g} % of the predicted gain: the model's own error or "
                f"a residual limits it, not the steps)"
            )
        return None

    def _announce(self, batch: Batch, batch_no: int, n: int, stand_s: float, effects) -> None:
        """Keep the decision in :attr:`history` and say it: the resonances the residual
        showed where the model has none, and the next batch."""
        self.history.append(
            {
                "steps": n,
                "stand_time_s": stand_s,
                "effects": tuple(effects),
                "unexpected": self.fit.unexpected,
                "batch_hz": tuple(float(f) for f in batch.frequency_hz),
                "predicted_gain": batch.predicted_gain,
            }
        )
        if self.fit.unexpected:
            self.say(
                "resonance where the model has none: "
                + ", ".join(f"{f:.1f} Hz (Q {q:.0f})" for f, q in self.fit.unexpected)
            )
        self.say(
            f"batch {batch_no + 1}: {len(batch)} steps "
            f"{', '.join(f'{f:.2f}' for f in batch.frequency_hz)} Hz, "
            f"{batch.stand_time_s:.1f} s of stand time predicted"
        )

    def _beta(self) -> float:
        """The loss factor the re-record waits use: the current fit's, else the stand's."""
        if self.fit is not None:
            p = self.fit.result.parameters
            if "beta" in p and p["beta"] > 0:
                return float(p["beta"])
        return self.config.timing.expected_loss_factor

    @staticmethod
    def _keep(measured: _Measured, index: int, cmd: StepCommand, last: StepOutcome) -> None:
        from vibid.signal import StepRecord

        r = last.reading
        status = "overload" if r.overloaded else "ok"  # as the runner writes it
        measured.records.append(
            StepRecord(
                cmd.frequency_hz,
                r.sample_rate_hz,
                r.base_m_s2,
                r.response_m_s2,
                status=status,
                index=index,
            )
        )
        measured.stand_s += float(last.settle_s) + r.base_m_s2.size / r.sample_rate_hz


def _recorded(step) -> Generator[StepCommand, StepOutcome | None, StepOutcome | None]:
    """Play one step's commands (:func:`~vibid.acquisition.plan.play_step`); return the
    outcome of its last record (the one the runner writes)."""
    last = None
    cmd = next(step)
    while True:
        last = yield cmd
        try:
            cmd = step.send(last)
        except StopIteration:
            return last


def _from_file(path: str) -> _Measured:
    """The steps of a session file (a resumed campaign): records and stand time."""
    from vibid.session import read_session
    from vibid.signal import StepRecord

    with read_session(path) as s:
        records = [
            StepRecord(
                step.frequency_hz,
                step.sample_rate_hz,
                step.base,
                step.response,
                status=step.status,
                index=step.index,
            )
            for step in s.steps()
        ]
        return _Measured(records, s.driven_s() or 0.0)
