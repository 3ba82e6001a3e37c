"""A long AFC at the cost of its information: the least-squares problem on a few nodes per band.

An FFT grid of 12 000 bins says no more about the parameters than the few hundred numbers
that fix the model's curve between its resonances, yet every local step (the exact Hessian
of chi2, its gradient) costs in proportion to the bins. The local fits therefore run on an
equivalent short problem, exact up to an interpolation error that is bounded and checked:

* the fitted points, by frequency, are cut into bands; in a band the model is replaced by
  its polynomial interpolant through ``q`` nodes, ``H(f_k) ≈ Σ_j h_j ℓ_j(f_k)`` (``h_j`` the
  model at node ``j``, ``ℓ_j`` the Lagrange polynomials);
* the nodes are the Gauss nodes of the band's own weights ``w_k = 1/σ_k²`` on its points
  (:func:`gauss_nodes`), whose quadrature weights ``W_j`` make the Lagrange polynomials
  orthogonal, ``Σ_k w_k ℓ_i(f_k) ℓ_j(f_k) = δ_ij W_j``; hence, exactly,

      Σ_k w_k |Σ_j h_j ℓ_j(f_k) − d_k|² = Σ_j W_j |h_j − c_j|² + κ,
      c_j = Σ_k w_k ℓ_j(f_k) d_k / W_j,   κ = Σ_k w_k |d_k|² − Σ_j W_j |c_j|²:

  the band's data enter through ``q`` pseudo-data ``c_j`` of standard uncertainty
  ``1/√W_j``, and the short problem is an ordinary :class:`LeastSquaresProblem` (same
  compiled code) on the nodes, with ``κ`` as its constant ``chi2_offset``;
* bands are bisected, at the fit's start ``θ_ref``, until the interpolant holds the model
  and its sensitivities over ``SCALE_STD`` standard deviations of every parameter: the
  weighted interpolation error ``e/σ`` of the whole AFC has a 2-norm of at most
  ``TOL_STD``, which bounds the shift of the (linearised) estimate by ``TOL_STD`` standard
  deviations in every direction;
* the run's end point is then checked on the full data (:func:`confirmed`): the full chi2's
  Newton step there must be shorter than ``TOL_STD`` standard deviations, or the bands are
  rebuilt around it and the run goes on (:func:`confirmed_run`); a neighbouring start of
  the same data and weights starts on the nodes the last run ended on (:class:`Compression`).

On a real strip's FFT AFC of 11 960 bins this leaves a few hundred nodes (BENCHMARKS.md).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from vibid.identify.fit.data import FitData
from vibid.identify.fit.problem import LeastSquaresProblem, SharedStructure
from vibid.identify.fit.result import LocalResult
from vibid.identify.model.reduced import PAD_SIZES, padded_size

log = logging.getLogger(__name__)

#: Problems with fewer fitted points than this are solved as they are.
MIN_POINTS = 1000
#: A compressed problem's nodes are padded to one of these counts (one compilation each):
#: the reduced bases' sizes from 32 up, the counts the nodes had before the bases gained a
#: 16 (a new count is a new compiled shape).
NODE_COUNTS = tuple(m for m in PAD_SIZES if m >= 32)
#: Nodes per band; a band of no more than twice as many points keeps its points.
NODES = 12
#: Bound on the shift of the estimate by the interpolation error, in standard deviations
#: (the full data's Newton step at the end point must be shorter, too).
TOL_STD = 0.05
#: The interpolant holds the model's sensitivities over this many standard deviations of
#: every parameter (a fit moves its estimate from the start).
SCALE_STD = 30.0
#: The nodes of a bisection round are evaluated in chunks of this many frequencies (one
#: compiled shape for every round).
CHUNK = 256


def gauss_nodes(x: np.ndarray, w: np.ndarray, q: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``q`` nodes and weights of the Gauss quadrature of the discrete measure
    ``Σ_k w_k δ(x − x_k)`` (``x`` distinct, ``w`` > 0, at least ``q`` points): exact for
    polynomials up to degree ``2q − 1``. Lanczos (Stieltjes) on ``diag(x)`` from ``√w``,
    fully reorthogonalised, then the Golub–Welsch eigenproblem of the Jacobi matrix."""
    centre, half = 0.5 * (x.max() + x.min()), 0.5 * (x.max() - x.min()) or 1.0
    t = (x - centre) / half
    V = np.zeros((x.size, q))
    alpha, beta = np.zeros(q), np.zeros(q - 1)
    v = np.sqrt(w) / math.sqrt(w.sum())
    for j in range(q):
        V[:, j] = v
        z = t * v
        alpha[j] = v @ z
        z -= V[:, : j + 1] @ (V[:, : j + 1].T @ z)
        z -= V[:, : j + 1] @ (V[:, : j + 1].T @ z)
        if j < q - 1:
            beta[j] = np.linalg.norm(z)
            v = z / beta[j]
    nodes, vectors = np.linalg.eigh(np.diag(alpha) + np.diag(beta, 1) + np.diag(beta, -1))
    return centre + half * nodes, w.sum() * vectors[0] ** 2


