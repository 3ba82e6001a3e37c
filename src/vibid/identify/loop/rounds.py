"""The loop's rounds: propose → fit → compare → choose, each a small function over a
frozen :class:`State` (the algorithm: :mod:`vibid.identify.loop`)."""

from __future__ import annotations

import contextlib
import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2 as chi2_dist

from vibid.errors import VibidError
from vibid.identify.engine.profile import timed
from vibid.identify.engine.threads import in_order, numpy_only
from vibid.identify.fit.data import FitData, fit_data
from vibid.identify.fit.noise import misfit_scale
from vibid.identify.fit.result import IdentificationResult
from vibid.identify.fit.strategy import Measurement, SearchOptions, identify
from vibid.identify.loop import refit as refits
from vibid.identify.loop.candidates import Place, all_candidates, distance_from_null
from vibid.identify.loop.evidence import (
    Noise,
    approximate,
    log_evidence,
    prior_space,
    probabilities,
)
from vibid.identify.loop.policy import DEFAULT, Policy
from vibid.identify.loop.scoring import extended_problem, score
from vibid.identify.loop.verdicts import Judgement, LoopResult, Score, Stage, Verdict
from vibid.identify.model.plate import Modes, Plate

log = logging.getLogger(__name__)

STOP = None  # the explanation "the current model, nothing added"


@dataclass(frozen=True)
class Inputs:
    """What stays the same across the rounds: the declared plate (the model every
    question of the loop is asked of), the data, the candidates, the local method."""

    plate: Plate
    data: FitData
    pool: tuple
    local: str
    #: (lo, hi) Hz: the bands the fit leaves out (a resonance's top whose response depends
    #: on its amplitude): no diagnosed pole inside one is a feature
    left_out_hz: tuple = ()
    policy: Policy = DEFAULT


@dataclass(frozen=True)
class State:
    """The loop between rounds: its stages (the last is the current fit), the box its fits
    search within (a placed resonance's span around its pole), the physical prior box of
    the current model's parameters (the evidence's), and the rounds so far."""

    stages: tuple[Stage, ...]
    box: dict
    prior: dict
    rounds: tuple[tuple[Score, ...], ...] = ()
    #: the refits compared that were not chosen (the models the loop compared)
    alternatives: tuple[IdentificationResult, ...] = ()

    @property
    def current(self) -> Stage:
        return self.stages[-1]


# -- the loop -----------------------------------------------------------------------------
def close_loop(
    setup,
    frequency_hz,
    H,
    std,
    *,
    used=None,
    candidates=None,
    max_rounds: int = 4,
    restarts: int = 5,
    seed=0,
    progress=None,
    local: str = "newton",
    declared: IdentificationResult | None = None,
    magnitude: bool = False,
    left_out_hz=(),
    policy: Policy = DEFAULT,
) -> LoopResult:
    """Fit the declared model, then add the explanations its residual makes most probable
    (:mod:`vibid.identify.loop`).

    ``candidates``: names to consider (default every one, :func:`all_candidates`);
    ``declared``: the declared model's result when already computed;
    ``magnitude``: fit |H| alone, with the candidates |H| can see (not a channel delay);
    ``left_out_hz``: (lo, hi) Hz, the bands ``used`` leaves out because a linear model
    cannot fit them (:func:`vibid.identify.assess.linearity.linear_part`), which the diagnoses
    ignore (:func:`diagnosis_of`); ``policy``: the loop's numbers
    (:class:`~vibid.identify.loop.policy.Policy`).
    """
    t0 = time.perf_counter()
    pool = tuple(c for c in _pool(candidates, policy) if not (magnitude and c.phase_only))
    if declared is None:
        declared = identify(
            setup,
            Measurement(frequency_hz, H, std, used=used, magnitude=magnitude),
            search=SearchOptions(local=local, restarts=restarts, seed=seed, progress=progress),
        )
    if not declared.noise_known:
        return LoopResult(
            (Stage.of(None, declared),),
            (),
            False,
            (
                "the AFC's uncertainty is unknown: the loop cannot test the residual against the "
                "noise, so no effect was looked for",
            ),
            time.perf_counter() - t0,
        )
    inputs = Inputs(
        Plate(setup),
        fit_data(frequency_hz, H, std, used, magnitude=magnitude),
        pool,
        local,
        tuple(left_out_hz),
        policy,
    )
    box = dict(setup.identification.bounds)
    state = State((diagnosed(inputs, Stage.of(None, declared)),), box, box)
    while len(state.rounds) < max_rounds and not state.current.fits_noise:
        proposals = propose(inputs, state)
        if not proposals:
            break
        state, added = play_round(inputs, state, proposals)
        if not added:
            break
    return finish(state, time.perf_counter() - t0)


