"""The loop's rounds: diagnose → score → refit → judge → choose, each a small function over
a frozen :class:`State` (the algorithm: :mod:`vibid.identify.loop`)."""

from __future__ import annotations

import contextlib
import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2 as chi2_dist

from vibid.errors import VibidError
from vibid.identify.fit.data import FitData, fit_data
from vibid.identify.fit.minima import indistinct_chi2
from vibid.identify.fit.noise import correlation_along, misfit_scale
from vibid.identify.fit.result import IdentificationResult
from vibid.identify.fit.space import ParameterSpace
from vibid.identify.fit.strategy import identify
from vibid.identify.loop import refit as refits
from vibid.identify.loop.candidates import POLE_SPAN, all_candidates, distance_from_null
from vibid.identify.loop.scoring import extended_problem, score
from vibid.identify.loop.verdicts import Judgement, LoopResult, Score, Stage, Verdict
from vibid.identify.profile import timed
from vibid.identify.threads import in_order, numpy_only

log = logging.getLogger(__name__)

#: A candidate's score must pass this quantile of chi-square to be refitted, and its
#: refit's likelihood ratio the same to be kept.
KEEP_QUANTILE = 0.99
#: A refit that explains this share of the chi2 above the noise (chi2 - dof) answers the
#: residual as a whole: where one does, only such refits compete (:func:`choose`).
WHOLE_SHARE = 0.90
#: A kept effect must lie this many standard deviations from its null value (Wald): a
#: refit that lowers chi2 while its effect stays at the null adds nothing physical.
KEEP_Z = 3.0
#: Candidates refitted per round (the highest scores that pass the score test) ...
REFITS_PER_ROUND = 3
#: ... and beyond them, the best-scoring candidate whose feature the diagnosis found: where
#: the model's own form leaves a misfit, a candidate that shaves it scores high without
#: explaining anything, while the one a diagnosed structure asks for may score lower (the
#: crosstalk's magnitude trend asked for a gain, ranked fourth behind a clamp).
ASKED_SLOTS = 1
#: The top candidate is searched globally only when no local refit explains this share
#: of the chi2 above the noise.
SEARCH_SHARE = 0.5


@dataclass(frozen=True)
class Inputs:
    """What stays the same across the rounds."""

    setup: object
    data: FitData
    pool: tuple
    local: str
    #: (lo, hi) Hz: the bands the fit leaves out (a resonance's top whose response depends
    #: on its amplitude): no diagnosed pole inside one is a feature
    left_out_hz: tuple = ()


@dataclass(frozen=True)
class State:
    """The loop between rounds: its stages (the last is the current fit), the prior box
    of the current model's parameters, and the rounds so far."""

    stages: tuple[Stage, ...]
    box: dict
    rounds: tuple[tuple[Score, ...], ...] = ()
    #: the refits the data support that were not chosen (the models the loop compared)
    alternatives: tuple[IdentificationResult, ...] = ()

    @property
    def current(self) -> Stage:
        return self.stages[-1]


# -- the loop -----------------------------------------------------------------------------
def close_loop(setup, frequency_hz, H, std, *, used=None, candidates=None, max_rounds: int = 4,
               restarts: int = 5, seed=0, progress=None, local: str = "newton",
               declared: IdentificationResult | None = None,
               magnitude: bool = False, left_out_hz=()) -> LoopResult:
    """Fit the declared model, then add the effects its residual asks for
    (:mod:`vibid.identify.loop`).

    ``candidates``: names to consider (default every one, :func:`all_candidates`);
    ``declared``: the declared model's result when already computed;
    ``magnitude``: fit |H| alone, with the candidates |H| can see (not a channel delay);
    ``left_out_hz``: (lo, hi) Hz, the bands ``used`` leaves out because a linear model
    cannot fit them (:func:`vibid.identify.linearity.linear_part`), which the diagnoses
    ignore (:func:`diagnosis_of`).
    """
    t0 = time.perf_counter()
    pool = tuple(c for c in _pool(candidates) if not (magnitude and c.phase_only))
    if declared is None:
        declared = identify(setup, frequency_hz, H, std, used=used, restarts=restarts,
                            seed=seed, progress=progress, local=local, magnitude=magnitude)
    if not declared.noise_known:
        return LoopResult((Stage.of(None, declared),), (), False, (
            "the AFC's uncertainty is unknown: the loop cannot test the residual against the "
            "noise, so no effect was looked for",), time.perf_counter() - t0)
    inputs = Inputs(setup, fit_data(frequency_hz, H, std, used, magnitude=magnitude), pool,
                    local, tuple(left_out_hz))
    state = State((diagnosed(inputs, Stage.of(None, declared)),),
                  dict(setup.identification.bounds))
    while len(state.rounds) < max_rounds and not state.current.fits_noise:
        todo = [c for c in inputs.pool if c.applies(state.current.result.plate_model,
                                                    state.current.diagnosis)]
        if not todo:
            break
        state, added = play_round(inputs, state, todo)
        if not added:
            break
    return finish(state, time.perf_counter() - t0)


