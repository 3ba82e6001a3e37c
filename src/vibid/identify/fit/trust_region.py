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

Two additions to Algorithm 4.1, both for the long curved valleys of the identification
(one resonance in the band: chi2 is ~1e8 times stiffer across the valley of D and nu than
along it, and the valley bends):

* a second-order correction (N&W section 15.6; for least squares the "geodesic
  acceleration" of Transtrum & Sethna, arXiv:1201.5885): when a step gives less than 3/4
  of the predicted decrease, the step p is bent by c = -(Z Z^T B Z Z^T)^+ (g(u+p) - g -
  B p), with Z a basis of the directions orthogonal to p, i.e. one Newton correction in the
  stiff directions back onto the valley floor, from the gradient already computed at
  u + p (one more chi2 evaluation). The ratio of the bent step is judged against the
  predicted decrease of p. A straight step can follow a bending valley only over ~|p|^4
  lambda_stiff kappa^2 < predicted decrease, which held the radius at ~1e-4 for
  thousands of iterations; bent steps go about ten times further.
* stopping tests against the rounding level of chi2 (see :func:`chi2_rounding_level`):
  chi2 = |r|^2 is computed to about ftol chi2 + 2 |r| |dr| + |dr|^2, with |dr| the rounding
  of the residual vector; once the decrease the quadratic model predicts (the Newton
  decrement g.B^-1.g / 2, B positive definite) is below it, no step can show a decrease
  that is not rounding, and the run is converged. This is decided from g and B alone,
  before any trial step, so it does not depend on how the rounding of trial values falls.
  With BFGS the test is confirmed with the exact Hessian (a quasi-Newton B can be far too
  stiff along a valley and predict nothing while far from the minimum); if that still
  predicts a decrease, BFGS goes on from the exact Hessian.

:func:`gauss_newton` is the Levenberg-Marquardt path: scipy.optimize.least_squares on the
weighted residual vector with its exact JAX Jacobian.

Both work on the coordinates ``u`` of a :class:`~vibid.identify.fit.space.ParameterSpace`
and return a :class:`~vibid.identify.fit.result.LocalResult` with their history and the
reason they stopped.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from vibid.identify.engine.profile import timed
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.result import HistoryEntry, LocalResult, Status

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


def chi2_rounding_level(f: float, f_floor: float, rel: float = 1e-12) -> float:
    """How precisely chi2 = |r|^2 is known from rounding: ``rel * f + 2 |r| |dr| + |dr|^2``
    with |r| = sqrt(f) and |dr|^2 = ``f_floor`` (the rounding of the residual vector)."""
    f = abs(float(f))
    return rel * f + 2.0 * math.sqrt(f * f_floor) + f_floor


def _second_order_correction(
    p: np.ndarray, g: np.ndarray, g_new: np.ndarray, B: np.ndarray
) -> np.ndarray | None:
    """Correction c orthogonal to p that brings u + p back onto the valley floor.

    The model's gradient error at u + p, e = g(u + p) - g - B p (second order in |p|), is
    removed in the directions orthogonal to p by one Newton step of the model restricted
    to them (its trust region: |c| <= |p| / 2, which also handles an indefinite B there).
    None when there is no such direction or nothing to correct.
    """
    n = p.size
    norm_p = float(np.linalg.norm(p))
    if n < 2 or norm_p == 0:
        return None
    e = g_new - g - B @ p
    if not np.all(np.isfinite(e)):
        return None
    # orthonormal basis of the complement of p
    Q, _ = np.linalg.qr(np.column_stack([p / norm_p, np.eye(n)]))
    Z = Q[:, 1:n]
    ez = Z.T @ e
    if not np.any(ez):
        return None
    cz, _ = solve_subproblem(ez, Z.T @ B @ Z, 0.5 * norm_p)
    c = Z @ cz
    return c if np.all(np.isfinite(c)) and np.any(c) else None


def _newton_decrease(g: np.ndarray, B: np.ndarray) -> float:
    """g.B^-1.g / 2, the decrease the quadratic model predicts (inf unless B > 0), on B
    scaled to a unit diagonal: a coordinate whose curvature is many decades below the
    others' (a parameter the loop holds inside a narrow logit,
    :func:`vibid.identify.loop.held.held_inside`) otherwise makes the unscaled solve
    return a negative decrease, which passed for convergence."""
    d = np.sqrt(np.abs(np.diag(B)))
    d = np.where(d > 0, d, 1.0)
    Bs, gs = B / d[:, None] / d[None, :], g / d
    try:
        if np.linalg.eigvalsh(Bs)[0] <= 0:
            return np.inf
        return float(0.5 * gs @ np.linalg.solve(Bs, gs))
    except np.linalg.LinAlgError:
        return np.inf


@dataclass(frozen=True)
class Iterate:
    """Where the trust region stands: the point ``u``, chi2 ``f`` and its gradient ``g``
    there, the quadratic model's matrix ``B``, and whether ``B`` is the exact Hessian at
    ``u`` (always for ``"exact"``; for BFGS at the start and after a check)."""

    u: np.ndarray
    f: float
    g: np.ndarray
    B: np.ndarray
    exact: bool


@dataclass(frozen=True)
class Trial:
    """A trial step ``p`` from an iterate: whether it reached the trust region's boundary,
    the decrease the model predicted, chi2 and its gradient at the end, the ratio ``rho`` of
    actual to predicted decrease, whether it was bent by the second-order correction, and
    the chi2 evaluations it cost."""

    p: np.ndarray
    on_boundary: bool
    predicted: float
    f_new: float
    g_new: np.ndarray
    rho: float
    corrected: bool = False
    evaluations: int = 1


def predicted_decrease(g: np.ndarray, B: np.ndarray, p: np.ndarray) -> float:
    """The decrease of chi2 the quadratic model predicts for the step ``p``."""
    return -(g @ p + 0.5 * p @ B @ p)


def decrease_ratio(f: float, f_new: float, predicted: float) -> float:
    """``rho``: actual over predicted decrease (-inf where chi2 is not finite at the end;
    without a predicted decrease, -inf for an increase and 0 otherwise)."""
    actual = f - f_new if np.isfinite(f_new) else -np.inf
    return actual / predicted if predicted > 0 else (-np.inf if actual < 0 else 0.0)


def next_radius(rho: float, radius: float, on_boundary: bool, max_radius: float) -> float:
    """N&W Algorithm 4.1's radius update: a quarter of it under a quarter of the predicted
    decrease, twice it (up to ``max_radius``) over three quarters on the boundary."""
    if rho < 0.25:
        return 0.25 * radius
    if rho > 0.75 and on_boundary:
        return min(2 * radius, max_radius)
    return radius


def bfgs_update(B: np.ndarray, s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The BFGS update of ``B`` for the step ``s`` and gradient change ``y`` (N&W eq.
    6.19); ``B`` itself where the curvature condition s^T y > 0 fails."""
    sy = s @ y
    if sy > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
        Bs = B @ s
        B = B + np.outer(y, y) / sy - np.outer(Bs, Bs) / (s @ Bs)
    return B


def stop_on_model(problem, it: Iterate, f_floor: float, ftol: float, decrement_tol: float):
    """The stop tests on the current model, before any trial step (no trial value enters).
    Returns ``(iterate, decrement, rounding level, stop)``, ``stop`` a ``(status, detail)``
    or None; a quasi-Newton ``B`` that predicts too little is checked with the exact
    Hessian, which the returned iterate then carries (BFGS goes on from it)."""
    if not np.all(np.isfinite(it.B)):
        return it, None, None, (Status.NOT_FINITE, "the Hessian is not finite")
    if it.f <= f_floor or not np.any(it.g):
        return it, None, None, (Status.CONVERGED, "the residual vanished to rounding")
    f_round = max(chi2_rounding_level(it.f, f_floor, ftol), decrement_tol)
    decrement = _newton_decrease(it.g, it.B)
    if decrement <= f_round and not it.exact:
        # a quasi-Newton B may be far too stiff along a valley: check with the exact
        # Hessian, and go on from it (BFGS restarted) if it still predicts a decrease
        it = replace(it, B=problem.hessian(it.u), exact=True)
        if not np.all(np.isfinite(it.B)):
            return it, decrement, f_round, (Status.NOT_FINITE, "the Hessian is not finite")
        decrement = _newton_decrease(it.g, it.B)
    if decrement <= f_round:
        detail = (
            "the decrease still predicted is below the "
            f"rounding level of chi2 ({decrement:.1e} <= {f_round:.1e})"
        )
        return it, decrement, f_round, (Status.CONVERGED, detail)
    return it, decrement, f_round, None


def trial_step(problem, it: Iterate, radius: float) -> Trial:
    """The model's step within ``radius`` and how chi2 answered it; where that was under
    three quarters of the predicted decrease, bent by the second-order correction if the
    bent step does better (its ratio judged against the straight step's prediction)."""
    p, on_boundary = solve_subproblem(it.g, it.B, radius)
    predicted = predicted_decrease(it.g, it.B, p)
    f_new, g_new = problem.value_and_grad(it.u + p)
    trial = Trial(p, on_boundary, predicted, f_new, g_new, decrease_ratio(it.f, f_new, predicted))
    if trial.rho < 0.75 and predicted > 0 and np.isfinite(f_new) and np.all(np.isfinite(g_new)):
        return _bent(problem, it, trial)
    return trial


def _bent(problem, it: Iterate, trial: Trial) -> Trial:
    """``trial`` bent back onto the valley floor (:func:`_second_order_correction`) where
    that gives a larger ratio and a finite gradient; ``trial`` otherwise."""
    c = _second_order_correction(trial.p, it.g, trial.g_new, it.B)
    if c is None:
        return trial
    f_c, g_c = problem.value_and_grad(it.u + trial.p + c)
    rho_c = (it.f - f_c) / trial.predicted if np.isfinite(f_c) else -np.inf
    if rho_c > trial.rho and np.all(np.isfinite(g_c)):
        return replace(
            trial, p=trial.p + c, f_new=f_c, g_new=g_c, rho=rho_c, corrected=True, evaluations=2
        )
    return replace(trial, evaluations=2)


def accepted_step(problem, hessian: str, it: Iterate, trial: Trial) -> Iterate:
    """The iterate at the end of an accepted trial step: the exact Hessian there, or the
    BFGS update of ``B``."""
    s, y = trial.p, trial.g_new - it.g
    u = it.u + trial.p
    if hessian == "exact":
        return Iterate(u, float(trial.f_new), trial.g_new, problem.hessian(u), True)
    return Iterate(u, float(trial.f_new), trial.g_new, bfgs_update(it.B, s, y), False)


def radius_collapsed(problem, it: Iterate, f_floor: float, radius: float) -> tuple[Status, str]:
    """The verdict once the radius fell below 1e-14 (no step helps any more): at the
    minimum to rounding if the quadratic model (on the exact Hessian) predicts nothing worth
    having (chi2's own rounding is ~1e-16 chi2 per point), stalled otherwise."""
    scale = max(it.f, f_floor)
    B = it.B if it.exact else problem.hessian(it.u)
    if _newton_decrease(it.g, B) <= 1e-6 * scale or np.linalg.norm(it.g) <= 1e-4 * scale:
        return Status.CONVERGED, "no further decrease above rounding"
    return Status.STALLED, f"trust radius {radius:.1e}"


def _local_result(method, space, u, f, status, detail, k, n_eval, history) -> LocalResult:
    return LocalResult(
        method,
        u.copy(),
        space.theta(u),
        f,
        status,
        status.sentence(detail),
        k,
        n_eval,
        tuple(history),
    )


def _log_step(method, k, it, decrement, f_round, step, radius, trial, accepted) -> None:
    log.debug(
        "%s it %d chi2 %.12g |g| %.3g decrement %.3g rounding %.3g step %.3g%s "
        "radius %.3g predicted %.3g rho %.3g%s",
        method,
        k,
        it.f,
        np.linalg.norm(it.g),
        decrement,
        f_round,
        step,
        " (corrected)" if trial.corrected else "",
        radius,
        trial.predicted,
        trial.rho,
        "" if accepted else " rejected",
    )


def _check_settings(hessian: str, eta: float) -> None:
    if hessian not in ("exact", "bfgs"):
        raise ValueError(f"trust_region: hessian must be 'exact' or 'bfgs', got {hessian!r}")
    if not 0 <= eta < 0.25:
        raise ValueError(f"trust_region: eta must lie in [0, 1/4), got {eta!r}")


@timed("local fits")
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
    decrement_tol: float = 0.0,
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
    xtol: converged when an accepted step that the trust region did not cut (a full
        Newton step) is shorter than ``xtol`` (inf-norm in ``u``).
    ftol: relative rounding level of chi2: converged when the decrease the quadratic
        model still predicts (the Newton decrement, B positive definite) is below
        ``ftol * chi2 + 2 sqrt(chi2 * f_floor) + f_floor``, the rounding level of chi2
        (:func:`chi2_rounding_level`; ``f_floor`` = 1e-20 per point: residuals exact to
        ~1e-10 relative).
    decrement_tol: converged, too, when the Newton decrement is below this (chi2 units):
        a run whose end is polished later need not walk to chi2's rounding level (a
        parameter sliding to the edge of its logit span gains a factor e per step).

    Returns
    -------
    LocalResult with ``method`` "trust-region-newton" or "trust-region-bfgs".
    """
    _check_settings(hessian, eta)
    method = "trust-region-newton" if hessian == "exact" else "trust-region-bfgs"
    space = problem.space
    u = np.asarray(u0, dtype=float).copy()
    f, g = problem.value_and_grad(u)
    n_eval = 1
    history: list[HistoryEntry] = []
    if not (np.isfinite(f) and np.all(np.isfinite(g))):
        return _local_result(method, space, u, f, Status.NOT_FINITE, f"chi2 = {f}", 0, 1, ())
    it = Iterate(u, f, g, problem.hessian(u), True)
    radius = radius0
    # chi2 below which a zero-residual fit is exact to rounding (relative residual 1e-10)
    f_floor = 1e-20 * getattr(problem, "n_points", 100)
    history.append(HistoryEntry(0, f, tuple(space.theta(u)), None, radius))

    def result(status, detail, k):
        return _local_result(method, space, it.u, it.f, status, detail, k, n_eval, history)

    for k in range(1, max_iter + 1):
        it, decrement, f_round, stop = stop_on_model(problem, it, f_floor, ftol, decrement_tol)
        if stop is not None:
            return result(*stop, k - 1)
        trial = trial_step(problem, it, radius)
        n_eval += trial.evaluations
        accepted = bool(trial.rho > eta and np.isfinite(trial.f_new))
        if accepted:
            it = accepted_step(problem, hessian, it, trial)
        step = float(np.linalg.norm(trial.p))
        theta = tuple(space.theta(it.u))
        history.append(HistoryEntry(k, it.f, theta, step, radius, float(trial.rho), accepted))
        _log_step(method, k, it, decrement, f_round, step, radius, trial, accepted)
        if accepted and not trial.on_boundary and np.max(np.abs(trial.p)) <= xtol:
            return result(Status.CONVERGED, "the step became negligible", k)
        radius = next_radius(trial.rho, radius, trial.on_boundary, max_radius)
        if radius < 1e-14:
            return result(*radius_collapsed(problem, it, f_floor, radius), k)
    return result(Status.MAX_ITERATIONS, f"{max_iter} iterations", max_iter)


@timed("local fits")
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
        return LocalResult(
            "levenberg-marquardt",
            u0,
            space.theta(u0),
            f0,
            Status.NOT_FINITE,
            Status.NOT_FINITE.sentence(f"chi2 = {f0}"),
            0,
            1,
            (),
        )
    sol = least_squares(
        fun,
        u0,
        jac=problem.jacobian,
        method="lm",
        xtol=tol,
        ftol=tol,
        gtol=tol,
        max_nfev=max_evaluations,
    )
    u = np.asarray(sol.x, dtype=float)
    f = problem.chi2(u)
    if sol.status > 0:
        status = Status.CONVERGED
    elif sol.status == 0:
        status = Status.MAX_ITERATIONS
    else:
        status = Status.FAILED
    return LocalResult(
        "levenberg-marquardt",
        u,
        space.theta(u),
        f,
        status,
        status.sentence(sol.message),
        int(sol.nfev),
        int(sol.nfev),
        tuple(history),
    )
