"""Local fits: the local methods by name, and the polish by continuation in the loss factor.

From a start, the loss factor (which smooths the landscape when large) is released step by
step: the other parameters are fitted with beta held at a decreasing ladder of values
(half a decade apart), and from each rung all parameters are fitted freely, until the free
fit's beta lies above the rung; the lowest chi2 of all free fits wins. The local method is
the paper's trust-region Newton with the exact Hessian (or BFGS, or Levenberg-Marquardt,
:mod:`~vibid.identify.fit.trust_region`).

A long AFC (thousands of FFT bins) is fitted on its compressed problem
(:mod:`~vibid.identify.fit.compress`: a few nodes per band, the same minimum to a bounded
fraction of a standard deviation), and each run's end point is confirmed on every point.
Runs from neighbouring starts of the same data and weights may share the nodes the last
one ended on (:func:`run_local`'s ``near``), and a start whose end is polished later may
stop at a looser Newton decrement (``tol``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from vibid.identify.fit.compress import Compression, compressed, confirmed_run
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.result import LocalResult
from vibid.identify.fit.space import ParameterSpace
from vibid.identify.fit.trust_region import gauss_newton, trust_region

log = logging.getLogger(__name__)

#: The local methods by name, each on the problem as given: ``(problem, u0, max_iter, tol)``,
#: ``tol`` a Newton decrement (chi2) at which the trust region may stop (Levenberg-Marquardt
#: keeps MINPACK's own test).
_METHODS: dict[str, Callable[..., LocalResult]] = {
    "newton": lambda problem, u0, max_iter=200, tol=0.0: trust_region(
        problem, u0, hessian="exact", max_iter=max_iter, decrement_tol=tol
    ),
    "bfgs": lambda problem, u0, max_iter=200, tol=0.0: trust_region(
        problem, u0, hessian="bfgs", max_iter=2 * max_iter, decrement_tol=tol
    ),
    "lm": lambda problem, u0, max_iter=200, tol=0.0: gauss_newton(
        problem, u0, max_evaluations=2 * max_iter
    ),
}


def run_local(
    local: str, problem, u0, near: Compression | None = None, max_iter: int = 200, tol: float = 0.0
) -> tuple[LocalResult, Compression | None]:
    """The local method ``local`` from ``u0``, on the problem compressed around ``u0`` when
    the AFC is long (:func:`confirmed_run`; a continuation's rung with parameters held is not
    confirmed: its loss is the full chi2 at its end), or on ``near``'s nodes where it has
    the same data and weights (a neighbouring start's: the end point is confirmed all the
    same). ``tol``: a Newton decrement (chi2) small enough to stop at and, where larger than
    :data:`~vibid.identify.fit.compress.TOL_STD` squared, to confirm with (a start whose
    end is polished later). Returns the result and the compression it ended on (None for
    a short AFC)."""
    method = _METHODS[local]
    if isinstance(problem, HeldProblem):
        short = compressed(problem.problem, problem.space.full(u0))
        if short is problem.problem:
            return method(problem, u0, max_iter, tol), None
        r = method(problem.on(short), u0, max_iter, tol)
        return replace(r, loss=problem.chi2(r.u)), None
    short = near.on(problem) if near is not None else None
    if short is None:
        short = compressed(problem, u0)
    if short is problem:
        return method(problem, u0, max_iter, tol), None
    r, short = confirmed_run(method, problem, short, u0, max_iter, tol)
    return r, (Compression(problem, short) if short is not problem else None)


def _on_compressed(name: str) -> Callable[..., LocalResult]:
    """The local method ``name`` run on the problem compressed around its start when the
    AFC is long (:func:`run_local`)."""

    def run(problem, u0, max_iter=200):
        return run_local(name, problem, u0, max_iter=max_iter)[0]

    return run


#: Local methods by name (compressing a long AFC).
LOCAL_METHODS: dict[str, Callable[..., LocalResult]] = {
    name: _on_compressed(name) for name in _METHODS
}
#: Iteration limit of each rung of the continuation (the winner is then run to the end).
RUNG_MAX_ITER = 30

#: The parameter that smooths the landscape when large (the loss factor).
SMOOTHING_PARAMETER = "beta"
#: Ratio between rungs of the continuation ladder (half a decade).
LADDER_RATIO = 10**-0.5


# -- a problem with some coordinates held --------------------------------------------------
class _HeldSpace:
    def __init__(self, space: ParameterSpace, free: np.ndarray, u_base: np.ndarray):
        self._space, self._free, self._base = space, free, u_base

    def full(self, u_free):
        u = self._base.copy()
        u[self._free] = u_free
        return u

    def theta(self, u_free):
        return self._space.theta(self.full(np.asarray(u_free, float)))


class HeldProblem:
    """``problem`` with the coordinates not in ``free`` held at ``u_base``; same interface
    as LeastSquaresProblem for the local optimisers (derivatives sliced from the full ones,
    so nothing is recompiled)."""

    def __init__(self, problem: LeastSquaresProblem, free, u_base):
        self.problem = problem
        self.free = np.asarray(free, dtype=int)
        self.space = _HeldSpace(problem.space, self.free, np.asarray(u_base, float).copy())
        self.n_points = problem.n_points

    def on(self, problem) -> HeldProblem:
        """The same coordinates held, on another problem (the compressed one)."""
        return HeldProblem(problem, self.free, self.space.full(np.zeros(self.free.size)))

    def value_and_grad(self, u_free):
        f, g = self.problem.value_and_grad(self.space.full(u_free))
        return f, g[self.free]

    def hessian(self, u_free):
        H = self.problem.hessian(self.space.full(u_free))
        return H[np.ix_(self.free, self.free)]

    def chi2(self, u_free):
        return self.problem.chi2(self.space.full(u_free))

    def residuals(self, u_free):
        return self.problem.residuals(self.space.full(u_free))

    def jacobian(self, u_free):
        return self.problem.jacobian(self.space.full(u_free))[:, self.free]


def polish_by_continuation(
    problem: LeastSquaresProblem,
    u_start,
    local: str = "newton",
) -> list[LocalResult]:
    """Local fits from ``u_start`` with the loss factor released step by step.

    Returns every free fit, best (lowest chi2) first. Without a loss-factor parameter, one
    local run from ``u_start``. The rungs of a long AFC run on one compressed problem
    (built at ``u_start``), the best then confirmed on the full data.
    """
    u = np.asarray(u_start, dtype=float).copy()
    space = problem.space
    if SMOOTHING_PARAMETER not in space.names:
        return [LOCAL_METHODS[local](problem, u)]
    method = _METHODS[local]
    short = compressed(problem, u)
    ib = space.names.index(SMOOTHING_PARAMETER)
    t = space.transforms[ib]
    beta = float(space.theta(u)[ib])
    low = max(t.low, 1e-6) if t.kind == "log" else t.low
    ladder = []
    b = beta
    while b > low * 1.0001:
        ladder.append(b)
        b *= LADDER_RATIO
    ladder.append(low)
    free = np.array([i for i in range(space.size) if i != ib], dtype=int)
    results: list[LocalResult] = []
    for b in ladder:
        u[ib] = float(t.to_u(b))
        held = HeldProblem(short, free, u)
        r_held = method(held, u[free], RUNG_MAX_ITER)
        u = held.space.full(r_held.u)
        r_free = method(short, u, RUNG_MAX_ITER)
        results.append(r_free)
        log.debug(
            "continuation beta=%.3g: held chi2 %.6g, free chi2 %.6g beta %.3g",
            b,
            r_held.loss,
            r_free.loss,
            r_free.theta[ib],
        )
        if r_free.theta[ib] >= b * math.sqrt(LADDER_RATIO):
            break  # the free fit's loss factor lies above the rung: lower rungs are useless
    if short is not problem:  # the full chi2 of each; the best confirmed on the full data
        results = [replace(r, loss=problem.chi2(r.u)) for r in results]
    results.sort(key=lambda r: (not np.isfinite(r.loss), r.loss))
    if short is not problem:
        results[0] = confirmed_run(method, problem, short, results[0].u)[0]
    elif not results[0].converged:  # finish the best rung's free fit
        results.insert(0, method(problem, results[0].u))
    return results
