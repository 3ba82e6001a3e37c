"""Uncertainty of the estimate from the Fisher information at the optimum.

With weighted residuals r(theta) (:mod:`vibid.identify.fit.problem`) and J = dr/dtheta at the
estimate, the Fisher information of Gaussian noise of the declared standard uncertainty
is F = J^T J (the Gauss-Newton part of half the Hessian of chi2; the second-order term
averages to zero at a correct model). The covariance of the estimate is F^-1 (the
Cramer-Rao bound, attained to first order by least squares).

Scaling. When the AFC's standard uncertainty is known, the covariance is F^-1 as is:
its meaning does not depend on the fit, and ``chi2_reduced`` separately says whether the
model fits to the level of the noise (a value >> 1 means model error the weights do not
cover, and then these deviations are too small; the result carries a warning). When the
uncertainty is not known (the paper's plain MSE), the weights are a common guess s; the
noise variance is then estimated from the residual as s^2 chi2/(2n - p) (the usual
unbiased estimate of nonlinear regression), i.e. the covariance is F^-1 scaled by the
reduced chi-square. Only in that case.

Computed in physical units directly (J with respect to theta, not u), so no Jacobian of
the transforms is needed; a (near) singular F, i.e. parameters the data cannot separate,
is handled by a pseudo-inverse on the scale-normalised matrix and reported with a
warning (a parameter the AFC does not depend on gets an infinite standard deviation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Uncertainty:
    covariance: np.ndarray  # (p, p), physical units
    std: np.ndarray  # (p,)
    correlation: np.ndarray  # (p, p)
    scaled_by_chi2: bool
    condition: float  # condition number of the normalised Fisher matrix
    warnings: tuple[str, ...]


def fisher_uncertainty(
    J: np.ndarray, names, *, chi2_reduced: float, noise_known: bool, rcond: float = 1e-13
) -> Uncertainty:
    """Covariance, standard deviations and correlation from the residual Jacobian.

    Parameters
    ----------
    J: (m, p) Jacobian of the weighted residuals w.r.t. the physical parameters.
    names: the p parameter names (for warnings).
    chi2_reduced: chi2 / (m - p) at the estimate.
    noise_known: whether the weights are the data's real standard uncertainties.
    rcond: relative cut-off on the eigenvalues of the normalised Fisher matrix.
    """
    J = np.asarray(J, dtype=float)
    p = J.shape[1]
    warnings = []
    F = J.T @ J
    d = np.sqrt(np.diag(F))
    if not np.all(np.isfinite(F)):
        nan = np.full((p, p), np.nan)
        return Uncertainty(
            nan,
            np.full(p, np.nan),
            nan,
            False,
            np.inf,
            ("the Fisher information is not finite: no uncertainty available",),
        )
    insensitive = [n for n, di in zip(names, d) if di == 0]
    d = np.where(d > 0, d, 1.0)
    Fn = F / np.outer(d, d)  # unit diagonal: conditioning reflects correlation only
    w, V = np.linalg.eigh(Fn)
    cond = float(w[-1] / w[0]) if w[0] > 0 else np.inf
    keep = w > rcond * w[-1]
    inv_w = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    Cn = (V * inv_w) @ V.T
    cov = Cn / np.outer(d, d)
    if insensitive:
        for n in insensitive:
            i = list(names).index(n)
            cov[i, :] = cov[:, i] = 0.0
            cov[i, i] = np.inf
        warnings.append(
            f"the AFC does not depend on {', '.join(insensitive)}: not identifiable from these data"
        )
    elif not keep.all():
        warnings.append(
            "the data cannot separate some parameters (singular Fisher information, condition "
            f"{cond:.1e}): their standard deviations are lower bounds"
        )
    elif cond > 1e8:
        warnings.append(
            f"the parameters are nearly inseparable from these data (Fisher condition {cond:.1e})"
        )
    scaled = not noise_known
    if scaled and np.isfinite(chi2_reduced):
        cov = cov * chi2_reduced
    std = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    return Uncertainty(cov, std, corr, scaled, cond, tuple(warnings))