def _pool(candidates, policy: Policy) -> tuple:
    if candidates is None:
        return all_candidates(policy)
    known = {c.name: c for c in all_candidates(policy)}
    unknown = sorted(set(candidates) - set(known))
    if unknown:
        raise VibidError(
            f"unknown candidate {', '.join(unknown)}: expected some of {', '.join(sorted(known))}"
        )
    return tuple(c for c in known.values() if c.name in set(candidates))


def play_round(inputs: Inputs, state: State, proposals) -> tuple[State, bool]:
    """One round: every proposal scored, the most promising refitted, every explanation
    compared by its evidence, the most probable chosen (stopping among them). Returns the
    next state and whether something was added."""
    current = state.current
    noise = Noise.of(current.result, inputs.data.n_residuals)
    now = log_evidence(current.result, state.prior, noise)
    scores, extended, by_name = score_all(inputs, state, proposals, noise, now.log_z)
    judged = fit_and_weigh(inputs, state, by_name, scores, extended, noise)
    scores, chosen, shares = compare(scores, judged, now.log_z, inputs.policy)
    rounds = state.rounds + (tuple(scores),)
    alternatives = state.alternatives + tuple(
        judged[s.name].fit.result for s in scores if s.verdict.compared and s.name != chosen
    )
    stages = state.stages[:-1] + (replace(current, alternatives=shares),)
    state = replace(state, stages=stages, rounds=rounds, alternatives=alternatives)
    if chosen is STOP:
        return state, False
    cand = by_name[chosen]
    values = current.result.parameters
    box = state.box | cand.bounds(state.box, values, current.diagnosis)
    prior = with_prior(state.prior, cand, values)
    fit = judged[chosen].fit
    own = refits.weighed(inputs.plate, inputs.data, fit, inputs.local)  # its own weights
    stage, gone = withdraw(
        inputs, Stage.of(chosen, own), box, prior, [s.added for s in state.stages[1:]]
    )
    if gone:
        rounds = rounds[:-1] + (rounds[-1] + tuple(gone),)
    stage = replace(
        diagnosed(inputs, stage),
        held=tuple(fit.held.values) if fit.held is not None and not gone else (),
    )
    dropped = {s.name for s in gone}
    kept = tuple(s for s in state.stages if s.added not in dropped)
    return State(kept + (stage,), box, prior, rounds, alternatives), True


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
        for s in (state.rounds[-1] if state.rounds else ())
        if s.kept and s.collinearity > 0.9
    ]
    return LoopResult(
        tuple(stages), state.rounds, unexplained, tuple(warnings), seconds, state.alternatives
    )


def with_prior(prior: dict, cand, values: dict) -> dict:
    """The physical prior box ``prior`` of the current model's parameters with ``cand``'s
    new ones (the evidence's prior of the model extended by it)."""
    return prior | cand.prior_bounds(prior, values)


# -- propose ---------------------------------------------------------------------------------
def propose(inputs: Inputs, state: State) -> list:
    """Every candidate of the pool that applies to the current model (a structural fact,
    :meth:`~vibid.identify.loop.candidates.EffectCandidate.applies`), a resonance once per
    place to try it: each diagnosed pole and the residual's largest maxima along the band
    (:func:`residual_peaks`)."""
    current = state.current
    model = current.result.plate_model
    peaks = residual_peaks(current.result, inputs.policy)
    return [
        p for c in inputs.pool if c.applies(model) for p in c.placements(current.diagnosis, peaks)
    ]


