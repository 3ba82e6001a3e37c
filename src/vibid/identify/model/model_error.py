"""The forward model's own error: the part the parameters absorb, and the part they cannot.

The forward model estimates its discretisation error at the estimate as the signed
difference d_k = H_finer,k - H_k to the next finer mesh (``ForwardModel.model_error_parts``),
plus a reduction error of known size but unknown sign (the reduced basis against the full
model). Most of d is a small shift of the
resonances, which a small change of the stiffnesses reproduces almost exactly: put in the
weights as it is, it would count as noise the fit never sees (reduced chi2 of a correct
model far below 1), while it really moves the estimate by a bias nobody reports.

So d is split, in the residual units of the fit (r = (H_model - H) / sigma), by a
least-squares projection onto the Jacobian J = dr/dtheta at the estimate:

    delta_theta = argmin |J delta_theta - d / sigma|,      rest = d / sigma - J delta_theta.

* ``delta_theta`` is the bias of the estimate that the discretisation error causes (to
  first order; the finer mesh's own error is several times smaller). It enters the
  covariance as a systematic term delta_theta delta_theta^T, so the reported standard
  deviations cover it.
* ``rest`` is what no parameter change explains: it stays in the residual, and its size
  per point (with the reduction error) is the model-error standard uncertainty that joins
  the data's in the weights, so that a correct model fits to a reduced chi2 near 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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


def split_model_error(J_theta: np.ndarray, d: np.ndarray, reduction,
                      sigma: np.ndarray) -> ModelErrorSplit:
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
