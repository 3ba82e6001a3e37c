"""The forward model's own error: the part the parameters absorb, and the part they cannot.

The forward model estimates its discretisation error at the estimate as the signed
difference ``d_k = H_inf,k - H_k`` to a mesh-converged AFC (``ForwardModel.model_error_parts``),
plus a reduction error of known size but unknown sign (the reduced basis against the full
model). ``H_inf`` is Richardson's extrapolation over three meshes of one refinement family
(:func:`richardson`): the next coarser ``H_c``, the model's own ``H`` and the next finer
``H_f``. The finer mesh's own error is not assumed small: with cells ``h_c > h > h_f`` and
an error ``C h^p``, the order ``p`` is measured from how much each step moves the AFC,

    |H_f - H| / |H - H_c| = (1 - s_f^p) / (s_c^p - 1),     s_f = h_f / h,  s_c = h_c / h,

and the model's error is ``H_inf - H = (H_f - H) / (1 - s_f^p)``. On the paper's strip
(cells 2/3 as large per level, one more corner level) p comes out about 5.9, so the next
finer mesh holds 9 to 11 % of the model's error itself, as a converged mesh (90 x 18
cells, 8 corner levels) shows: 7 to 9 % of D's and nu's bias. On a plate meshed by its
bending wavelength (150 x 100 mm to 600 Hz: 15 x 10 cells) the meshes are not yet
asymptotic: p 3.8, the finer mesh holding 26 % by the extrapolation where a mesh three
levels finer shows about 49 %; the estimate misses half of what the finer step alone
missed (``benchmarks/disc_error.py``). The coarser mesh costs about a quarter of the finer
one (0.3-0.5 s against 0.9-1.8 s on the strip, once after the fit).

Most of d is a small shift of the
resonances, which a small change of the stiffnesses reproduces almost exactly: put in the
weights as it is, it would count as noise the fit never sees (reduced chi2 of a correct
model far below 1), while it really moves the estimate by a bias nobody reports.

So d is split, in the residual units of the fit (r = (H_model - H) / sigma), by a
least-squares projection onto the Jacobian J = dr/dtheta at the estimate:

    delta_theta = argmin |J delta_theta - d / sigma|,      rest = d / sigma - J delta_theta.

* ``delta_theta`` is the bias of the estimate that the discretisation error causes (to
  first order, against the extrapolated limit). It enters the covariance as a systematic
  term delta_theta delta_theta^T, so the reported standard deviations cover it: each
  holds the fit's noise (the data's Fisher information, widened by rival minima where
  there are some) and this discretisation part, in quadrature.
* ``rest`` is what no parameter change explains: it stays in the residual, and its size
  per point (with the reduction error) is the model-error standard uncertainty that joins
  the data's in the weights, so that a correct model fits to a reduced chi2 near 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

#: The slowest mesh convergence the extrapolation trusts, ``h^MIN_ORDER``: where the three
#: meshes show a slower one (or none), the model's error is taken as ``(H_f - H) / (1 -
#: s_f^MIN_ORDER)``, three times the finer step for cells 2/3 as large. A corner
#: singularity of a clamped-free plate limits a uniform mesh of any element to about h^1.5
#: (scikit-fem's Argyris on the strip's torsion mode); vibid refines the corners.
MIN_ORDER = 1.0
#: The fastest order solved for (beyond it the finer step is the whole error).
MAX_ORDER = 40.0


@dataclass(frozen=True)
class Extrapolation:
    """Richardson's extrapolation of a discretisation's error from three meshes.

    ``ratio``: ``|H_f - H| / |H - H_c|`` (relative to ``|H|`` at each point); ``order``:
    the measured ``p`` of ``C h^p`` (``MIN_ORDER`` where the meshes show a slower one,
    ``inf`` where the coarser step moved nothing); ``factor``: ``(H_inf - H) / (H_f - H)``,
    at least 1; ``limited``: whether ``order`` was held at ``MIN_ORDER``."""

    ratio: float
    order: float
    factor: float
    limited: bool = False


def convergence_order(ratio: float, s_fine: float, s_coarse: float) -> float:
    """The order p with ``(1 - s_fine^p) / (s_coarse^p - 1) = ratio``: the error ``C h^p``
    of three meshes whose cells are ``s_coarse > 1`` and ``s_fine < 1`` times the middle
    one's, given how much the finer step moves the result against the coarser step
    (``ratio``; ``s_fine^p`` when both steps are alike). ``MIN_ORDER`` where the steps
    show a slower convergence, ``MAX_ORDER`` a faster one."""
    if not (0.0 < s_fine < 1.0 < s_coarse):
        raise ValueError(f"cell ratios must bracket 1, got {s_fine} and {s_coarse}")

    def g(p):
        return (1.0 - s_fine**p) / (s_coarse**p - 1.0) - ratio

    if not np.isfinite(ratio) or g(MIN_ORDER) <= 0.0:
        return MIN_ORDER
    if g(MAX_ORDER) >= 0.0:
        return MAX_ORDER
    return float(brentq(g, MIN_ORDER, MAX_ORDER, xtol=1e-10))


def richardson(H_coarse, H, H_fine, s_fine: float, s_coarse: float) -> Extrapolation:
    """Richardson's extrapolation of the error of ``H`` (complex (n,)) from the AFCs of a
    coarser and a finer mesh of the same family, cells ``s_coarse`` and ``s_fine`` times
    ``H``'s: ``H_inf - H = factor (H_fine - H)``, the order measured from the two steps in
    the 2-norm of the differences relative to ``|H|`` at each point. ``H_coarse`` None:
    no coarser mesh, and the error is bounded by the slowest order trusted
    (:data:`MIN_ORDER`)."""
    H, H_fine = np.asarray(H, complex), np.asarray(H_fine, complex)
    scale = np.maximum(np.abs(H), 1e-300)
    fine = float(np.linalg.norm((H_fine - H) / scale))
    coarse = (
        0.0
        if H_coarse is None
        else float(np.linalg.norm((H - np.asarray(H_coarse, complex)) / scale))
    )
    if H_coarse is None:
        s_coarse = max(s_coarse, 1.0 / s_fine)
    if fine == 0.0:  # the finer mesh moved nothing: nothing to extrapolate
        return Extrapolation(0.0, math.inf, 1.0)
    ratio = fine / coarse if coarse > 0.0 else math.inf
    p = convergence_order(ratio, s_fine, s_coarse)
    return Extrapolation(ratio, p, 1.0 / (1.0 - s_fine**p), limited=p <= MIN_ORDER)


@dataclass(frozen=True)
class ModelErrorSplit:
    """``point_std``: (n,) model-error standard uncertainty per Re/Im part of each fitted
    point (the unexplained part); ``bias``: (p,) parameter shift, physical units."""

    point_std: np.ndarray
    bias: np.ndarray

    @property
    def covariance(self) -> np.ndarray:
        """The systematic covariance term ``bias bias^T``."""
        return np.outer(self.bias, self.bias)


def split_model_error(
    J_theta: np.ndarray, d: np.ndarray, reduction, sigma: np.ndarray
) -> ModelErrorSplit:
    """Split the model's error at the estimate into a parameter bias and a remainder.

    Parameters
    ----------
    J_theta: (2n, p) Jacobian of the weighted residuals (real parts, then imaginary) with
        respect to the physical parameters, weights ``sigma``; (n, p) for a fit of |H|
        alone, whose ``d`` is then the error of |H| (real).
    d: (n,) complex signed discretisation error of the model AFC at the fitted points.
    reduction: (n,) standard uncertainty of the reduction error per Re/Im part at the
        fitted points (unknown sign, so never projected), or a scalar for all.
    sigma: (n,) the weights the Jacobian was computed with.
    """
    d = np.asarray(d, complex)
    sigma = np.asarray(sigma, float)
    J = np.asarray(J_theta, float)
    n = d.size
    parts = 1 if J.shape[0] == n else 2  # |H| alone, or Re H and Im H
    delta = np.concatenate([d.real, d.imag][:parts]) / np.tile(sigma, parts)
    finite = np.all(np.isfinite(J), axis=1) & np.isfinite(delta)
    bias = np.zeros(J.shape[1])
    if finite.any() and np.any(delta[finite] != 0):
        Jf = J[finite]
        scale = np.linalg.norm(Jf, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        b, *_ = np.linalg.lstsq(Jf / scale, delta[finite], rcond=1e-12)
        bias = b / scale
    rest = np.where(finite, delta - J @ bias, 0.0) * np.tile(sigma, parts)
    per_point = np.sqrt(np.sum(rest.reshape(parts, n) ** 2, axis=0) / parts)
    point_std = np.sqrt(per_point**2 + np.asarray(reduction, float) ** 2)
    return ModelErrorSplit(point_std=point_std, bias=bias)
