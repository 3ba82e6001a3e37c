"""The loop's rounds: propose → fit → compare → choose, each a small function over a
frozen :class:`~vibid.identify.loop.state.State` (the algorithm: :mod:`vibid.identify.loop`),
each step in its module: :mod:`~vibid.identify.loop.propose`,
:mod:`~vibid.identify.loop.scoring` and :mod:`~vibid.identify.loop.fitting` (fit),
:mod:`~vibid.identify.loop.choose` (compare and choose), :mod:`~vibid.identify.loop.withdraw`,
and :mod:`~vibid.identify.loop.examine` (each new stage's modes and diagnosis)."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from vibid.errors import VibidError
from vibid.identify.fit.data import fit_data
from vibid.identify.fit.noise import misfit_scale
from vibid.identify.fit.result import IdentificationResult
from vibid.identify.fit.strategy import Measurement, SearchOptions, identify
from vibid.identify.loop import refit as refits
from vibid.identify.loop.candidates import all_candidates
from vibid.identify.loop.choose import compare
from vibid.identify.loop.evidence import Noise, log_evidence, with_prior
from vibid.identify.loop.examine import diagnosed
from vibid.identify.loop.fitting import fit_and_weigh
from vibid.identify.loop.policy import DEFAULT, Policy
from vibid.identify.loop.propose import propose
from vibid.identify.loop.scoring import score_all
from vibid.identify.loop.state import STOP, Inputs, State
from vibid.identify.loop.verdicts import LoopResult, Stage, Verdict
from vibid.identify.loop.withdraw import at_the_end, withdraw
from vibid.identify.model.plate import Plate


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
    ignore (:func:`~vibid.identify.loop.diagnosis.diagnosis_of`); ``policy``: the loop's numbers
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
    return finish(at_the_end(inputs, state), time.perf_counter() - t0)


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
    last = state.rounds[-1] if state.rounds else ()
    withdrawn = {s.name for s in last if s.verdict is Verdict.WITHDRAWN}  # at the end
    unexplained = not stages[-1].fits_noise
    if unexplained:
        stages[-1] = replace(stages[-1], result=scaled_by_misfit(stages[-1].result))
    warnings = [
        f"{s.name} is nearly collinear with the declared parameters (cosine "
        f"{s.collinearity:.5f}): the data separate them only through the "
        f"{100 * math.sqrt(max(1 - s.collinearity**2, 0)):.2g} % of its sensitivity the "
        "others cannot mimic; its std and theirs include that"
        for s in last
        if s.kept and s.collinearity > 0.9 and s.name not in withdrawn
    ]
    return LoopResult(
        tuple(stages), state.rounds, unexplained, tuple(warnings), seconds, state.alternatives
    )


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