def lagrange_matrix(nodes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(len(x), q) values of the Lagrange polynomials of ``nodes`` at ``x`` (barycentric)."""
    scale = 0.5 * (nodes.max() - nodes.min()) or 1.0
    s = nodes / scale
    weights = np.array([1.0 / np.prod(s[j] - np.delete(s, j)) for j in range(s.size)])
    d = (x[:, None] - nodes[None, :]) / scale
    exact = d == 0
    t = weights[None, :] / np.where(exact, 1.0, d)
    L = t / t.sum(axis=1, keepdims=True)
    hit = exact.any(axis=1)
    L[hit] = exact[hit]
    return L


def project(
    f_hz: np.ndarray,
    w: np.ndarray,
    d: np.ndarray,
    nodes: np.ndarray,
    W: np.ndarray,
    L: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """The pseudo-data ``c`` (q,) at the Gauss ``nodes`` (weights ``W``) of a band's points
    ``f_hz`` (weights ``w``, data ``d``) and the constant ``κ``, such that for any values
    ``h`` at the nodes ``Σ_k w_k |Σ_j h_j ℓ_j(f_k) − d_k|² = Σ_j W_j |h_j − c_j|² + κ``
    (``L``: the Lagrange matrix of ``nodes`` at ``f_hz``, if known)."""
    L = lagrange_matrix(nodes, f_hz) if L is None else L
    c = (L.T @ (w * d)) / W
    return c, float(w @ np.abs(d) ** 2 - W @ np.abs(c) ** 2)


class Quadratures:
    """The Gauss nodes, weights and Lagrange matrix of each band ``(i0, i1)`` of one set
    of sorted points and weights, made once: they depend on the data alone, and a loop's
    refits compress the same data, same weights, dozens of times (on a real strip's AFC
    they were a third of each compression)."""

    def __init__(self, f_hz: np.ndarray, w: np.ndarray, q: int):
        self.f_hz, self.w, self.q, self._bands = f_hz, w, q, {}

    def __call__(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(nodes, weights, L)`` of the band of points ``i0:i1``."""
        if (i0, i1) not in self._bands:
            nodes, W = gauss_nodes(self.f_hz[i0:i1], self.w[i0:i1], self.q)
            self._bands[i0, i1] = nodes, W, lagrange_matrix(nodes, self.f_hz[i0:i1])
        return self._bands[i0, i1]


@functools.lru_cache(maxsize=8)
def _quadratures_of(f_hz: bytes, w: bytes, q: int) -> Quadratures:
    return Quadratures(np.frombuffer(f_hz, float), np.frombuffer(w, float), q)


def quadratures(f_hz: np.ndarray, w: np.ndarray, q: int) -> Quadratures:
    """The :class:`Quadratures` of sorted points ``f_hz`` with weights ``w`` (kept for the
    last few such sets)."""
    return _quadratures_of(
        np.ascontiguousarray(f_hz, float).tobytes(), np.ascontiguousarray(w, float).tobytes(), q
    )


def _values_and_sensitivities(problem: LeastSquaresProblem, theta, f_hz):
    """The model and dH/dθ at frequencies ``f_hz`` (in the model's band), in chunks of
    :data:`CHUNK` (one compiled shape)."""
    H, J = [], []
    for i in range(0, f_hz.size, CHUNK):
        f = f_hz[i : i + CHUNK]
        padded = np.concatenate([f, np.full(CHUNK - f.size, f[-1])])
        probe = LeastSquaresProblem(
            problem.model.on_frequencies(padded),
            FitData(
                padded,
                np.zeros(CHUNK, complex),
                None,
                np.ones(CHUNK, bool),
                magnitude=problem.magnitude,
            ),
            problem.space,
            np.ones(CHUNK),
        )
        Jr, r = probe.jacobian_and_residuals_theta(theta)
        H.append(_values(r, CHUNK, problem.magnitude)[: f.size])
        J.append(_values(Jr, CHUNK, problem.magnitude)[: f.size])
    return np.concatenate(H), np.concatenate(J)


def _values(r: np.ndarray, n: int, magnitude: bool) -> np.ndarray:
    """The complex values (or, for a fit of |H| alone, the real ones) of stacked residuals
    or Jacobian rows ``r`` of ``n`` points: real parts, then imaginary parts."""
    return r[:n].astype(complex) if magnitude else r[:n] + 1j * r[n:]


def bands(
    problem: LeastSquaresProblem, theta, f_hz, sigma, scale, H, J, q: int = NODES
) -> list[tuple[int, int, tuple | None]]:
    """``[(i0, i1, (nodes, weights, L) or None)]``: the bands of the sorted points ``f_hz``
    (weights ``1/sigma²``) on which the interpolant through ``q`` Gauss nodes holds the
    model ``H`` and its sensitivities ``J`` times ``scale`` (p,) at ``theta`` to the band's
    share of :data:`TOL_STD` (``L``: the band's Lagrange matrix); ``None``: the band keeps
    its points."""
    n = f_hz.size
    quadrature = quadratures(f_hz, sigma**-2.0, q)
    todo, done = [(0, n)], []
    while todo:
        trial = [(i0, i1, quadrature(i0, i1)) for i0, i1 in todo if i1 - i0 > 2 * q]
        done += [(i0, i1, None) for i0, i1 in todo if i1 - i0 <= 2 * q]
        if not trial:
            break
        Hn, Jn = _values_and_sensitivities(problem, theta, np.concatenate([t[2][0] for t in trial]))
        todo = []
        for k, (i0, i1, (_, _, L)) in enumerate(trial):
            eH = np.abs(L @ Hn[k * q : (k + 1) * q] - H[i0:i1])
            eJ = (np.abs(L @ Jn[k * q : (k + 1) * q] - J[i0:i1]) * scale).max(axis=1)
            e2 = np.sum((np.maximum(eH, eJ) / sigma[i0:i1]) ** 2)
            if e2 <= TOL_STD**2 * (i1 - i0) / n:
                done.append(trial[k])
            else:
                mid = (i0 + i1) // 2
                todo += [(i0, mid), (mid, i1)]
    return sorted(done, key=lambda b: b[0])


def compressed(problem: LeastSquaresProblem, u) -> LeastSquaresProblem:
    """``problem`` on a few nodes per band, built around ``u`` (module docstring), or
    ``problem`` itself when it is short, not a shared-structure plate model, or would not
    shrink by half. A fit of |H| alone is compressed alike: its bands interpolate |H|."""
    if problem.n_points < MIN_POINTS or not isinstance(problem.model, SharedStructure):
        return problem
    theta = problem.space.theta(np.asarray(u, float))
    if not np.all(np.isfinite(theta)):
        return problem
    d = problem.data
    f = d.frequency_hz[d.used]
    order = np.argsort(f, kind="stable")
    f, data, sigma = f[order], d.H[d.used][order], problem.sigma[order]
    if np.any(np.diff(f) <= 0):
        return problem  # repeated frequencies: no interpolation
    n = f.size
    Jr, r = problem.jacobian_and_residuals_theta(theta)
    if not (np.all(np.isfinite(Jr)) and np.all(np.isfinite(r))):
        return problem  # no model there (a stiffness matrix not positive definite): no bands
    J = _values(Jr, n, problem.magnitude)[order] * sigma[:, None]
    H = _values(r, n, problem.magnitude)[order] * sigma + data
    F = Jr.T @ Jr
    scale = SCALE_STD * np.sqrt(np.abs(np.diag(np.linalg.pinv(F, rcond=1e-13, hermitian=True))))
    found = bands(problem, theta, f, sigma, scale, H, J)
    nodes, c, s, kappa = [], [], [], 0.0
    for i0, i1, quadrature in found:
        w, y = sigma[i0:i1] ** -2.0, data[i0:i1]
        if quadrature is None:
            nodes.append(f[i0:i1]), c.append(y), s.append(sigma[i0:i1])
            continue
        cj, k = project(f[i0:i1], w, y, *quadrature)
        kappa += k
        nodes.append(quadrature[0]), c.append(cj), s.append(quadrature[1] ** -0.5)
    nodes, c, s = np.concatenate(nodes), np.concatenate(c), np.concatenate(s)
    if nodes.size > n // 2:
        return problem
    # padded to a few lengths (one compilation each): nodes of infinite std weigh nothing
    extra = padded_size(nodes.size, NODE_COUNTS) - nodes.size
    nodes = np.append(nodes, np.full(extra, nodes[-1]))
    c, s = np.append(c, np.zeros(extra)), np.append(s, np.full(extra, np.inf))
    short = FitData(nodes, c, s, np.ones(nodes.size, bool), magnitude=d.magnitude)
    return LeastSquaresProblem(
        problem.model.on_frequencies(nodes), short, problem.space, s, chi2_offset=kappa
    )


def confirmed(
    problem: LeastSquaresProblem, short: LeastSquaresProblem, u, tol: float = 0.0
) -> bool:
    """Whether the full ``problem`` agrees that ``u``, the short problem's minimum, is its
    own to :data:`TOL_STD`: the full chi2's Newton step there (with the short problem's
    Hessian ``B``) is shorter than that many standard deviations, ``½ gᵀB⁻¹g ≤ TOL_STD²``
    (``B/2`` is the Fisher information), or than ``tol`` where that is larger."""
    f, g = problem.value_and_grad(u)
    if not (np.isfinite(f) and np.all(np.isfinite(g))):
        return True  # nothing to refine here: the optimiser's own status says it
    try:
        step = np.linalg.solve(short.hessian(u), g)
    except np.linalg.LinAlgError:
        return False
    return 0.5 * float(g @ step) <= max(TOL_STD**2, tol)


#: Rebuilds of the compressed problem around an end point the full data do not confirm
#: (then the run is finished on the full problem).
REBUILDS = 2


@dataclass(frozen=True)
class Compression:
    """A long AFC's ``full`` problem and the ``short`` one a run ended on: the next run of
    the same data and weights starts on its nodes (on a real strip's AFC, building them
    again for every start of a refit was a fifth of the closed loop's time)."""

    full: LeastSquaresProblem
    short: LeastSquaresProblem

    def on(self, problem: LeastSquaresProblem) -> LeastSquaresProblem | None:
        """The short problem on ``problem``'s model; None unless ``problem`` has the same
        data and weights as :attr:`full`."""
        if problem.data is not self.full.data or not np.array_equal(problem.sigma, self.full.sigma):
            return None
        if problem.model is self.full.model:
            return self.short
        return self.short.with_model(problem.model.on_frequencies(self.short.model.frequencies_hz))


def confirmed_run(
    method,
    problem: LeastSquaresProblem,
    short: LeastSquaresProblem,
    u0,
    max_iter: int = 200,
    tol: float = 0.0,
) -> tuple[LocalResult, LeastSquaresProblem]:
    """``method`` on the compressed ``short`` from ``u0``, its end point confirmed on the
    full ``problem`` (else the compression rebuilt there and the run resumed, at most
    :data:`REBUILDS` times, then finished on ``problem``); the loss is the full chi2.
    Returns the result and the short problem it ended on (``problem`` when finished on it).
    ``tol``: :func:`~vibid.identify.fit.local.run_local`'s."""
    r = method(short, u0, max_iter, tol)
    for _ in range(REBUILDS + 1):
        if not np.all(np.isfinite(r.u)) or confirmed(problem, short, r.u, tol):
            return replace(r, loss=problem.chi2(r.u)), short
        log.debug("the full data do not confirm the compressed fit: compressed again there")
        short = compressed(problem, r.u)
        r = method(short, r.u, max_iter, tol)
    return method(problem, r.u, max_iter, tol), problem
