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

chi2 alone misses a residual that is small but structured (a slow phase drift from a
delay, a resonance slightly off): the normalised residual ordered by frequency is then not
white. :func:`ljung_box_p` and :func:`runs_test_p` test that.

:func:`explains` is the one judge of "the fit explains the data": chi2 below its 0.999
quantile, and where chi2 is borderline (above its 0.95 quantile) a white normalised residual
along frequency. The report's ``unexplained_residual`` (with or without the loop), the
result's warning and the closed loop all ask it.
"""

from __future__ import annotations

import math

import numpy as np

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


def fits_noise(
    chi2: float, dof: int, noise_known: bool, *, quantile: float = QUANTILE
) -> bool | None:
    """Whether chi2 (weights: the data's standard uncertainties, and the model's own error
    where the fit includes it) is within the noise; None when the noise is not known."""
    if not noise_known or dof <= 0:
        return None
    return bool(math.isfinite(chi2) and chi2 <= chi2_limit(dof, quantile))


#: chi2 below this quantile fits the noise whatever the residual's shape; between it and
#: :data:`QUANTILE` chi2 is borderline, and a structured residual (not white) does not fit.
#: The model's own discretisation error is structured along frequency too: on low-noise
#: sessions it alone made the whiteness test fail on clean data.
BORDERLINE_QUANTILE = 0.95
#: A residual whose Ljung-Box p-value is below this is structured (not white).
WHITENESS_P = 1e-3
#: Whiteness is judged where the data's standard uncertainty is at least this share of the
#: weight (the model's estimated error below a quarter of the noise), on at least this many
#: points.
DATA_SHARE = 0.97
WHITENESS_MIN_POINTS = 20


def explains(result) -> bool | None:
    """Whether an :class:`~vibid.identify.fit.result.IdentificationResult` explains its data
    to the level of their noise (module doc); None when the noise is not known."""
    verdict = fits_noise(result.chi2, result.dof, result.noise_known)
    if not verdict:
        return verdict
    if fits_noise(result.chi2, result.dof, True, quantile=BORDERLINE_QUANTILE):
        return True
    return not whiteness_p(result) < WHITENESS_P


def _along_frequency(result, values) -> np.ndarray:
    """``values`` (one per AFC point) on ``result``'s used points, over its weights, in
    order of frequency: the normalised residual for ``model_afc - H``."""
    u = np.asarray(result.used)
    order = np.argsort(np.asarray(result.frequency_hz)[u], kind="stable")
    return (np.asarray(values)[u] / result.weights)[order]


def whiteness_p(result) -> float:
    """Ljung-Box p-value of ``result``'s normalised residual (real parts, then imaginary,
    each along frequency) on the points where the data's noise dominates the weight: the
    model's own discretisation error is smooth along frequency, so where it is a sizeable
    part of the weight the residual looks structured on data the model explains. Where
    fewer than :data:`WHITENESS_MIN_POINTS` such points remain, every point."""
    r = _along_frequency(result, result.model_afc - result.H)
    if result.H_std is not None:
        quiet = _along_frequency(result, np.asarray(result.H_std)) >= DATA_SHARE
        if np.count_nonzero(quiet) >= WHITENESS_MIN_POINTS:
            r = r[quiet]
    return ljung_box_p(r.real if result.magnitude else np.concatenate([r.real, r.imag]))


#: The window of the integrated autocorrelation time: the sum stops at the first lag M
#: with M >= WINDOW_C tau(M) (Sokal's automatic windowing).
WINDOW_C = 5.0


def _autocorrelation(x, centred: bool = True) -> np.ndarray:
    """The autocorrelation of ``x`` (real) at lags 0 .. n-1, normalised to 1 at lag 0 (its
    mean removed first where ``centred``); zeros where ``x`` is zero."""
    x = np.asarray(x, float)
    if centred:
        x = x - x.mean()
    n = x.size
    size = 1 << (2 * n - 1).bit_length()
    spectrum = np.fft.rfft(x, size)
    acf = np.fft.irfft(spectrum * np.conj(spectrum), size)[:n]
    return acf / acf[0] if acf[0] > 0 else np.zeros(n)


def _window(rho) -> int:
    """Sokal's window of the autocorrelation ``rho``: the first lag M with
    M >= WINDOW_C tau(M) (the last lag where there is none)."""
    tau = 2.0 * np.cumsum(rho) - 1.0
    lags = np.arange(rho.size)
    window = np.flatnonzero(lags >= WINDOW_C * tau)
    return int(window[0]) if window.size else rho.size - 1


def autocorrelation_time(residual) -> float:
    """The integrated autocorrelation time ``tau = 1 + 2 sum_k rho_k`` of ``residual``
    (real, ordered by frequency), summed up to Sokal's automatic window (the first lag
    ``M >= 5 tau(M)``; A. Sokal, "Monte Carlo methods in statistical mechanics", 1996,
    and emcee's ``integrated_time``): how many neighbouring residuals carry one
    independent one. 1 for white noise; a smooth model-form error spans many points.
    Floored at 1."""
    r = np.asarray(residual, float).ravel()
    r = r[np.isfinite(r)]
    if r.size < 3:
        return 1.0
    rho = _autocorrelation(r)
    if rho[0] <= 0:
        return 1.0
    m = _window(rho)
    return float(max(2.0 * np.sum(rho[: m + 1]) - 1.0, 1.0))


def correlation_along(result, other) -> float:
    """How many neighbouring residuals of ``result`` carry one independent one as seen
    along the change of the model from ``result`` to ``other`` (a refit of the same data:
    the difference of their ``model_afc``): ``1 + 2 Σ_k ρ_k c_k`` over Sokal's window of
    the residual's autocorrelation ``ρ``, ``c`` the change's own (not centred), the real
    and imaginary parts weighed by the change's share in each; at most
    :func:`residual_correlation`.

    A parameter that explains nothing takes from a residual with covariance ``σ² C`` a
    chi2 of ``(jᵀ C j / jᵀ j)`` times a chi-square variable, ``j`` the direction it moves
    the model in: the residual's correlation time where ``j`` is smooth over it (a gain,
    a step across the band), fewer neighbours where ``j`` is a narrow resonance (on a real
    strip, a stand feature 10 points wide in a residual correlated over 856)."""
    r = _along_frequency(result, result.model_afc - result.H)
    d = _along_frequency(result, np.asarray(other.model_afc) - np.asarray(result.model_afc))
    parts = ((r.real, d.real),) if result.magnitude else ((r.real, d.real), (r.imag, d.imag))
    taus, shares = [], []
    for x, y in parts:
        ok = np.isfinite(x) & np.isfinite(y)
        x, y = x[ok], y[ok]
        if x.size < 3 or not np.any(y):
            continue
        rho, c = _autocorrelation(x), _autocorrelation(y, centred=False)
        m = _window(rho)
        taus.append(1.0 + 2.0 * float(np.sum(rho[1 : m + 1] * c[1 : m + 1])))
        shares.append(float(y @ y))
    if not taus:
        return residual_correlation(result)
    along = float(np.average(taus, weights=shares))
    return float(min(max(along, 1.0), residual_correlation(result)))


def residual_correlation(result) -> float:
    """``result``'s normalised residual's autocorrelation time along frequency
    (:func:`autocorrelation_time`; the real parts' and the imaginary parts' mean, each
    ordered by frequency): the factor by which a residual that is not white inflates the
    variance of the estimates, beyond what chi2 says (an estimate is a weighted sum of
    residuals, and ``tau`` neighbouring ones count as one)."""
    r = _along_frequency(result, result.model_afc - result.H)
    parts = (r.real,) if result.magnitude else (r.real, r.imag)
    return float(np.mean([autocorrelation_time(x) for x in parts]))


def misfit_scale(result) -> tuple[float, float]:
    """``(reduced chi2, tau)`` of a fit whose residual holds more than the noise (reduced
    chi2 above 1, the noise known), tau its :func:`residual_correlation`; ``(1, 1)``
    otherwise. Their product is the variance a residual above the noise carries per
    independent point, in units of the noise's: the misfit measures the error, and its
    ``n / tau`` independent points carry it. The loop scales the final covariance by it
    (:func:`vibid.identify.loop.scaled_by_misfit`), and its judge asks a new effect's
    likelihood ratio to pass chi-square's quantile in its units: a parameter that explains
    nothing lowers chi2 by about this product times a chi-square variable with its
    parameters' count as degrees of freedom (``test_noise_correlation.py``)."""
    birge = float(result.chi2_reduced)
    if not (result.noise_known and np.isfinite(birge) and birge > 1.0):
        return 1.0, 1.0
    return birge, residual_correlation(result)