def residual_peaks(result, policy: Policy) -> tuple[Place, ...]:
    """The frequencies of the :attr:`Policy.band_trials` largest local maxima of the
    weighted residual's magnitude along the band (with the policy's trial Q): where a
    resonance the diagnosis did not find may stand."""
    u = np.asarray(result.used)
    f = np.asarray(result.frequency_hz)[u]
    order = np.argsort(f)
    r = np.abs(
        (np.asarray(result.model_afc)[u] - np.asarray(result.H)[u]) / np.asarray(result.weights)
    )[order]
    f = f[order]
    if r.size < 3:
        return ()
    inner = np.flatnonzero((r[1:-1] >= r[:-2]) & (r[1:-1] >= r[2:])) + 1
    top = inner[np.argsort(-r[inner])][: policy.band_trials]
    return tuple(Place(float(f[i]), policy.trial_q, "residual_peak") for i in top)


# -- diagnose -------------------------------------------------------------------------------
def diagnosed(inputs: Inputs, stage: Stage) -> Stage:
    """``stage`` with its fitted plate's modes (:meth:`Plate.modes`, asked once per stage)
    and its residual's diagnosis (either None where it cannot be made)."""
    modes = modes_of(inputs.plate, stage.result)
    return replace(
        stage, modes=modes, diagnosis=diagnosis_of(modes, stage.result, inputs.left_out_hz)
    )


def modes_of(plate: Plate, result: IdentificationResult, n: int = 12) -> Modes | None:
    """The first ``n`` modes of the plate at ``result``'s estimate, or None (logged) where
    its modal problem cannot be solved: then no diagnosis is made, and no candidate that
    needs the modes in the band is tried."""
    try:
        return plate.modes(result.parameters, n)
    except Exception as exc:  # noqa: BLE001 - the modes inform, they never stop a fit
        log.warning("loop: the fitted plate's modes could not be computed: %s", exc)
        return None


@numpy_only
def diagnosis_of(modes: Modes | None, r: IdentificationResult, left_out_hz=()):
    """The diagnosis of a fit's residual (:mod:`vibid.identify.loop.diagnosis`) given its
    plate's ``modes``, or None; ``left_out_hz``: bands the fit leaves out, where no pole is
    a feature (:class:`Inputs`; not every unused stretch: an adaptive campaign's planner
    wants the pole its residual shows between two steps, to measure there)."""
    from vibid.identify.loop.diagnosis import diagnose

    if modes is None:
        return None
    try:
        modes_hz, q, hidden_hz = model_resonances(modes, r)
        u = np.asarray(r.used)
        return diagnose(
            r.frequency_hz[u],
            r.H[u],
            r.model_afc[u],
            None if r.H_std is None else np.asarray(r.H_std)[u],
            plate_modes_hz=modes_hz,
            plate_q=q,
            hidden_hz=hidden_hz,
            left_out_hz=left_out_hz,
        )
    except Exception as exc:  # noqa: BLE001 - the diagnosis informs, it never stops a fit
        log.warning("loop: the residual could not be diagnosed: %s", exc)
        return None


def model_resonances(modes: Modes, result):
    """``(frequency_hz, Q, hidden_hz)`` of the fitted model's resonances: the plate's
    ``modes`` its sensor sees and its stand resonances; and the plate's modes its sensor
    does not see (:attr:`Modes.seen`)."""
    params = result.parameters
    shown = modes.seen
    hidden_hz = modes.frequency_hz[~shown]
    f_hz, q = modes.frequency_hz[shown], modes.q[shown]
    stand = [
        (params[t.names[0]], params[t.names[1]])  # (f_hz_k, q_k)
        for t in result.plate_model.effects
        if t.rotates_base
    ]
    if stand:
        f_hz = np.concatenate([f_hz, [s[0] for s in stand]])
        q = np.concatenate([q, [s[1] for s in stand]])
    return np.asarray(f_hz, float), np.asarray(q, float), hidden_hz


