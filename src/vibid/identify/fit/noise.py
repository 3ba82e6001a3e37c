"""Does a fit explain the data to the level of their noise? The one home of that test.

With known standard uncertainties, the weighted residuals of a correct model are standard
normal, so chi2 follows the chi-square distribution with ``dof`` degrees of freedom: a fit
*fits the noise* when its chi2 lies below that distribution's ``QUANTILE``. The
identification strategy asks it (a polished minimum that does not fit the noise sends the
search on to match the resonance peaks), the result's warning and the report's
``unexplained_residual`` report it, and the closed loop decides on it whether an effect is
missing.

Without a known noise level nothing can be tested against the noise: :func:`fits_noise`
then says None, and the strategy falls back on the relative RMS residual
(:data:`MAX_REL_RMS_UNKNOWN_NOISE`).
"""

from __future__ import annotations

import math

#: A chi2 beyond this quantile of its distribution does not fit the noise (one false alarm
#: in a thousand correct fits).
QUANTILE = 0.999
#: Without a known noise, a relative RMS residual above this is not a fit (a wrong basin
#: misses whole resonances: relative residuals of order 1).
MAX_REL_RMS_UNKNOWN_NOISE = 1e-2


def chi2_limit(dof: int, quantile: float = QUANTILE) -> float:
    """The largest chi2 that fits the noise with ``dof`` degrees of freedom."""
    from scipy.stats import chi2

    return float(chi2.ppf(quantile, max(int(dof), 1)))


def fits_noise(chi2: float, dof: int, noise_known: bool, *,
               quantile: float = QUANTILE) -> bool | None:
    """Whether chi2 (weights: the data's standard uncertainties, and the model's own error
    where the fit includes it) is within the noise; None when the noise is not known."""
    if not noise_known or dof <= 0:
        return None
    return bool(math.isfinite(chi2) and chi2 <= chi2_limit(dof, quantile))


def fits(chi2: float, dof: int, n_points: int, noise_known: bool) -> bool:
    """The strategy's verdict on a polished minimum: :func:`fits_noise` with a known noise;
    without one (every weight the RMS |H|, so chi2 / 2n is the relative mean square
    residual), a relative RMS residual up to :data:`MAX_REL_RMS_UNKNOWN_NOISE`."""
    verdict = fits_noise(chi2, dof, noise_known)
    if verdict is not None:
        return verdict
    return bool(math.isfinite(chi2) and chi2 / (2 * max(n_points, 1)) <= MAX_REL_RMS_UNKNOWN_NOISE**2)