def _pool(candidates) -> tuple:
    if candidates is None:
        return all_candidates()
    known = {c.name: c for c in all_candidates()}
    unknown = sorted(set(candidates) - set(known))
    if unknown:
        raise VibidError(f"unknown candidate {', '.join(unknown)}: expected some of "
                         f"{', '.join(sorted(known))}")
    return tuple(c for c in known.values() if c.name in set(candidates))


def play_round(inputs: Inputs, state: State, todo) -> tuple[State, bool]:
    """One round: every candidate scored, the best refitted and judged, one chosen. Returns
    the next state and whether a candidate was added."""
    current = state.current
    pairs = list(in_order(lambda c: scored(inputs, current, c, state.box), todo))
    scores = [s for s, _ in pairs]
    extended = {s.name: e for s, e in pairs if e is not None}
    judged = refit_and_judge(inputs, state, todo, scores, extended)
    by_name = {c.name: c for c in todo}
    after = {n: j.diagnosis for n, j in judged.items() if j.verdict.passes}
    removes = {n: removed_feature(current.diagnosis, d, by_name[n].explains,
                                  by_name[n].resonances_hz(judged[n].fit.result.parameters,
                                                           current.result.parameters))
               for n, d in after.items()}
    scores, chosen = choose(scores, judged, current.result,
                            {c.name: c.plainness for c in todo}, removes)
    rounds = state.rounds + (tuple(scores),)
    alternatives = state.alternatives + tuple(
        judged[s.name].fit.result for s in scores
        if s.verdict.compared and (chosen is None or s.name != chosen.added))
    state = replace(state, alternatives=alternatives)
    if chosen is None:
        return replace(state, rounds=rounds), False
    cand = by_name[chosen.added]
    box = state.box | cand.bounds(state.box, current.result.parameters, current.diagnosis)
    fit = judged[chosen.added].fit
    own = refits.weighed(inputs.setup, inputs.data, fit, inputs.local)  # its own weights
    chosen, gone = withdraw(inputs, Stage.of(chosen.added, own), box,
                            [s.added for s in state.stages[1:]])
    if gone:  # a new fit (nothing held): its residual read again
        rounds = rounds[:-1] + (rounds[-1] + tuple(gone),)
        chosen = diagnosed(inputs, chosen)
    else:  # the residual of the refit it was chosen for (its weights aside, the same fit)
        chosen = replace(chosen, diagnosis=after[chosen.added],
                         held=tuple(fit.held.values) if fit.held is not None else ())
    dropped = {s.name for s in gone}
    stages = tuple(s for s in state.stages if s.added not in dropped)
    return State(stages + (chosen,), box, rounds, alternatives), True


def finish(state: State, seconds: float) -> LoopResult:
    """The loop's result: a final residual above the noise scales the covariance by the
    misfit; a kept effect nearly collinear with the declared parameters is a warning."""
    stages = list(state.stages)
    unexplained = not stages[-1].fits_noise
    if unexplained:
        stages[-1] = replace(stages[-1], result=scaled_by_misfit(stages[-1].result))
    warnings = [
        f"{s.name} is nearly collinear with the declared parameters (cosine "
        f"{s.collinearity:.5f}): the data separate them only through the "
        f"{100 * math.sqrt(max(1 - s.collinearity**2, 0)):.2g} % of its sensitivity the "
        "others cannot mimic; its std and theirs include that"
        for s in (state.rounds[-1] if state.rounds else ()) if s.kept and s.collinearity > 0.9]
    return LoopResult(tuple(stages), state.rounds, unexplained, tuple(warnings), seconds,
                      state.alternatives)