def plate_modes_in_band(modes: Modes | None, result) -> int:
    """How many of the fitted plate's ``modes`` (:attr:`Stage.modes`) lie within the band
    ``result``'s data cover (0 where its modes are unknown)."""
    f = np.asarray(result.frequency_hz)[np.asarray(result.used)]
    return 0 if modes is None else modes.in_band(f.min(), f.max())


# -- score -----------------------------------------------------------------------------------
def score_all(inputs: Inputs, state: State, proposals, noise: Noise, log_z_now: float):
    """Every proposal's score test at the current fit and its approximate evidence
    (:func:`~vibid.identify.loop.evidence.approximate`), one per candidate: of a
    resonance's places, the best. Returns ``(scores, extended, candidates)``: the scores,
    name -> the extended problem its refit starts from, name -> the candidate (at its
    place)."""
    current = state.current
    groups: dict = {}
    for c in proposals:  # a candidate's places in turn, on one forward model
        groups.setdefault(c.name, []).append(c)

    def at_its_places(group):
        out, like = [], None
        for c in group:
            s, e = scored(inputs, current, c, state, noise, log_z_now, like)
            like = like or e
            out.append((c, s, e))
        return out

    scores, extended, cands = [], {}, {}
    for tried in in_order(at_its_places, list(groups.values())):
        cand, s, e = max(tried, key=lambda t: np.nan_to_num(t[1].log_evidence, nan=-np.inf))
        if len(tried) > 1:
            s = replace(
                s,
                detail=s.detail
                + (
                    (
                        "places",
                        ", ".join(
                            f"{c.at.f_hz:.4g} Hz ({t.score:.3g})"
                            for c, t, _ in tried
                            if np.isfinite(t.score)
                        ),
                    ),
                ),
            )
        scores.append(s)
        cands[cand.name] = cand
        if e is not None:
            extended[cand.name] = e
    return scores, extended, cands


@timed("loop scoring")
def scored(
    inputs: Inputs, current: Stage, cand, state: State, noise: Noise, log_z_now: float, like=None
) -> tuple[Score, tuple | None]:
    """``cand``'s score test at the current fit and its approximate evidence (a failure is
    its verdict, not fatal), and the problem of the model extended by it
    (:func:`~vibid.identify.loop.scoring.extended_problem`; None where it failed), which
    its refit starts from: built once, not again for the refit."""
    args = (inputs.plate, inputs.data, current.result, cand, state.box, current.diagnosis, like)
    extended = None
    at = {} if cand.at is None else {"at_hz": cand.at.f_hz}
    try:
        extended = extended_problem(*args)
        lm, dof, cos, info = score(
            extended, current.result, cand, with_prior(state.prior, cand, current.result.parameters)
        )
    except Exception as exc:  # noqa: BLE001
        return Score(
            cand.name,
            math.nan,
            0,
            math.nan,
            math.nan,
            verdict=Verdict.NOT_SCORED,
            detail=(("error", str(exc)),),
            **at,
        ), extended
    p = float(chi2_dist.sf(lm, dof))
    log_z = approximate(log_z_now, noise, float(current.result.chi2), lm, info)
    return Score(
        cand.name, lm, dof, p, cos, detail=(("p", p),), log_evidence=log_z, estimated=True, **at
    ), extended


