"""A round's refits: the guards, which candidates are refitted and in what order, each refit
weighed by its evidence (:func:`weigh`)."""

from __future__ import annotations

import contextlib
import logging
from typing import TYPE_CHECKING

import numpy as np

from vibid.identify.engine.threads import in_order
from vibid.identify.loop import refit as refits
from vibid.identify.loop.evidence import Noise, log_evidence, outside_prior, with_prior
from vibid.identify.loop.verdicts import Judgement, Score, Stage, Verdict

if TYPE_CHECKING:
    from vibid.identify.loop.state import Inputs, State
    from vibid.identify.model.plate import Modes

log = logging.getLogger(__name__)


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
    ranked = to_refit(scores, judged, cands, res, bool(outside), policy)
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


def to_refit(scores, judged: dict, cands: dict, res, outside: bool, policy) -> list[Score]:
    """The scores refitted this round, highest approximate evidence first (the rule in
    :func:`fit_and_weigh`'s doc: the policy's few, every one without a parameter of its
    own, every one where the current estimate is ``outside`` its prior box); each other
    score not ``judged`` yet is marked not refitted in ``judged``."""
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
    return ranked


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
    prior = with_prior(state.prior, cand, res.parameters)  # the extended model's box
    ev = log_evidence(r, prior, noise, chi2=float(res.chi2 - fit.gain))
    return Judgement(Verdict.COMPARED, detail + ev.parts, fit, evidence=ev.log_z)


def plate_modes_in_band(modes: Modes | None, result) -> int:
    """How many of the fitted plate's ``modes`` (:attr:`Stage.modes`) lie within the band
    ``result``'s data cover (0 where its modes are unknown)."""
    f = np.asarray(result.frequency_hz)[np.asarray(result.used)]
    return 0 if modes is None else modes.in_band(f.min(), f.max())


def _values(result, names, box) -> str:
    """``names``' values in ``result`` beside their prior boxes, in words."""
    bounds = result.plate_model.default_bounds(box)
    return ", ".join(
        f"{n} {result.parameters[n]:.3g} (box {bounds[n][0]:.3g} to {bounds[n][1]:.3g})"
        for n in names
    )