# -- diagnose -------------------------------------------------------------------------------
def diagnosed(inputs: Inputs, stage: Stage) -> Stage:
    """``stage`` with its residual's diagnosis (None where it cannot be made)."""
    return replace(stage, diagnosis=diagnosis_of(inputs.setup, stage.result,
                                                 inputs.left_out_hz))


@numpy_only
def diagnosis_of(setup, r: IdentificationResult, left_out_hz=()):
    """The diagnosis of a fit's residual (:mod:`vibid.identify.diagnosis`), or None;
    ``left_out_hz``: bands the fit leaves out, where no pole is a feature (:class:`Inputs`;
    not every unused stretch: an adaptive campaign's planner wants the pole its residual
    shows between two steps, to measure there)."""
    from vibid.identify.diagnosis import diagnose

    try:
        modes_hz, q, hidden_hz = model_resonances(setup, r)
        u = np.asarray(r.used)
        return diagnose(r.frequency_hz[u], r.H[u], r.model_afc[u],
                        None if r.H_std is None else np.asarray(r.H_std)[u],
                        plate_modes_hz=modes_hz, plate_q=q, hidden_hz=hidden_hz,
                        left_out_hz=left_out_hz)
    except Exception as exc:  # noqa: BLE001 - the diagnosis informs, it never stops a fit
        log.warning("loop: the residual could not be diagnosed: %s", exc)
        return None


def model_resonances(setup, result, n: int = 12):
    """``(frequency_hz, Q, hidden_hz)`` of the fitted model's resonances: the plate's modes
    its sensor sees and its stand resonances; and the plate's modes its sensor does not see
    (:func:`vibid.identify.model.modal.seen`)."""
    from vibid.identify.model.forward import natural_frequencies, natural_mode_heights
    from vibid.identify.model.modal import seen

    params = result.parameters
    f_hz, decay = natural_frequencies(setup, params, n)
    q = np.pi * np.asarray(f_hz) / np.maximum(np.asarray(decay), 1e-30)
    shown = seen(natural_mode_heights(setup, params, n)[1])  # the same modes, in order
    hidden_hz = np.asarray(f_hz, float)[~shown]
    f_hz, q = np.asarray(f_hz)[shown], q[shown]
    stand = [(params[t.names[0]], params[t.names[1]])  # (f_hz_k, q_k)
             for t in result.plate_model.effects if t.rotates_base]
    if stand:
        f_hz = np.concatenate([f_hz, [s[0] for s in stand]])
        q = np.concatenate([q, [s[1] for s in stand]])
    return np.asarray(f_hz, float), np.asarray(q, float), hidden_hz


def plate_modes_in_band(setup, result, n: int = 12) -> int:
    """How many of the fitted plate's modes lie within the band its data cover."""
    from vibid.identify.model.forward import natural_frequencies

    f = np.asarray(result.frequency_hz)[np.asarray(result.used)]
    f_hz, _ = natural_frequencies(setup, result.parameters, n)
    return int(np.count_nonzero((np.asarray(f_hz) >= f.min()) & (np.asarray(f_hz) <= f.max())))


# -- score ----------------------------------------------------------------------------------
@timed("loop scoring")
def scored(inputs: Inputs, current: Stage, cand, box) -> tuple[Score, tuple | None]:
    """``cand``'s score test at the current fit (a failure is its verdict, not fatal), and
    the problem of the model extended by it
    (:func:`~vibid.identify.loop.scoring.extended_problem`; None where it failed), which
    its refit starts from: built once, not again for the refit (its forward model, 0.1 s
    on the titanium strip, for each of a loop's 25 refits)."""
    asked = bool(current.diagnosis is not None and any(
        k in cand.explains for f in current.diagnosis.features for k in f.kinds))
    args = (inputs.setup, inputs.data, current.result, cand, box, current.diagnosis)
    extended = None
    try:
        extended = extended_problem(*args)
        lm, dof, cos = score(extended, current.result, cand)
    except Exception as exc:  # noqa: BLE001
        return Score(cand.name, math.nan, 0, math.nan, math.nan, verdict=Verdict.NOT_SCORED,
                     detail=(("error", str(exc)),), asked=asked), extended
    p = float(chi2_dist.sf(lm, dof))
    return Score(cand.name, lm, dof, p, cos, detail=(("p", p),), asked=asked), extended