# -- fit ---------------------------------------------------------------------------------------
def fit_and_weigh(
    inputs: Inputs, state: State, cands: dict, scores, extended: dict, noise: Noise
) -> dict:
    """Refit the candidates of highest approximate evidence and weigh each refit's
    evidence: name -> :class:`Judgement`.

    Guards first, each a fact: a model with as many parameters as the data have real
    numbers cannot be fitted (``too_few_points``), and a new material needs more of the
    plate's modes in the band than the current material has stiffnesses, which place any
    fewer (``no_mode_pattern``). Of the rest, the :attr:`Policy.refits_per_round` of
    highest approximate evidence are refitted, and every one without a parameter of its own
    (its refit is one local run, and its score, along the secant to the model with it, is
    no local slope); every one while the current estimate lies outside its prior box (the
    score at a bent estimate says little: the bent parameter already mimics the effect).
    A new material is refitted after the effects, searched globally over its box where
    their refits leave more than :attr:`Policy.search_share` of the misfit or the current
    estimate lies outside its box (its basin may lie far from the current fit's, and a
    bent estimate's basin is suspect), and not where an effect's refit already fits the
    noise (a search costs what the whole round does)."""
    res = state.current.result
    policy = inputs.policy
    judged = guarded(inputs, state.current, cands, scores)
    outside = outside_prior(res, state.prior)
    if outside:
        log.info(
            "loop: %s outside the prior box: every candidate is refitted",
            _values(res, outside, state.prior),
        )
    open_ = sorted(
        (s for s in scores if s.name not in judged and np.isfinite(s.log_evidence)),
        key=lambda s: -s.log_evidence,
    )
    own_free = [
        s
        for s in open_
        if not set(cands[s.name].extend(res.plate_model).names) - set(res.parameter_names)
    ]
    ranked = open_ if outside else open_[: policy.refits_per_round]
    ranked = ranked + [s for s in own_free if s not in ranked]
    for s in open_:
        if s not in ranked:
            judged[s.name] = Judgement(Verdict.NOT_REFITTED)
    excess = max(res.chi2 - res.dof, 0.0)

    def attempt(s: Score, search: bool) -> Judgement:
        cand = cands[s.name]
        log.info(
            "loop: refitting %s (approximate log evidence %.4g%s)",
            cand.label,
            s.log_evidence,
            ", searched globally" if search else "",
        )
        try:
            fit = refits.refit(
                inputs.plate,
                inputs.data,
                res,
                cand,
                state.box,
                state.current.diagnosis,
                inputs.local,
                search=search,
                extended=extended.get(s.name),
                policy=policy,
            )
        except Exception as exc:  # noqa: BLE001 - a failing refit is reported, not fatal
            return Judgement(Verdict.REFIT_FAILED, (("error", str(exc)),))
        return weigh(cand, fit, res, state, noise)

    later = next((s for s in ranked if cands[s.name].moves_basin), None)  # after the rest
    first = [s for s in ranked if s is not later]
    fits_noise = False
    with contextlib.closing(
        in_order(  # the next refits start early (vibid.identify.engine.threads)
            lambda k: attempt(first[k], False), range(len(first))
        )
    ) as runs:
        for s, j in zip(first, runs):
            judged[s.name] = j
            fits_noise = fits_noise or (
                j.verdict is Verdict.COMPARED and Stage.of(s.name, j.fit.result).fits_noise
            )
    if fits_noise and later is not None:
        judged[later.name] = Judgement(Verdict.NOT_REFITTED, (("fitted_by", "an effect"),))
    elif later is not None:  # a bent estimate's own basin is suspect: searched
        explained = max(
            (j.gain for j in judged.values() if j.verdict is Verdict.COMPARED), default=0.0
        )
        judged[later.name] = attempt(
            later, bool(outside) or explained < policy.search_share * excess
        )
    return judged


def guarded(inputs: Inputs, current: Stage, cands: dict, scores) -> dict:
    """name -> the :class:`Judgement` of a candidate a physical fact rules out this round
    (module doc of :func:`fit_and_weigh`)."""
    res = current.result
    judged = {}
    n_residuals = inputs.data.n_residuals
    for s in scores:
        if s.verdict is Verdict.NOT_SCORED:
            judged[s.name] = Judgement(Verdict.NOT_SCORED, s.detail)
            continue
        cand = cands[s.name]
        n = len(cand.extend(res.plate_model).names)
        if n >= n_residuals:
            judged[s.name] = Judgement(
                Verdict.TOO_FEW_POINTS, (("n", n), ("residuals", n_residuals))
            )
            continue
        needed = cand.modes_needed(res.plate_model)
        if needed:
            modes = plate_modes_in_band(current.modes, res)
            if modes < needed:
                judged[s.name] = Judgement(
                    Verdict.NO_MODE_PATTERN, (("modes", modes), ("needed", needed))
                )
    return judged