def fits(chi2: float, dof: int, n_residuals: int, noise_known: bool) -> bool:
    """The strategy's verdict on a polished minimum: :func:`fits_noise` with a known noise;
    without one (every weight the RMS |H|, so chi2 / m, m the real numbers fitted, is about
    the relative mean square residual), a relative RMS residual up to
    :data:`MAX_REL_RMS_UNKNOWN_NOISE`."""
    verdict = fits_noise(chi2, dof, noise_known)
    if verdict is not None:
        return verdict
    return bool(math.isfinite(chi2) and chi2 / max(n_residuals, 1) <= MAX_REL_RMS_UNKNOWN_NOISE**2)


def ljung_box_p(residual, lags: int | None = None) -> float:
    """p-value of the Ljung-Box test that ``residual`` (real, ordered by frequency; for a
    complex AFC pass the normalised residual's real parts, then its imaginary parts)
    is white: ``Q = n (n + 2) Σ_k ρ_k² / (n - k)`` over ``lags`` lags (default
    ``min(20, n // 5)``), chi-square with ``lags`` degrees of freedom under the null
    (Ljung & Box, Biometrika 65, 1978). A residual that is structured along the
    frequency axis (a missing effect) gives p near 0 even when chi2 is borderline."""
    from scipy.stats import chi2

    r = np.asarray(residual, float).ravel()
    r = r[np.isfinite(r)]
    n = r.size
    lags = min(20, n // 5) if lags is None else int(lags)
    if n < 3 or lags < 1:
        return math.nan
    r = r - r.mean()
    denom = float(r @ r)
    if denom == 0:
        return 1.0
    rho = np.array([float(r[k:] @ r[:-k]) / denom for k in range(1, lags + 1)])
    q = n * (n + 2) * float(np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return float(chi2.sf(q, lags))


def runs_test_p(residual) -> float:
    """Two-sided p-value of the Wald-Wolfowitz runs test on the signs of ``residual``
    (ordered by frequency): too few runs means neighbouring points err alike."""
    from scipy.stats import norm

    r = np.asarray(residual, float).ravel()
    s = np.sign(r[np.isfinite(r) & (r != 0)])
    n_pos, n_neg = int((s > 0).sum()), int((s < 0).sum())
    n = n_pos + n_neg
    if n_pos == 0 or n_neg == 0:
        return 0.0 if n > 10 else math.nan
    runs = 1 + int(np.sum(s[1:] != s[:-1]))
    mean = 2.0 * n_pos * n_neg / n + 1.0
    var = (mean - 1.0) * (mean - 2.0) / (n - 1.0)
    if var <= 0:
        return math.nan
    return float(2.0 * norm.sf(abs(runs - mean) / math.sqrt(var)))