# -- refit and judge ------------------------------------------------------------------------
def refit_and_judge(inputs: Inputs, state: State, todo, scores,
                    extended: dict | None = None) -> dict:
    """Refit the candidates whose score asks for it, best first, and judge each: name ->
    :class:`Judgement` (``extended``: name -> the extended problem the scoring built,
    :func:`scored`).

    The best few are refitted locally, with the best one the diagnosis asks for (a
    feature of its kind found) where it is not among them, and every candidate without a
    parameter of its own whose score passes (its refit is one local run from the current
    estimate, and its score, taken along the secant to the model with it, is no local
    slope: the transverse shear of a Timoshenko beam scored 806, seventh, and its refit
    lowered chi2 from 15 186 to 167), stopping at one that fits the noise. The
    best-scoring candidate whose basin may lie elsewhere (a new material) comes after the
    others: where their refits leave most of the misfit unexplained, it is
    searched globally over its box, its local refit run beside the search only where the
    search does not settle it (on the CFRP plate the local refit of the orthotropic
    material, 9 s, ended at a chi2 a million times the search's); else it is refitted
    locally if it is among the refitted. An effect is not searched: its new
    parameters start at their null or where the diagnosis placed them, in the basin the
    declared fit's own search found. While the current estimate lies outside its prior
    box every candidate is refitted, whatever its score (the top one searched first if it
    is a new material): the effect behind an excursion scores low at the bent estimate
    (the bent parameter already mimics it), and its refit starts with the bent parameters
    back inside the box."""
    res = state.current.result
    by_name = {c.name: c for c in todo}
    judged = {}
    n_residuals = inputs.data.n_residuals
    for s in scores:
        n = len(by_name[s.name].extend(res.plate_model).names)
        if s.verdict is Verdict.BELOW_SCORE and n >= n_residuals:
            judged[s.name] = Judgement(Verdict.TOO_FEW_POINTS,
                                       (("n", n), ("residuals", n_residuals)))
    for s in scores:
        needed = by_name[s.name].modes_needed(res.plate_model)
        if s.name not in judged and needed:
            modes = plate_modes_in_band(inputs.setup, res)
            if modes < needed:
                judged[s.name] = Judgement(Verdict.NO_MODE_PATTERN,
                                           (("modes", modes), ("needed", needed)))
    outside = outside_prior(res, state.box)
    if outside:
        log.info("loop: %s outside the prior box: every candidate is refitted",
                 _values(res, outside, state.box))
    asking = sorted((s for s in scores if s.name not in judged and np.isfinite(s.score)
                     and (outside or s.score > chi2_dist.ppf(KEEP_QUANTILE, s.dof))),
                    key=lambda s: -s.score)
    ranked = refit_order(asking, bool(outside))
    ranked += [s for s in asking if s not in ranked and not set(by_name[s.name].extend(
        res.plate_model).names) - set(res.parameter_names)]  # no parameter: one run each
    refitted = {s.name for s in ranked}
    for s in asking:
        if s.name not in refitted:
            judged[s.name] = Judgement(Verdict.NOT_REFITTED)
    excess = max(res.chi2 - res.dof, 0.0)

    def attempt(s: Score, search: bool):
        cand = by_name[s.name]
        log.info("loop: refitting %s (score %.4g%s)", s.name, s.score,
                 ", searched globally" if search else "")
        try:
            fit = refits.refit(inputs.setup, inputs.data, res, cand, state.box,
                               state.current.diagnosis, inputs.local, search=search,
                               extended=(extended or {}).get(s.name))
        except Exception as exc:  # noqa: BLE001 - a failing refit is reported, not fatal
            return Judgement(Verdict.REFIT_FAILED, (("error", str(exc)),))
        j = judge(cand, s, fit, res, state.box, outside, state.current.diagnosis)
        if not j.verdict.passes:
            return j
        # a passing refit's residual, read once, on its own thread beside the next refit
        return replace(j, diagnosis=diagnosis_of(inputs.setup, fit.result, inputs.left_out_hz))

    basin = next((s for s in asking if by_name[s.name].moves_basin), None)
    later = None if outside else basin  # judged after the rest
    first = [s for s in ranked if s is not later]
    searched_first = bool(outside) and bool(first) and by_name[first[0].name].moves_basin
    fits_noise = False
    with contextlib.closing(in_order(  # the next refits start early (vibid.identify.threads)
            lambda k: attempt(first[k], searched_first and k == 0), range(len(first)))) as runs:
        for k, (s, j) in enumerate(zip(first, runs)):
            judged[s.name] = j
            fits_noise = j.verdict.passes and Stage.of(s.name, j.fit.result).fits_noise
            if fits_noise:
                for rest in first[k + 1:] + ([later] if later in ranked else []):
                    # another could at best tie, for a refit's price
                    judged[rest.name] = Judgement(Verdict.NOT_REFITTED, (("by", s.name),))
                break
    if not fits_noise:
        explained = max((j.gain for j in judged.values() if j.verdict.passes), default=0.0)
        if later is not None:
            search = explained < SEARCH_SHARE * excess  # its local refit only if unsettled
            if search or later in ranked:
                judged[later.name] = attempt(later, search)
    return judged


