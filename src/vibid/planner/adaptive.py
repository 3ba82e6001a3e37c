"""The adaptive campaign: measure a little, fit, then measure where the fit says it learns most.

One batch at a time, as a plain generator of step commands
(:class:`~vibid.acquisition.plan.StepSource`; the runner plays them and writes each step):

1. **Coarse sweep.** ``coarse_steps`` frequencies spread geometrically over the band, each
   settled the setup's ``settle_s`` and recorded the stand's shortest record: enough of the
   AFC's shape for the global search to place the modes.
2. **Fit** what is measured, as the report does (:func:`fit_steps`): the signal stage's AFC
   sorted by frequency, the declared model, the closed loop when the one judge of "fits
   the data" says the residual asks for it. A later fit starts from the last one (the
   model with the effects found so far; the declared model, and the loop, again when that
   no longer explains the data).
3. **Stop** when every targeted parameter's reported standard uncertainty is at or below
   its target (the same estimator as the report: a warm refit that claims it is checked by
   the report's own identification, global search and all), when the stand time reaches the cap, or
   when the last three batches lowered it by less than a quarter of what their information
   predicted (the model's own error or a residual the model cannot explain limits it, not
   the number of steps).
4. **Choose** the next batch (:func:`next_batch`): draws from the current fit's posterior
   (its estimate and covariance), the Fisher information per step over them at candidate
   frequencies (a grid over the band and, for every mode of every draw, its half-power band
   evenly in phase: :mod:`.information`), greedily by expected gain per second of stand
   time (:mod:`.design`) starting from the information of the steps measured, aiming below
   the target by as much as the report's std is now wider than the information's (a Birge
   ratio, rival minima, the model's error: :func:`calibration`), and spending at most as
   much stand time as all the steps before it. A resonance the residual's diagnosis finds
   where the model has none gets steps across its half-power band as well, and each
   minimum the fit could not tell from its estimate (its std includes their spread) a step
   where their AFCs differ most (:func:`telling_apart`).
5. **Play** the batch in ascending frequency, each step settled as the current fit's modes
   require (:mod:`.settle`; the setup's ``settle_s`` the floor; a record still ringing is
   recorded again, :func:`~vibid.acquisition.plan.play_step`, waiting the fit's Q), then
   pause with the output off while the next fit runs: compute time is not stand time.

The session carries the options as its ``adaptive`` attribute (:meth:`AdaptiveOptions.attribute`),
so a resumed campaign reads its steps from the file and goes on from step 2.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Generator

import numpy as np

from vibid.acquisition.plan import (Pause, PlanError, StepCommand, StepOutcome, play_step,
                                    record_samples)
from vibid.acquisition.stand_config import StandConfig
from vibid.errors import VibidError
from vibid.planner.prior import Target, parse_targets, prior_std

log = logging.getLogger(__name__)

__all__ = ["AdaptiveCampaign", "AdaptiveOptions", "CurrentFit", "fit_steps", "next_batch",
           "reached"]

#: posterior draws the next batch is chosen over (the estimate and 8 Sobol normal draws)
N_DRAWS = 9
#: where a resonance the model lacks is measured: phases across its half-power band, deg
UNEXPECTED_PHASES_DEG = (-60.0, -30.0, 0.0, 30.0, 60.0)


@dataclass(frozen=True)
class AdaptiveOptions:
    """What an adaptive campaign aims at and may spend: ``targets`` (standard uncertainties
    of named parameters), the ``band_hz`` it measures in, the stand-time cap, steps per
    batch, the coarse sweep's step count and the seed of its posterior draws."""

    targets: tuple[Target, ...]
    band_hz: tuple[float, float]
    max_stand_time_s: float = 600.0
    batch_size: int = 4
    coarse_steps: int = 16
    seed: int = 0

    def attribute(self) -> dict:
        """The session's ``adaptive`` root attribute (session-format.md)."""
        return {"target": [str(t) for t in self.targets], "band_hz": [float(b) for b in self.band_hz],
                "max_stand_time_s": float(self.max_stand_time_s), "batch_size": int(self.batch_size),
                "coarse_steps": int(self.coarse_steps), "seed": int(self.seed)}

    @classmethod
    def from_attribute(cls, doc: dict, names) -> "AdaptiveOptions":
        """The options a session's ``adaptive`` attribute records (one-line errors)."""
        try:
            return cls(parse_targets(doc["target"], names), tuple(float(b) for b in doc["band_hz"]),
                       float(doc["max_stand_time_s"]), int(doc["batch_size"]),
                       int(doc.get("coarse_steps", 16)), int(doc.get("seed", 0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise VibidError(f"the session's adaptive attribute cannot be read ({exc})") from None

    def check(self, setup) -> None:
        lo, hi = self.band_hz
        nyquist = setup.daq.sample_rate_hz / 2
        if not 0 < lo < hi < nyquist:
            raise VibidError(f"--band {lo:g}:{hi:g}: needs 0 < low < high < {nyquist:g} Hz (Nyquist)")
        if not self.max_stand_time_s > 0:
            raise VibidError("--max-stand-time must be positive")
        if self.batch_size < 1 or self.coarse_steps < 4:
            raise VibidError("--batch must be at least 1 and the coarse sweep at least 4 steps")


@dataclass(frozen=True)
class CurrentFit:
    """The fit of the steps measured so far: ``result`` (the final model's, effects
    included), ``declared`` (the declared model's: where the next fit starts when the
    effects no longer explain), ``loop`` (the closed loop's, when it ran), ``unexpected_hz``
    (with Q: resonances the residual shows where the model has none) and ``noise`` (each
    channel's noise relative to the base amplitude, estimated from the AFC's std)."""

    result: Any
    declared: Any
    loop: Any
    noise: float
    unexpected: tuple[tuple[float, float], ...] = ()
    seconds: float = math.nan
    #: a local refit from the last fit (cheap); else the report's own identification
    #: (the global search with the report's restarts and seed, the loop where asked)
    warm: bool = False

    def std_of(self, name: str) -> tuple[float, float]:
        """(value, reported standard uncertainty) of a parameter."""
        j = list(self.result.parameter_names).index(name)
        return float(self.result.values[j]), float(self.result.std[j])


def reached(fit: CurrentFit, targets) -> tuple[bool, str]:
    """Whether each target is met by the fit's reported std, and the line that says so."""
    parts, ok = [], True
    for t in targets:
        value, std = fit.std_of(t.name)
        want = t.std_of(value)
        ok &= bool(std <= want)
        if t.relative:
            parts.append(f"{t.name} {100 * std / abs(value):.3g} % (target {100 * t.value:g} %)")
        else:
            parts.append(f"{t.name} {std:.3g} (target {t.value:g})")
    return ok, ", ".join(parts)


#: the campaign stops when its last STALL_BATCHES batches together lowered the worst ratio
#: of a targeted std to its target by less than STALL_SHARE of what their information
#: predicted (in log ratio): more steps no longer buy certainty
STALL_BATCHES = 3
STALL_SHARE = 0.25


def worst_ratio(fit: CurrentFit, targets) -> float:
    """The largest targeted standard uncertainty over its target."""
    out = 0.0
    for t in targets:
        value, std = fit.std_of(t.name)
        out = max(out, std / t.std_of(value))
    return out


def stalled(progress, predicted) -> bool:
    """Whether the last :data:`STALL_BATCHES` batches lowered the worst ratio (``progress``,
    one per fit) by less than :data:`STALL_SHARE` of what they were predicted to
    (``predicted``: per batch after the coarse sweep, the predicted drop of its log)."""
    if len(progress) <= STALL_BATCHES or len(predicted) < STALL_BATCHES:
        return False
    got = math.log(progress[-1 - STALL_BATCHES] / progress[-1])
    expected = float(sum(predicted[-STALL_BATCHES:]))
    return expected > 0 and got < STALL_SHARE * expected


# -- the fit ------------------------------------------------------------------------------------
def fit_steps(setup, afc, previous: CurrentFit | None = None, *, loop: bool = True,
              candidates=None, restarts: int = 5, seed: int = 0) -> CurrentFit:
    """Fit the AFC of the steps so far (sorted by frequency), as the module doc says.
    Without ``previous``, the report's own identification (``restarts``, ``seed``)."""
    from vibid.identify.fit import identify
    from vibid.identify.fit.noise import explains
    from vibid.pipeline import COMPUTE_LOCK

    t0 = time.perf_counter()
    with COMPUTE_LOCK:
        if previous is not None:
            warm = _local(setup, afc, previous.result)
            if warm is not None and explains(warm):
                return CurrentFit(warm, previous.declared, previous.loop, noise_level(afc),
                                  seconds=time.perf_counter() - t0, warm=True)
        declared = None
        if previous is not None:
            declared = _local(setup, afc, previous.declared)
        if declared is None or not declared.converged:
            declared = identify(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                                restarts=restarts, seed=seed)
        result, closed = declared, None
        if loop and declared.converged and not explains(declared):
            from vibid.identify.loop import close_loop

            closed = close_loop(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                                candidates=candidates, declared=declared)
            result = closed.final
        unexpected = () if explains(result) else _unexpected(setup, result, closed)
    return CurrentFit(result, declared, closed, noise_level(afc), unexpected,
                      time.perf_counter() - t0, warm=previous is not None)


def _local(setup, afc, start_result):
    """``start_result``'s model (its effects included) refitted locally from its estimate,
    or None where it cannot be."""
    from vibid.identify.fit import identify
    from vibid.identify.model.forward import build_forward_model

    plate = start_result.plate_model
    if plate is None:
        return None
    start = {n: float(v) for n, v in zip(start_result.parameter_names, start_result.values)}
    box = plate.default_bounds(dict(setup.identification.bounds))
    try:
        fm = build_forward_model(setup, afc.frequency_hz[afc.used], model=plate, theta0=start,
                                 bounds=box)
        return identify(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                        model=plate.model, forward_model=fm, method="local", start=start,
                        bounds=box)
    except VibidError as exc:
        log.info("adaptive: the local refit failed (%s); searching again", exc)
        return None


def _unexpected(setup, result, closed) -> tuple[tuple[float, float], ...]:
    """Resonances the residual shows where the fitted model has none: (f_hz, Q)."""
    from vibid.identify.loop.rounds import diagnosis_of

    diagnosis = None
    if closed is not None and closed.stages:
        diagnosis = closed.stages[-1].diagnosis
    if diagnosis is None:
        diagnosis = diagnosis_of(setup, result)
    if diagnosis is None:
        return ()
    return tuple((float(f.f_hz), float(f.q)) for f in diagnosis.features
                 if f.kind == "extra_pole" and np.isfinite(f.f_hz) and f.q > 2)


def noise_level(afc) -> float:
    """Each channel's noise relative to the base amplitude, from the AFC's std: the median
    over the used steps of ``s / (√(2/N) √(1 + |H|²))`` (:mod:`.information`)."""
    used = np.asarray(afc.used, bool)
    n = np.array([p.n_samples for p in afc.points], float)[used]
    s = np.asarray(afc.std, float)[used]
    h = np.abs(np.asarray(afc.H))[used]
    level = s / (np.sqrt(2.0 / n) * np.sqrt(1.0 + h**2))
    level = level[np.isfinite(level) & (level > 0)]
    return float(np.median(level)) if level.size else 1e-3


# -- the next batch ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Batch:
    """Steps to play, in ascending frequency: Hz, settle s, minimum record s."""

    frequency_hz: np.ndarray
    settle_s: np.ndarray
    record_s: np.ndarray
    #: the predicted drop of log(worst targeted std / target) at the estimate
    predicted_gain: float = math.nan

    def __len__(self) -> int:
        return int(self.frequency_hz.size)

    @property
    def stand_time_s(self) -> float:
        return float(np.sum(self.settle_s) + np.sum(self.record_s))


def posterior_draws(result, box: dict, n: int, seed: int) -> np.ndarray:
    """(n, p): the estimate, then normal draws of the fit's covariance (Sobol), in the box."""
    from scipy.stats import norm, qmc

    theta = np.asarray(result.values, float)
    names = list(result.parameter_names)
    cov = np.asarray(result.covariance, float)
    if not np.all(np.isfinite(cov)):
        cov = np.diag(np.nan_to_num(np.asarray(result.std, float), nan=0.0) ** 2)
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    root = v * np.sqrt(np.clip(w, 0.0, None))
    u = np.clip(qmc.Sobol(len(names), scramble=True, seed=seed).random(max(n - 1, 1)), 1e-6, 1 - 1e-6)
    draws = np.vstack([theta, theta + norm.ppf(u) @ root.T])[:n]
    lo = np.array([box[k][0] for k in names], float)
    hi = np.array([box[k][1] for k in names], float)
    span = hi - lo
    return np.clip(draws, lo + 1e-6 * span, hi - 1e-6 * span)


def next_batch(setup, config: StandConfig, fit: CurrentFit, options: AdaptiveOptions,
               measured_hz, measured_record_s, *, spent_s: float, floor_s: float,
               seed: int = 0) -> Batch:
    """The next steps (module doc, 4): at most ``options.batch_size``, within the stand
    time left under the cap and no more than all the steps before took (so that a batch the
    information overrates wastes at most as much as was spent)."""
    from vibid.planner.design import greedy
    from vibid.planner.information import fisher, information

    r = fit.result
    names = tuple(r.parameter_names)
    box = r.plate_model.default_bounds(dict(setup.identification.bounds))
    draws, n_rivals = design_draws(r, box, seed)
    forced = unexpected_steps(fit, measured_hz)
    measured_hz = np.asarray(measured_hz, float)
    info = information(setup, names, draws, options.band_hz, noise=fit.noise,
                       extra_hz=measured_hz, plate=r.plate_model, bounds=box, more_hz=forced)
    n_cand = info.frequency_hz.size - measured_hz.size
    measured = (n_cand + np.arange(measured_hz.size), np.asarray(measured_record_s, float))
    targeted = [names.index(t.name) for t in options.targets]
    t_std = np.array([[t.std_of(d[j]) for t, j in zip(options.targets, targeted)] for d in draws])
    # the report's std is the Fisher one widened (a Birge ratio, the model's error): aim
    # lower by the factor it is wider now, so that the batch reaches the target by the
    # report's measure. Rival minima widen it too, but steps that tell them apart remove
    # that, not more precision at the estimate: those steps come first, and no factor.
    if not n_rivals:
        t_std = t_std * calibration(info, measured, r, targeted)
    fs = setup.daq.sample_rate_hz
    shortest = np.array([record_samples(f, fs, config.timing) / fs for f in info.frequency_hz[:n_cand]])
    weak = np.diag(1.0 / prior_std(names, box, {}, draws[0]) ** 2)  # the box: keeps A invertible
    A0 = weak[None] + fisher(info, *measured).sum(axis=1)
    start = np.searchsorted(info.frequency_hz[:n_cand], np.round(forced, 6)).clip(0, n_cand - 1)
    start = np.unique(np.concatenate([start, telling_apart(info, n_cand, n_rivals, shortest,
                                                           floor_s)])).astype(int)
    steps = greedy(info, np.arange(n_cand), shortest, t_std, targeted, A0, floor_s=floor_s,
                   cap_s=config.timing.max_settle_s, quantile=0.5, settle_quantile=0.9,
                   max_stand_time_s=max(min(options.max_stand_time_s - spent_s, spent_s), 0.0),
                   start=start, max_steps=max(options.batch_size, start.size), measured=measured)
    gain = predicted_gain(info, measured, (steps.index, steps.record_s), targeted, t_std[0])
    return Batch(info.frequency_hz[steps.index], steps.settle_s, steps.record_s, gain)


def design_draws(result, box: dict, seed: int) -> tuple[np.ndarray, int]:
    """The draws a batch is chosen over: the estimate, the other minima the fit could not
    tell from it (their number is returned too), then draws of its covariance."""
    draws = posterior_draws(result, box, N_DRAWS, seed)
    rivals = np.array(list(result.rivals), float).reshape(-1, draws.shape[1])
    return np.vstack([draws[:1], rivals, draws[1:]]), len(rivals)


def unexpected_steps(fit: CurrentFit, measured_hz) -> np.ndarray:
    """Frequencies across each resonance the residual shows where the model has none, evenly
    in its phase, unless steps lie across its half-power band already."""
    from vibid.planner.information import across_mode

    todo = [(f, q) for f, q in fit.unexpected if not _covered(f, q, measured_hz)]
    if not todo:
        return np.zeros(0)
    f, q = np.array(todo, float).T
    return across_mode(f, 1.0 / q, UNEXPECTED_PHASES_DEG).ravel()


def predicted_gain(info, measured, new, targeted, t_std) -> float:
    """How much the new steps lower ``log`` of the worst targeted std over its target
    ``t_std`` at the estimate (draw 0), by the information."""
    from vibid.planner.design import data_std

    def worst(index, record):
        return float(np.max(data_std(info, np.asarray(index, int), np.asarray(record, float))[0, targeted] / t_std))

    before = worst(*measured)
    after = worst(np.concatenate([measured[0], new[0]]), np.concatenate([measured[1], new[1]]))
    return math.log(before / after) if np.isfinite(before) and np.isfinite(after) else math.nan


def telling_apart(info, n_cand: int, n_rivals: int, record_s, floor_s: float) -> np.ndarray:
    """For each rival minimum (draws 1..``n_rivals`` of ``info``; draw 0 the estimate), the
    candidate where the two AFCs differ most against the step's noise and model error, per
    second of its stand time (its shortest record and the settle floor)."""
    out = []
    T = np.asarray(record_s, float)
    for i in range(1, n_rivals + 1):
        diff = np.abs(info.H[i, :n_cand] - info.H[0, :n_cand]) ** 2
        var = info.s_1s[0, :n_cand] ** 2 / T + info.e[0, :n_cand] ** 2
        out.append(int(np.argmax(diff / var / (T + floor_s))))
    return np.asarray(out, int)


def calibration(info, measured, result, targeted) -> np.ndarray:
    """Per targeted parameter, the information's standard uncertainty of the steps measured
    (at the estimate) over the one the fit reports: 1 where they agree, below where the
    report's is wider."""
    from vibid.planner.design import data_std

    predicted = data_std(info, measured[0].astype(int), measured[1])[0, targeted]
    reported = np.asarray(result.std, float)[targeted]
    with np.errstate(divide="ignore", invalid="ignore"):
        k = predicted / reported
    return np.where(np.isfinite(k), np.clip(k, 1e-3, 1.0), 1.0)


def _covered(f_hz: float, q: float, measured_hz) -> bool:
    """Whether steps lie across this resonance's half-power band already (three or more)."""
    m = np.asarray(measured_hz, float)
    return int(np.count_nonzero(np.abs(m - f_hz) <= f_hz / q)) >= 3


def coarse_sweep(options: AdaptiveOptions) -> np.ndarray:
    """The first batch's frequencies, Hz: geometric over the band."""
    return np.round(np.geomspace(*options.band_hz, options.coarse_steps), 6)


# -- the campaign ---------------------------------------------------------------------------
@dataclass
class _Measured:
    """The steps so far: what the fit needs of each (its record) and its stand time."""

    records: list = field(default_factory=list)   # StepRecord, in acquisition order
    record_s: list = field(default_factory=list)
    stand_s: float = 0.0


class AdaptiveCampaign:
    """The adaptive campaign as a :class:`~vibid.acquisition.plan.StepSource` (module doc).

    ``on_fit(fit, n_steps, stand_time_s)`` is called after every fit (the live AFC, the
    log); ``say(line)`` with one line per decision; ``loop``/``candidates`` are the closed
    loop's between batches.
    """

    def __init__(self, setup, config: StandConfig, options: AdaptiveOptions, *,
                 loop: bool = True, candidates=None, restarts: int = 5, seed: int = 0,
                 on_fit: Callable[[CurrentFit, int, float], Any] | None = None,
                 say: Callable[[str], Any] | None = None):
        options.check(setup)
        #: the identification's global search, as the report runs it
        self.restarts, self.seed = int(restarts), int(seed)
        self.setup, self.config, self.options = setup, config, options
        self.loop, self.candidates = loop, candidates
        self.on_fit = on_fit or (lambda fit, n, stand_s: None)
        self.say = say or log.info
        self.attribute = options.attribute()
        self.compute_s = 0.0   #: seconds spent fitting and choosing, beside the stand time
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
        return [f"adaptive campaign: coarse sweep of {f.size} steps {f[0]:g}-{f[-1]:g} Hz "
                f"(geometric), settle {self.floor_s:g} s each",
                "  " + " ".join(f"{x:.4g}" for x in f),
                f"then batches of {o.batch_size} steps where the current fit's information per "
                "second of stand time is largest (each mode's half-power band evenly in phase; "
                "resonances the residual shows where the model has none), settled as the fit's "
                f"Q asks (at least {self.floor_s:g} s), a fit after each batch (the closed loop "
                f"{'when the residual asks for it' if self.loop else 'off'})",
                f"until {', '.join(map(str, o.targets))} (the report's standard uncertainty) or "
                f"{o.max_stand_time_s:g} s of stand time"]

    def plan(self, session_path: str | None, start: int) -> Generator[StepCommand | Pause, StepOutcome | None, str]:
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
                    raise PlanError(f"the fit of {len(measured.records)} steps failed: {exc}") from None
                finally:
                    self.compute_s += time.perf_counter() - t0
                if isinstance(why, str):
                    self.say(why)
                    return why
                batch = why
            batch_no += 1
            # re-records wait the current fit's Q; the coarse sweep records once: a step still
            # ringing there is flagged and left out, and the batches measure the modes settled
            timing = replace(self.config.timing, expected_loss_factor=self._beta(),
                             **({"settle_time_constants": 0.0} if coarse else {}))
            fs = self.setup.daq.sample_rate_hz
            n_planned = index + len(batch)
            for f, settle, rec in zip(batch.frequency_hz, batch.settle_s, batch.record_s):
                first = StepCommand(index, n_planned, float(f), float(settle),
                                    record_samples(float(f), fs, self.config.timing, float(rec) or None), fs)
                last = yield from _recorded(play_step(first, timing))
                if last is not None and last.reading is not None:
                    self._keep(measured, index, first, last)
                index += 1
            batch = None
            yield Pause(f"batch {batch_no} measured")

    # -- between batches --------------------------------------------------------------------
    def _decide(self, measured: _Measured, batch_no: int):
        """Fit what is measured; the stop line, or the next :class:`Batch`."""
        from vibid.signal import afc_from_records

        o = self.options
        afc = afc_from_records(measured.records).by_frequency()
        fit = lambda previous: fit_steps(self.setup, afc, previous, loop=self.loop,  # noqa: E731
                                         candidates=self.candidates, restarts=self.restarts,
                                         seed=self.seed)
        self.fit = fit(self.fit)
        ok, where = reached(self.fit, o.targets)
        if ok and self.fit.warm:
            # the stop is the report's to decide: its own identification (a global search
            # may find rival minima that widen the std a local refit does not see)
            self.fit = fit(None)
            ok, where = reached(self.fit, o.targets)
        n = len(measured.records)
        self.on_fit(self.fit, n, measured.stand_s)
        self.progress.append(worst_ratio(self.fit, o.targets))
        effects = [t.name for t in (self.fit.result.plate_model.effects if self.fit.result.plate_model else ())]
        self.say(f"fit of {n} steps ({measured.stand_s:.1f} s of stand time): {where}"
                 f"{'; effects ' + ', '.join(effects) if effects else ''}"
                 f" ({self.fit.seconds:.1f} s)")
        tail = (f" after {n} steps, stand time {measured.stand_s:.1f} s "
                f"(computing {self.compute_s + self.fit.seconds:.0f} s beside it)")
        if ok:
            return f"target reached: {where}{tail}"
        if measured.stand_s >= o.max_stand_time_s:
            return f"stand-time cap {o.max_stand_time_s:g} s reached: {where}{tail}"
        if stalled(self.progress, [d["predicted_gain"] for d in self.history]):
            return (f"the standard uncertainty no longer falls as the steps' information "
                    f"says it should (the last {STALL_BATCHES} batches brought under "
                    f"{100 * STALL_SHARE:g} % of the predicted gain: the model's own error or "
                    f"a residual limits it, not the steps): {where}{tail}")
        measured_hz = [r.frequency_hz for r in measured.records]
        batch = next_batch(self.setup, self.config, self.fit, o, measured_hz, measured.record_s,
                           spent_s=measured.stand_s, floor_s=self.floor_s, seed=o.seed + batch_no)
        if not len(batch):
            return f"no step left under the stand-time cap {o.max_stand_time_s:g} s: {where}{tail}"
        self.history.append({"steps": n, "stand_time_s": measured.stand_s,
                             "effects": tuple(effects), "unexpected": self.fit.unexpected,
                             "batch_hz": tuple(float(f) for f in batch.frequency_hz),
                             "predicted_gain": batch.predicted_gain})
        if self.fit.unexpected:
            self.say("resonance where the model has none: " + ", ".join(
                f"{f:.1f} Hz (Q {q:.0f})" for f, q in self.fit.unexpected))
        self.say(f"batch {batch_no + 1}: {len(batch)} steps "
                 f"{', '.join(f'{f:.2f}' for f in batch.frequency_hz)} Hz, "
                 f"{batch.stand_time_s:.1f} s of stand time predicted")
        return batch

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
        measured.records.append(StepRecord(cmd.frequency_hz, r.sample_rate_hz, r.base_m_s2,
                                           r.response_m_s2, status=status, index=index))
        record_s = r.base_m_s2.size / r.sample_rate_hz
        measured.record_s.append(record_s)
        measured.stand_s += float(last.settle_s) + record_s


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

    out = _Measured()
    with read_session(path) as s:
        for step in s.steps():
            attrs = s.step_attributes(step.index)
            record_s = step.n_samples / step.sample_rate_hz
            out.records.append(StepRecord(step.frequency_hz, step.sample_rate_hz, step.base,
                                          step.response, status=step.status, index=step.index))
            out.record_s.append(record_s)
            out.stand_s += float(attrs.get("settle_s", 0.0)) + record_s
    return out