def weigh(cand, fit: refits.Refit, res, state: State, noise: Noise) -> Judgement:
    """A refit's evidence under the round's noise model, at its chi2 under the current
    fit's weights (the same for every explanation the round compares); a refit that did
    not converge is no estimate, and has none."""
    r = fit.result
    detail = (("searched", fit.searched),)
    if cand.at is not None:
        detail += (("at_hz", cand.at.f_hz),)
    if fit.held is not None:  # parameters the refit held inside their box
        detail += (("held", fit.held.sentence),)
    if not r.converged:
        return Judgement(Verdict.NOT_CONVERGED, detail + (("message", r.message),), fit)
    placed = cand.resonances_hz(r.parameters, res.parameters)
    if placed:
        detail += (("f_hz", placed[0]),)
    ev = log_evidence(
        r, with_prior(state.prior, cand, res.parameters), noise, chi2=float(res.chi2 - fit.gain)
    )
    return Judgement(Verdict.COMPARED, detail + ev.parts, fit, evidence=ev.log_z)


# -- compare and choose -----------------------------------------------------------------------
def compare(scores, judged: dict, log_z_now: float, policy: Policy):
    """Every explanation of the round by its evidence: returns the scores with their final
    verdicts and probabilities, the name chosen (:data:`STOP` for the current model), and
    the stage's alternatives (the report's ``loop.stages[].alternatives``, the chosen
    first).

    The model prior: :attr:`Policy.stop_prior` on "the current model is complete", the
    rest spread evenly over the round's candidates. The probabilities are shares among the
    fitted explanations and stopping, and the most probable is chosen: only a fit is a
    model. A candidate that was not refitted keeps its approximate evidence in its score
    (marked estimated), with no share."""
    names = [s.name for s in scores]
    log_z = {STOP: log_z_now}
    estimated = set()
    for s in scores:
        j = judged.get(s.name)
        if j is not None and j.verdict is Verdict.COMPARED:
            log_z[s.name] = j.evidence
        elif j is not None and j.verdict is Verdict.NOT_REFITTED and np.isfinite(s.log_evidence):
            log_z[s.name] = s.log_evidence
            estimated.add(s.name)
        else:
            log_z[s.name] = -math.inf
    share = (1.0 - policy.stop_prior) / max(len(names), 1)
    prior = {STOP: policy.stop_prior} | {n: share for n in names}
    prob = probabilities({k: (-math.inf if k in estimated else z) for k, z in log_z.items()}, prior)
    fitted = [k for k in log_z if k is STOP or (k not in estimated and np.isfinite(log_z[k]))]
    chosen = max(fitted, key=lambda k: (prob[k], log_z[k]))
    for k in estimated:
        prob[k] = math.nan
    by = "stopping here" if chosen is STOP else chosen
    out = []
    for s in scores:
        j = judged.get(s.name)
        verdict, detail = (j.verdict, j.detail) if j is not None else (s.verdict, s.detail)
        if s.name == chosen:
            verdict = Verdict.CHOSEN
        elif verdict is Verdict.COMPARED:
            verdict = Verdict.LESS_PROBABLE
        detail = detail + (
            ("probability", prob[s.name]),
            ("by", by),
            ("by_probability", prob[chosen]),
            ("log_evidence", log_z[s.name]),
        )
        out.append(
            replace(
                s,
                verdict=verdict,
                detail=detail,
                probability=prob[s.name],
                log_evidence=log_z[s.name],
                estimated=s.name in estimated,
                delta_chi2=j.gain if j is not None else math.nan,
            )
        )
    at = {
        s.name: dict(judged[s.name].detail).get("f_hz", s.at_hz) if s.name in judged else s.at_hz
        for s in scores
    }
    order = sorted(fitted, key=lambda k: (k != chosen, -prob[k], -log_z[k]))
    shares = tuple(
        {"added": k, "criterion": log_z[k], "probability": prob[k]}
        | (
            {"f_hz": at[k]}
            if k is not STOP and at.get(k) is not None and np.isfinite(at[k])
            else {}
        )
        for k in order
    )
    return out, chosen, shares