def refit_order(asking: list[Score], outside: bool) -> list[Score]:
    """Which of the scores that ask for a refit (highest first) are refitted, in order:
    every one while the estimate is outside its prior box, else the best
    :data:`REFITS_PER_ROUND` and, after them, the best :data:`ASKED_SLOTS` the diagnosis
    asks for among the rest."""
    ranked = asking[:None if outside else REFITS_PER_ROUND]
    return ranked + [s for s in asking[len(ranked):] if s.asked][:ASKED_SLOTS]


def judge(cand, s: Score, fit: refits.Refit, res, box, outside,
          diagnosis=None) -> Judgement:
    """The verdict on one refit: converged, a resonance the diagnosis placed still at its
    pole (inside the spans :data:`~vibid.identify.loop.candidates.POLE_SPAN` and
    :data:`~vibid.identify.loop.candidates.Q_SPAN` around it, not on their faces), its
    effect :data:`KEEP_Z` std from its null and not past its box towards a null at
    infinity (a clamp stiffer than the box's stiffest is the rigid clamp), every
    parameter the current fit had inside
    its prior box still inside it (an orthotropic refit of a steel beam whose D22 fell to
    2 % of D11 explains a residual with no physical material), significant under the
    current weights (likelihood ratio past :data:`KEEP_QUANTILE`), lower in chi2 under its
    own weights, and significant under the residual's own error too: where a misfit no
    candidate explains remains, every extra parameter lowers chi2 a little and passes the
    likelihood-ratio test, which takes the residual for white noise; the misfit's reduced
    chi2 and its correlation along frequency as the refit's change of the model sees it
    (:func:`~vibid.identify.fit.noise.misfit_scale`,
    :func:`~vibid.identify.fit.noise.correlation_along`: a narrow resonance sees fewer
    neighbours of a smooth misfit than a gain does) say how much a parameter that
    explains nothing removes from it, and the likelihood ratio must pass the same quantile
    in those units (the loop's final covariance is scaled by the same two); or,
    while the estimate is outside its prior box, one that brings it back inside at a chi2
    the data cannot tell from the current one (the excursion was this effect)."""
    r, gain = fit.result, fit.gain
    detail = (("searched", fit.searched),)
    if fit.held is not None:  # parameters the refit held inside their box
        detail += (("held", fit.held.sentence),)
    if not r.converged:
        return Judgement(Verdict.NOT_CONVERGED, detail + (("message", r.message),), fit)
    moved = cand.strayed(r.parameters, res.parameters, diagnosis)
    if moved:
        return Judgement(Verdict.LEFT_ITS_FEATURE, detail + (("moved", moved),), fit)
    z = cand.distance_from_null(r)
    if z <= KEEP_Z:
        return Judgement(Verdict.AT_NULL, detail + (("z", z),), fit)
    own = box | cand.bounds(box, res.parameters, diagnosis)
    beyond = cand.beyond_null(r, own)
    if beyond:
        return Judgement(Verdict.AT_NULL, detail + (("beyond", beyond),), fit)
    need = float(chi2_dist.ppf(KEEP_QUANTILE, s.dof))
    significant = gain > need and r.chi2 < res.chi2
    birge, tau = misfit_scale(res)
    if tau > 1.0:  # the residual's correlation as the refit's change sees it
        tau = correlation_along(res, r)
    left = tuple(n for n in outside_prior(r, own) if n not in idle_parameters(r, cand.name))
    strayed = [n for n in left if n not in outside]
    if strayed:
        return Judgement(Verdict.OUTSIDE_PRIOR, detail + (("left", _values(r, strayed, own)),),
                         fit, left)
    if significant and gain > need * birge * tau:
        return Judgement(Verdict.OUTRANKED, detail, fit, left)  # passes; choose() decides
    if outside and not left and gain >= -indistinct_chi2(len(r.values),
                                                         max(1.0, float(res.chi2_reduced))):
        return Judgement(Verdict.EXPLAINS_EXCURSION,
                         detail + (("outside", ", ".join(outside)),), fit, left)
    if significant:
        return Judgement(Verdict.WITHIN_MISFIT, detail + (
            ("gain", gain), ("need", need * birge * tau), ("birge", birge), ("tau", tau)),
            fit, left)
    return Judgement(Verdict.NOT_SIGNIFICANT, detail, fit, left)


