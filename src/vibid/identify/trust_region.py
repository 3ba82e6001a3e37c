"""Local minimisation: the paper's trust-region method (Algorithm 1) and a Gauss-Newton path.

:func:`trust_region` is Algorithm 1 of the paper, which is Algorithm 4.1 of Nocedal &
Wright, "Numerical Optimization" (2nd ed., 2006), with its constants: the radius shrinks
to a quarter when the actual decrease is under a quarter of the predicted one, doubles
(up to ``max_radius``) when it is over three quarters and the step reached the boundary;
a step is accepted when the ratio exceeds ``eta``. The quadratic model's matrix is

* ``hessian="exact"``: the exact Hessian of chi2 by automatic differentiation (the
  paper's "Newton-Gauss" variant), or
* ``hessian="bfgs"``: the exact Hessian at the start, then BFGS updates (the paper's
  second variant; standard BFGS formula, N&W eq. 6.19, skipped when s^T y <= 0).

The subproblem min g.p + p.B.p/2, |p| <= radius is solved exactly from the eigen-
decomposition of B (N&W section 4.3, including the "hard case"): p is tiny (3 to 10
unknowns), so this costs nothing.

:func:`gauss_newton` is the Levenberg-Marquardt path: scipy.optimize.least_squares on the
weighted residual vector with its exact JAX Jacobian.

Both work on the coordinates ``u`` of a :class:`~vibid.identify.params.ParameterSpace`
and return a :class:`~vibid.identify.fit_result.LocalResult` with their history and the
reason they stopped.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from vibid.identify.fit_result import HistoryEntry, LocalResult, Status
from vibid.identify.loss import LeastSquaresProblem

log = logging.getLogger(__name__)


def solve_subproblem(g: np.ndarray, B: np.ndarray, radius: float) -> tuple[np.ndarray, bool]:
    """argmin_p g.p + p.B.p / 2 subject to |p| <= radius; returns (p, on_boundary).

    Exact solution (Nocedal & Wright, Theorem 4.1): p = -(B + lam I)^-1 g with lam >= 0,
    B + lam I positive semidefinite and lam (radius - |p|) = 0.
    """
    lam_all, Q = np.linalg.eigh((B + B.T) / 2)
    a = Q.T @ g
    lam_min = lam_all[0]
    if lam_min > 0:
        p = -Q @ (a / lam_all)
        if np.linalg.norm(p) <= radius:
            return p, False

    def norm_p(lam):
        return np.linalg.norm(a / (lam_all + lam))

    lo = max(0.0, -lam_min)
    # hard case: g has (almost) no component along the lowest eigenvectors
    small = np.abs(lam_all - lam_min) <= 1e-12 * max(1.0, abs(lam_min))
    if np.all(np.abs(a[small]) <= 1e-14 * max(1.0, np.linalg.norm(g))):
        shifted = lam_all + lo
        coef = np.where(small, 0.0, -a / np.where(small, 1.0, shifted))
        p = Q @ coef
        rest = radius**2 - p @ p
        if rest >= 0:
            return p + math.sqrt(rest) * Q[:, 0], True
    # |p(lam)| decreases from +inf (or a value > radius) at lo to 0: bracket and bisect
    # on 1/|p| - 1/radius, which is nearly linear in lam (N&W eq. 4.39), via a safeguarded
    # secant (brentq).
    from scipy.optimize import brentq

    def phi(lam):
        return 1.0 / norm_p(lam) - 1.0 / radius

    eps = 1e-14 * max(1.0, abs(lam_min), abs(lam_all[-1]))
    a_lo = lo + eps
    while phi(a_lo) > 0 and a_lo > lo:  # |p| already below radius right at lo
        a_lo = lo + (a_lo - lo) / 16
        if a_lo - lo < 1e-300:
            break
    hi = lo + np.linalg.norm(g) / radius + abs(lam_all[-1]) + 1.0
    while phi(hi) < 0:
        hi *= 2
    if phi(a_lo) > 0:
        lam = a_lo
    else:
        lam = brentq(phi, a_lo, hi, xtol=1e-14 * hi, rtol=1e-12, maxiter=200)
    p = -Q @ (a / (lam_all + lam))
    return p * min(1.0, radius / np.linalg.norm(p)), True


def _newton_decrease(g: np.ndarray, B: np.ndarray) -> float:
    """g.B^-1.g / 2, the decrease the quadratic model predicts (inf unless B > 0)."""
    try:
        if np.linalg.eigvalsh(B)[0] <= 0:
            return np.inf
        return float(0.5 * g @ np.linalg.solve(B, g))
    except np.linalg.LinAlgError:
        return np.inf


def trust_region(
    problem: LeastSquaresProblem,
    u0,
    *,
    hessian: str = "exact",
    radius0: float = 0.25,
    max_radius: float = 4.0,
    eta: float = 0.05,
    max_iter: int = 200,
    xtol: float = 1e-11,
    ftol: float = 1e-12,
) -> LocalResult:
    """Minimise chi2(u) from ``u0`` by the paper's Algorithm 1.

    Parameters
    ----------
    problem: the weighted least-squares problem.
    u0: (p,) start, in the coordinates of ``problem.space``.
    hessian: ``"exact"`` (autodiff Hessian at every iterate) or ``"bfgs"``.
    radius0, max_radius: initial and largest trust radius, in ``u`` (the prior box is
        [-1, 1] in every coordinate).
    eta: acceptance threshold on the ratio of actual to predicted decrease, in [0, 1/4).
    max_iter: iteration limit; reaching it is reported as MAX_ITERATIONS.
    xtol: converged when an accepted step is shorter than ``xtol`` (inf-norm in ``u``).
    ftol: converged when the decrease the quadratic model still predicts (with B positive
        definite) is below ``ftol * chi2`` (chi2 floored at the rounding level).

    Returns
    -------
    LocalResult with ``method`` "trust-region-newton" or "trust-region-bfgs".
    """
    if hessian not in ("exact", "bfgs"):
        raise ValueError(f"trust_region: hessian must be 'exact' or 'bfgs', got {hessian!r}")
    if not 0 <= eta < 0.25:
        raise ValueError(f"trust_region: eta must lie in [0, 1/4), got {eta!r}")
    method = "trust-region-newton" if hessian == "exact" else "trust-region-bfgs"
    space = problem.space
    u = np.asarray(u0, dtype=float).copy()
    f, g = problem.value_and_grad(u)
    n_eval = 1
    history: list[HistoryEntry] = []

    def result(status, detail, k):
        return LocalResult(method, u.copy(), space.theta(u), f, status,
                           status.sentence(detail), k, n_eval, tuple(history))

    if not (np.isfinite(f) and np.all(np.isfinite(g))):
        return result(Status.NOT_FINITE, f"chi2 = {f}", 0)
    B = problem.hessian(u)
    radius = radius0
    # chi2 below which a zero-residual fit is exact to rounding (relative residual 1e-10)
    f_floor = 1e-20 * getattr(problem, "n_points", 100)
    history.append(HistoryEntry(0, f, tuple(space.theta(u)), None, radius))
    for k in range(1, max_iter + 1):
        if not np.all(np.isfinite(B)):
            return result(Status.NOT_FINITE, "the Hessian is not finite", k - 1)
        # stop tests on the current model
        if f <= f_floor or not np.any(g):
            return result(Status.CONVERGED, "the residual vanished to rounding", k - 1)
        if _newton_decrease(g, B) <= ftol * max(f, f_floor):
            return result(Status.CONVERGED, "the predicted decrease is negligible", k - 1)
        p, on_boundary = solve_subproblem(g, B, radius)
        predicted = -(g @ p + 0.5 * p @ B @ p)
        f_new, g_new = problem.value_and_grad(u + p)
        n_eval += 1
        actual = f - f_new if np.isfinite(f_new) else -np.inf
        rho = actual / predicted if predicted > 0 else (-np.inf if actual < 0 else 0.0)
        step = float(np.linalg.norm(p))
        if rho < 0.25:
            radius_next = 0.25 * radius
        elif rho > 0.75 and on_boundary:
            radius_next = min(2 * radius, max_radius)
        else:
            radius_next = radius
        accepted = bool(rho > eta and np.isfinite(f_new))
        if accepted:
            s, y = p, g_new - g
            u, f, g = u + p, float(f_new), g_new
            if hessian == "exact":
                B = problem.hessian(u)
            else:
                sy = s @ y
                if sy > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
                    Bs = B @ s
                    B = B + np.outer(y, y) / sy - np.outer(Bs, Bs) / (s @ Bs)
        history.append(HistoryEntry(k, f, tuple(space.theta(u)), step, radius, float(rho), accepted))
        log.debug("%s it %d chi2 %.6g step %.3g radius %.3g rho %.3g", method, k, f, step, radius, rho)
        if accepted and np.max(np.abs(p)) <= xtol:
            return result(Status.CONVERGED, "the step became negligible", k)
        radius = radius_next
        if radius < 1e-14:
            # no step helps any more: at the minimum to rounding if the quadratic model
            # predicts nothing worth having (chi2's own rounding is ~1e-16 chi2 per point)
            scale = max(f, f_floor)
            if _newton_decrease(g, B) <= 1e-6 * scale or np.linalg.norm(g) <= 1e-4 * scale:
                return result(Status.CONVERGED, "no further decrease above rounding", k)
            return result(Status.STALLED, f"trust radius {radius:.1e}", k)
    return result(Status.MAX_ITERATIONS, f"{max_iter} iterations", max_iter)


def gauss_newton(
    problem: LeastSquaresProblem,
    u0,
    *,
    max_evaluations: int = 400,
    tol: float = 1e-12,
) -> LocalResult:
    """Levenberg-Marquardt (scipy.optimize.least_squares, MINPACK's ``lm``) on the weighted
    residuals with their exact JAX Jacobian. The history has one entry per residual
    evaluation (no radius: MINPACK keeps it internal)."""
    from scipy.optimize import least_squares

    space = problem.space
    history: list[HistoryEntry] = []
    last = [np.asarray(u0, dtype=float)]

    def fun(u):
        r = problem.residuals(u)
        step = float(np.linalg.norm(u - last[0])) if history else None
        last[0] = np.array(u, dtype=float)
        f = float(r @ r) if np.all(np.isfinite(r)) else np.inf
        history.append(HistoryEntry(len(history), f, tuple(space.theta(u)), step, None))
        if not np.all(np.isfinite(r)):
            return np.full_like(r, 1e150)
        return r

    u0 = np.asarray(u0, dtype=float)
    f0 = problem.chi2(u0)
    if not np.isfinite(f0):
        return LocalResult("levenberg-marquardt", u0, space.theta(u0), f0, Status.NOT_FINITE,
                           Status.NOT_FINITE.sentence(f"chi2 = {f0}"), 0, 1, ())
    sol = least_squares(fun, u0, jac=problem.jacobian, method="lm", xtol=tol, ftol=tol,
                        gtol=tol, max_nfev=max_evaluations)
    u = np.asarray(sol.x, dtype=float)
    f = problem.chi2(u)
    if sol.status > 0:
        status = Status.CONVERGED
    elif sol.status == 0:
        status = Status.MAX_ITERATIONS
    else:
        status = Status.FAILED
    return LocalResult("levenberg-marquardt", u, space.theta(u), f, status,
                       status.sentence(sol.message), int(sol.nfev), int(sol.nfev), tuple(history))