def outside_prior(result: IdentificationResult, box: dict) -> list[str]:
    """Names of ``result``'s parameters outside (or on a face of) their prior box."""
    return prior_space(result, box).out_of_bounds(result.values)


def _values(result, names, box) -> str:
    """``names``' values in ``result`` beside their prior boxes, in words."""
    bounds = result.plate_model.default_bounds(box)
    return ", ".join(
        f"{n} {result.parameters[n]:.3g} (box {bounds[n][0]:.3g} to {bounds[n][1]:.3g})"
        for n in names
    )


# -- withdraw ---------------------------------------------------------------------------------
def withdraw(
    inputs: Inputs, stage: Stage, box: dict, prior: dict, added: list
) -> tuple[Stage, list]:
    """``stage`` less the effects added in earlier rounds that the new one makes
    redundant (an isotropic fit's extra peak taken for a stand resonance, then the
    orthotropic material that places it; a fixture's step that stood in for a mass the
    next round adds): each one is refitted without, and withdrawn where the model without
    it is the more probable (its evidence, under the new fit's noise model). Returns the
    stage and a :class:`Score` per withdrawn effect."""
    gone = []
    for term in reversed(stage.result.plate_model.effects):
        res = stage.result
        if term.name == stage.added or term.name not in added or not term.parameters:
            continue
        z = distance_from_null(term, res)
        model = res.plate_model.without_effect(term)
        start = {n: v for n, v in res.parameters.items() if n in model.names}
        d, bounds = inputs.data, model.default_bounds(box)
        fm = inputs.plate.forward_model(
            d.frequency_hz[d.used], model=model, theta0=start, bounds=bounds
        )
        try:
            smaller = refits.polish(inputs.plate, d, fm, start, bounds, None, inputs.local)
        except Exception as exc:  # noqa: BLE001 - the larger model stays
            log.info("loop: %s could not be refitted without %s: %s", stage.added, term.name, exc)
            continue
        noise = Noise.of(res, d.n_residuals)
        chi2_with, chi2_without = _data_chi2(res), _data_chi2(smaller)
        odds = (
            log_evidence(smaller, prior, noise, chi2=chi2_without).log_z
            - log_evidence(res, prior, noise, chi2=chi2_with).log_z
        )
        if not (smaller.converged and odds >= 0):
            continue
        stage = Stage.of(stage.added, smaller)
        gone.append(
            Score(
                term.name,
                math.nan,
                len(term.parameters),
                math.nan,
                math.nan,
                delta_chi2=-float(chi2_without - chi2_with),
                verdict=Verdict.WITHDRAWN,
                log_evidence=odds,
                detail=(("by", stage.added), ("z", z), ("odds", odds)),
            )
        )
    return stage, gone


def _data_chi2(result) -> float:
    """``result``'s chi2 under the data's weights as the report gives it."""
    return float(result.chi2_reduced_reported * result.dof)


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
    note = (
        f"the standard deviations are scaled by sqrt(reduced chi2) = {math.sqrt(birge):.3g}"
        f" and by sqrt(tau) = {math.sqrt(tau):.3g} for the residual's correlation along "
        f"frequency (about {tau:.3g} neighbouring points per independent one): the "
        "residual holds more than the noise, and the misfit measures the error"
    )
    kept = tuple(w for w in result.warnings if "understate the error" not in w)
    std = result.std * math.sqrt(k)
    poor = tuple(
        f"{n} is poorly determined by these data (scaled std {sd:.2g} = "
        f"{100 * sd / abs(v):.0f} % of its value)"
        for n, v, sd, s0 in zip(result.parameter_names, result.values, std, result.std)
        if abs(v) > 0 and np.isfinite(sd) and sd > 0.3 * abs(v) and not s0 > 0.3 * abs(v)
    )
    return replace(
        result, std=std, covariance=result.covariance * k, warnings=kept + (note,) + poor
    )