def idle_parameters(result, but: str) -> set[str]:
    """The parameters of ``result``'s effects (but ``but``) that it leaves at their null:
    where such an effect has nothing left to explain, its parameters may wander outside
    their box (a stand resonance's frequency, once a new material places the peak it stood
    in for), and the withdrawal removes it."""
    return {n for t in result.plate_model.effects
            if t.name != but and t.parameters and distance_from_null(t, result) <= KEEP_Z
            for n in t.names}


def _values(result, names, box) -> str:
    """``names``' values in ``result`` beside their prior boxes, in words."""
    bounds = result.plate_model.default_bounds(box)
    return ", ".join(f"{n} {result.parameters[n]:.3g} (box {bounds[n][0]:.3g} to "
                     f"{bounds[n][1]:.3g})" for n in names)


# -- withdraw ---------------------------------------------------------------------------------
def withdraw(inputs: Inputs, stage: Stage, box: dict, added: list) -> tuple[Stage, list]:
    """``stage`` less the effects added in earlier rounds that it leaves at their null
    value (the new effect explains what they stood in for: an isotropic fit's extra peak
    taken for a stand resonance, then the orthotropic material that places it), where the
    data cannot tell the model without one from the model with it (likelihood ratio,
    data weights, below :data:`KEEP_QUANTILE` in units of the reduced chi2). Returns the
    stage and a :class:`Score` per withdrawn effect."""
    from vibid.identify.model.forward import build_forward_model

    gone = []
    for term in reversed(stage.result.plate_model.effects):
        res = stage.result
        if term.name == stage.added or term.name not in added or not term.parameters:
            continue
        z = distance_from_null(term, res)
        if z > KEEP_Z:
            continue
        model = res.plate_model.without_effect(term)
        start = {n: v for n, v in res.parameters.items() if n in model.names}
        d = inputs.data
        fm = build_forward_model(inputs.setup, d.frequency_hz[d.used], model=model,
                                 theta0=start, bounds=model.default_bounds(box))
        try:
            smaller = identify(inputs.setup, d.frequency_hz, d.H, d.std, used=d.used,
                               model=model.model, forward_model=fm, method="local",
                               start=start, bounds=model.default_bounds(box),
                               local=inputs.local, magnitude=d.magnitude)
        except Exception as exc:  # noqa: BLE001 - the larger model stays
            log.info("loop: %s could not be refitted without %s: %s", stage.added,
                     term.name, exc)
            continue
        lr = (smaller.chi2_reduced_reported * smaller.dof - res.chi2_reduced_reported * res.dof)
        limit = chi2_dist.ppf(KEEP_QUANTILE, len(term.parameters)) * max(
            1.0, res.chi2_reduced_reported)
        if not (smaller.converged and lr < limit):
            continue
        stage = Stage.of(stage.added, smaller)
        gone.append(Score(term.name, math.nan, len(term.parameters), math.nan, math.nan,
                          delta_chi2=-float(lr), verdict=Verdict.WITHDRAWN,
                          detail=(("by", stage.added), ("z", z))))
    return stage, gone


