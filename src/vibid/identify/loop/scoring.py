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

import numpy as np

from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.space import ParameterSpace


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
