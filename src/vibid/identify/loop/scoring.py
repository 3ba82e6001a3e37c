"""The score (Lagrange-multiplier) test of a candidate at the current fit.

With ``r`` the weighted residual and ``J`` the Jacobian of the model extended by the
candidate, both at the current estimate and the candidate's null value,
``LM = rᵀ (P_ext − P) r``, ``P`` the projector onto the current parameters' sensitivities:
chi-square with as many degrees of freedom as the candidate adds, under the null. Its
collinearity is how much of its sensitivity the current parameters already explain. A
candidate without parameters of its own (``transverse_shear`` on an isotropic plate) is
scored along the secant from the current model to the extended one (one dof).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from scipy.stats import chi2 as chi2_dist

from vibid.identify.engine.profile import timed
from vibid.identify.engine.threads import in_order
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.space import ParameterSpace
from vibid.identify.loop.evidence import Noise, approximate, with_prior
from vibid.identify.loop.verdicts import Score, Stage, Verdict

if TYPE_CHECKING:
    from vibid.identify.loop.state import Inputs, State


def extended_problem(plate, data, res, cand, box, diagnosis, like=None):
    """(the least-squares problem of the model extended by ``cand`` on the declared
    ``plate`` (:class:`~vibid.identify.model.plate.Plate`) under ``res``'s weights,
    its start at the null, its prior box). ``like``: the extended problem of the same
    candidate at another place (a resonance tried elsewhere), whose forward model it
    shares: the places differ in a resonance's frequency and Q, which move no stiffness
    or inertia, so the basis is the same."""
    values = res.parameters
    model = cand.extend(res.plate_model)
    start = cand.at_null(values, box, plate.setup.specimen.thickness_m, diagnosis)
    ext_box = model.default_bounds(box | cand.bounds(box, values, diagnosis))
    if like is not None:
        fm = like[0].model
    else:
        fm = plate.forward_model(
            data.frequency_hz[data.used], model=model, theta0=start, bounds=ext_box
        )
    space = ParameterSpace.from_bounds(
        fm.parameter_names,
        ext_box,
        {q.name: q.kind for q in model.parameters} | cand.held(values, diagnosis),
    )
    return LeastSquaresProblem(fm, data, space, res.weights), start, ext_box


def score(extended, res, cand, prior: dict) -> tuple[float, int, float, np.ndarray]:
    """(LM statistic, its degrees of freedom, collinearity, the new parameters' Fisher
    information given the others in the coordinates of their prior box ``prior``, unit
    noise) of ``cand`` at ``res``, on ``extended``: :func:`extended_problem`'s (the
    caller keeps it for the refit)."""
    problem, start, _ = extended
    names = problem.space.names
    theta = np.array([start[n] for n in names])
    J = problem.jacobian_theta(theta)
    r = problem.residuals_theta(theta)
    J_small, new = cand.directions(J, names, res.parameters, res.parameter_names)
    if not new:
        # no parameter of its own: the extended model at the current values differs from
        # the current one by d; score along that secant, one dof
        r0 = res.weighted_residuals
        d = r - r0
        Q = span(J)
        lm = max(projected(span(np.column_stack([J, d])), r0) - projected(Q, r0), 0.0)
        return float(lm), 1, collinearity(Q, d[:, None]), np.zeros((0, 0))
    Q_small = span(J_small)  # the current parameters' directions, once
    lm = max(projected(span(J), r) - projected(Q_small, r), 0.0)
    model = cand.extend(res.plate_model)
    kinds = {q.name: q.kind for q in model.parameters}
    info = new_information(
        problem.space.names, theta, J[:, new], Q_small, new, model.default_bounds(prior), kinds
    )
    return (
        float(lm),
        len(names) - len(res.parameter_names),
        collinearity(Q_small, J[:, new]),
        info,
    )


def new_information(all_names, theta, J_new, Q_small, new, prior: dict, kinds: dict) -> np.ndarray:
    """The new parameters' Fisher information given the current ones (the Schur
    complement of JᵀJ: ``J_new``'s part that the current parameters' directions
    ``Q_small``, :func:`span`, cannot mimic), in the coordinates in which their prior is
    uniform over ``prior`` (each one's fit coordinate over its physical box, box ->
    [-1, 1])."""
    names = [all_names[k] for k in new]
    space = ParameterSpace.from_bounds(
        names, {n: prior[n] for n in names}, {n: kinds.get(n) for n in names}
    )
    g = space.du_dtheta(theta[new])
    Jn = J_new / np.where(np.isfinite(g) & (g != 0), g, np.inf)  # d r / d u
    R = Jn - Q_small @ (Q_small.T @ Jn)
    return R.T @ R


def span(J) -> np.ndarray:
    """An orthonormal basis of the columns of J (scale-invariant, rank-safe)."""
    scale = np.linalg.norm(J, axis=0)
    Q, s, _ = np.linalg.svd(J / np.where(scale > 0, scale, 1.0), full_matrices=False)
    return Q[:, s > 1e-10 * s.max()]


def projected(Q, r) -> float:
    """``rᵀ P r``, P the projector onto the span ``Q`` (:func:`span`)."""
    return float(np.sum((Q.T @ r) ** 2))


def collinearity(Q_old, J_new) -> float:
    """How much of the extension the current parameters (their span ``Q_old``) can mimic:
    the cosine between a new direction and that span (the smallest over the new
    directions: the data see the extension through its least mimicked direction)."""
    cos = [
        np.linalg.norm(Q_old.T @ v) / np.linalg.norm(v) for v in J_new.T if np.linalg.norm(v) > 0
    ]
    return float(min(cos)) if cos else float("nan")


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