def outside_prior(result: IdentificationResult, box: dict) -> list[str]:
    """Names of ``result``'s parameters outside (or on a face of) their prior box."""
    bounds = result.plate_model.default_bounds(box)
    space = ParameterSpace.from_bounds(result.parameter_names, bounds,
                                       {q.name: q.kind for q in result.plate_model.parameters})
    return space.out_of_bounds(result.values)


# -- choose ---------------------------------------------------------------------------------
def removed_feature(before, after, kinds, resonances_hz=()):
    """The most significant feature of the diagnosis ``before`` of a kind in ``kinds`` that
    the refit's diagnosis ``after`` no longer shows (none of its kind near it at half its
    significance or more), or None. Of a trend, a candidate that explains some of its
    parts (:data:`~vibid.identify.diagnosis.TREND_PARTS`: a gain its mean offset, a delay
    its phase) removed it where no trend after keeps half of any of those parts: the steel
    strip's gain took the trend's −8.4 % offset and left its phase and a rise across the
    band, at 0.51 of its significance. A candidate whose refit placed resonances
    (``resonances_hz``, :meth:`~vibid.identify.loop.candidates.EffectCandidate.
    resonances_hz`) removed only the features within :data:`~vibid.identify.loop.
    candidates.POLE_SPAN` of one of them: the calibrated titanium run's fixture, its
    resonance at 666 Hz, was credited with a broad pole at 1 338 Hz that its refit's
    other changes had smoothed away."""
    if before is None or after is None or not before.features:
        return None

    def around(f) -> bool:
        if not resonances_hz:
            return True
        return bool(np.isfinite(f.f_hz) and f.f_hz > 0) and any(
            abs(math.log(f.f_hz / r)) <= math.log(POLE_SPAN) for r in resonances_hz if r > 0)

    def remains(f) -> bool:
        parts = set(f.parts) & set(kinds)  # the parts of a trend the candidate explains
        return any(g.kind == f.kind and g.significance >= 0.5 * f.significance
                   and (f.kind == "trend" or abs(g.f_hz - f.f_hz) <= 0.03 * f.f_hz)
                   and (not parts or any(g.part_size(p) >= 0.5 * f.part_size(p)
                                         for p in parts))
                   for g in after.features)

    gone = [f for f in before.features
            if set(f.kinds) & set(kinds) and not remains(f) and around(f)]
    return max(gone, key=lambda f: f.significance, default=None)


def choose(scores, judged: dict, res, plainness: dict,
           removes: dict | None = None) -> tuple[list[Score], Stage | None]:
    """The candidate the round adds, and every score with its final verdict (``judged``:
    name -> :class:`Judgement`, left as it is).

    One that brings the estimate back inside its prior box and competes (below) goes
    first (an effect that leaves it outside is kept back). Among the rest, the refits that
    explain :data:`WHOLE_SHARE` of the misfit compete where there are any; where
    there are none, only those whose refit removes a diagnosed feature (``removes``:
    name -> the feature it removed) or explains a bent estimate's excursion compete, and
    the others are ``no_structure`` (a share of a misfit that remains is no explanation:
    any extra parameter shaves some). Of those competing, an effect is chosen for the
    structure it explains: the ones whose refit removes the most significant diagnosed
    feature compete, or all where none removes one; of those whose chi2 the data cannot
    tell from the best's, the plainest explanation wins: one whose feature the diagnosis
    found before one without, an effect before a new material, then the larger likelihood
    ratio."""
    removes = removes or {}
    final = dict(judged)
    passing = [n for n, j in judged.items() if j.verdict.passes]
    excess = max(float(res.chi2 - res.dof), 0.0)

    def competitors(names):
        """``(whole, competing)``: a refit that explains :data:`WHOLE_SHARE` of the misfit
        answers the residual as a whole, and only such refits
        compete where there are any (the orthotropic plate's anisotropy, 99.99998 % of the
        misfit, against a stand resonance, 18 %, that removed the isotropic fit's most
        significant pole); else only a refit that removes a diagnosed structure (or brings
        a bent estimate back inside its box) explains something: shaving a share off a
        misfit that remains is what any extra parameter does (a free length on a
        crosstalk)."""
        whole = [n for n in names if judged[n].gain >= WHOLE_SHARE * excess]
        return whole, whole or [n for n in names if removes.get(n)
                                or judged[n].verdict is Verdict.EXPLAINS_EXCURSION]

    # an effect that leaves the estimate outside its box is kept back for one that brings
    # it inside and competes, not for one that only shaves a share (a stiff clamp under a
    # stand resonance: the clamp's refit took 26 % of the misfit with nu back inside, the
    # resonance's 90 % with nu still bent, and nothing was added)
    inside = [n for n in passing if not judged[n].left]
    whole, competing = competitors(inside)
    if competing:
        for n in [n for n in passing if judged[n].left]:
            final[n] = judged[n].becomes(Verdict.KEPT_BACK, left=", ".join(judged[n].left))
        passing = inside
    else:
        whole, competing = competitors(passing)
    if not whole:
        for n in [n for n in passing if n not in competing]:
            left_share = 100 * (1 - judged[n].gain / excess) if excess > 0 else 0.0
            final[n] = judged[n].becomes(Verdict.NO_STRUCTURE, left_share=left_share)
        passing = competing
    chosen = plainest(competing, judged, removes, res, {s.name: s.asked for s in scores},
                      plainness) if competing else None
    for n in passing:
        j = judged[n]
        if n != chosen:
            final[n] = j.becomes(Verdict.OUTRANKED, by=chosen)
        else:
            verdict = (j.verdict if j.verdict is Verdict.EXPLAINS_EXCURSION
                       else Verdict.CHOSEN)
            feature = {"feature": removes[n].note} if removes.get(n) else {}
            final[n] = j.becomes(verdict, **feature)
    out = [replace(s, verdict=final[s.name].verdict, detail=final[s.name].detail,
                   delta_chi2=final[s.name].gain) if s.name in final else s for s in scores]
    stage = Stage.of(chosen, judged[chosen].fit.result) if chosen else None
    return out, stage


def plainest(competing, judged: dict, removes: dict, res, asked: dict, plainness: dict):
    """Of the ``competing`` refits, those that remove the most significant diagnosed
    feature (all where none removes one); of those whose chi2 the data cannot tell from
    the best's (in the units of the misfit that remains, :func:`judge`), the plainest:
    asked for by the diagnosis, then an effect before a new material, then the larger
    likelihood ratio."""
    top = max((f.significance for n, f in removes.items() if n in competing and f),
              default=None)
    pool = [n for n in competing if top is None or (removes.get(n) and
                                                   removes[n].significance == top)]
    # gains are all under the current fit's weights: comparable, and told apart in the
    # units of the misfit that remains (the judge's second test)
    best = max(judged[n].gain for n in pool)
    tie = indistinct_chi2(1, math.prod(misfit_scale(res)))
    rivals = [n for n in pool if judged[n].gain >= best - tie]
    return min(rivals, key=lambda n: (not asked[n], plainness[n], -judged[n].gain))


def scaled_by_misfit(result: IdentificationResult) -> IdentificationResult:
    """``result`` with its covariance scaled by its reduced chi2 when that exceeds 1 (the
    standard deviations by the Birge ratio ``√chi2_red``), and by the residual's
    autocorrelation time along frequency ``tau``
    (:func:`~vibid.identify.fit.noise.residual_correlation`: a misfit that is a smooth
    model-form error spans ``tau`` neighbouring points, which then count as one), the
    warning saying so in place of the one that they understate the error."""
    birge, tau = misfit_scale(result)
    if birge <= 1.0:
        return result
    k = birge * tau
    note = (f"the standard deviations are scaled by sqrt(reduced chi2) = {math.sqrt(birge):.3g}"
            f" and by sqrt(tau) = {math.sqrt(tau):.3g} for the residual's correlation along "
            f"frequency (about {tau:.3g} neighbouring points per independent one): the "
            "residual holds more than the noise, and the misfit measures the error")
    kept = tuple(w for w in result.warnings if "understate the error" not in w)
    std = result.std * math.sqrt(k)
    poor = tuple(
        f"{n} is poorly determined by these data (scaled std {sd:.2g} = "
        f"{100 * sd / abs(v):.0f} % of its value)"
        for n, v, sd, s0 in zip(result.parameter_names, result.values, std, result.std)
        if abs(v) > 0 and np.isfinite(sd) and sd > 0.3 * abs(v) and not s0 > 0.3 * abs(v))
    return replace(result, std=std, covariance=result.covariance * k,
                   warnings=kept + (note,) + poor)
