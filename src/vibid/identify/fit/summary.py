"""The answer of an identification: estimate, covariance, warnings, model AFC."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from vibid.errors import VibidError
from vibid.identify.fit.data import FitData
from vibid.identify.fit.minima import rival_minima
from vibid.identify.fit.noise import explains
from vibid.identify.fit.problem import PlateForwardModel
from vibid.identify.fit.result import IdentificationResult, LocalResult, final_status
from vibid.identify.fit.uncertainty import fisher_uncertainty
from vibid.identify.model.model_error import ModelErrorSplit


def summarise(
    problem,
    data: FitData,
    model: str,
    best: LocalResult,
    runs,
    global_result,
    warnings: list,
    t0: float,
    throw: bool,
    systematic: ModelErrorSplit | None,
    compared: list,
) -> IdentificationResult:
    """The IdentificationResult of the best run on its final ``problem``: covariance
    (Fisher, widened by rival minima and the model's systematic error), warnings, the
    model AFC. ``compared`` holds every run with its chi2 under the final weights."""
    space = problem.space
    theta = best.theta
    if not np.all(np.isfinite(theta)):  # cannot happen for finite u; never report NaN
        raise VibidError("the identification produced non-finite parameters")
    r = problem.residuals(best.u)
    chi2 = float(r @ r)
    dof = problem.dof
    chi2_red = chi2 / dof if dof > 0 else math.nan
    cov, rivals = covariance(problem, data, best, compared, chi2_red, systematic, warnings)
    std, corr = std_and_correlation(cov)
    model_afc, rel_rms, chi2_red_data = model_afc_on(problem, data, theta, dof)
    status, message = final_status(best, space, theta, chi2)
    if not status.ok:
        warnings.append(f"the local optimisation {message}")
    if throw and not status.ok:
        raise VibidError(f"identification of model {model!r}: {message}")
    result = IdentificationResult(
        model=model,
        parameter_names=space.names,
        values=np.asarray(theta, float),
        std=std,
        covariance=cov,
        correlation=corr,
        chi2=chi2,
        chi2_reduced=chi2_red,
        dof=dof,
        rel_rms_residual=rel_rms,
        status=status,
        message=message,
        noise_known=data.noise_known,
        frequency_hz=data.frequency_hz,
        H=data.H,
        H_std=data.std,
        used=data.used,
        model_afc=model_afc,
        global_result=global_result,
        local_results=tuple(runs),
        warnings=(),
        model_error_bias=None if systematic is None else systematic.bias,
        chi2_reduced_data_weights=chi2_red_data,
        seconds=time.perf_counter() - t0,
        weights=np.asarray(problem.sigma, float).copy(),
        plate_model=(problem.model.param if isinstance(problem.model, PlateForwardModel) else None),
        magnitude=data.magnitude,
        magnitude_only_std_ratio=magnitude_only_std_ratio(problem, theta),
        rivals=rivals,
    )
    # the one judge of "fits the noise" (chi2 and, where borderline, a white residual), as
    # the report's unexplained_residual and the closed loop ask it
    reaches_noise = explains(result) is not False
    warnings += estimate_warnings(space, theta, std, chi2_red, reaches_noise)
    return replace(result, warnings=tuple(warnings))


def covariance(problem, data: FitData, best: LocalResult, compared, chi2_red, systematic, warnings):
    """The estimate's covariance: the Fisher information's, widened by the rival minima
    (:func:`~vibid.identify.fit.minima.rival_minima`) and the model's systematic error;
    returns ``(covariance, rivals)`` and adds their notes to ``warnings``."""
    space = problem.space
    unc = fisher_uncertainty(
        problem.jacobian_theta(best.theta),
        space.names,
        chi2_reduced=chi2_red,
        noise_known=data.noise_known,
    )
    warnings.extend(unc.warnings)
    cov, note, rivals = rival_minima(
        compared, best, unc.covariance, chi2_red, data.noise_known, space.names
    )
    if systematic is not None:
        cov = cov + systematic.covariance
    if note:
        warnings.append(note)
    return cov, rivals


def std_and_correlation(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviations and correlation matrix of ``cov`` (nan where undefined, 1 on the
    diagonal)."""
    std = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    return std, corr


def model_afc_on(problem, data: FitData, theta, dof: int):
    """The model AFC at ``theta`` on every point (nan where unused, as the fit sees it),
    its relative RMS residual and its reduced chi2 under the data's own std (nan when
    unknown): ``(model_afc, rel_rms, chi2_red_data)``."""
    Hm_used = problem.model_afc(theta)
    if Hm_used.size != data.n_used:
        Hm_used = problem.on_points(Hm_used)
    Hm_used = problem.observed(Hm_used)
    H_used = data.H[data.used]
    rel_rms = float(np.sqrt(np.mean(np.abs(Hm_used - H_used) ** 2) / np.mean(np.abs(H_used) ** 2)))
    chi2_red_data = math.nan
    if data.noise_known and dof > 0:
        rd = (Hm_used - H_used) / data.std[data.used]
        chi2_red_data = float(np.sum(rd.real**2 + rd.imag**2)) / dof
    model_afc = np.full(data.H.shape, np.nan + 1j * np.nan)
    model_afc[data.used] = Hm_used
    return model_afc, rel_rms, chi2_red_data


def estimate_warnings(space, theta, std, chi2_red: float, reaches_noise: bool) -> list[str]:
    """Warnings about the estimate: parameters on their prior bounds (whose advice depends
    on whether the model reaches the data's noise), parameters poorly determined, and a
    model that does not reach the noise."""
    warnings = []
    for name in space.out_of_bounds(theta):
        t = space.transforms[space.names.index(name)]
        v = theta[space.names.index(name)]
        warnings.append(
            f"{name} = {v:.6g} lies on or outside its prior bounds [{t.low:g}, {t.high:g}]: "
            + (
                "the bounds may exclude the true value; widen them and identify again"
                if reaches_noise
                else "the model does not reach the data's noise, so it may stand in for what the "
                "model lacks rather than lie outside them (widening them would explain "
                "nothing)"
            )
        )
    for name, v, s in zip(space.names, theta, std):
        if np.isfinite(s) and abs(v) > 0 and s > 0.3 * abs(v):
            warnings.append(
                f"{name} is poorly determined by these data (std {s:.2g} = "
                f"{100 * s / abs(v):.0f} % of its value)"
            )
    if not reaches_noise:
        warnings.append(
            f"the model does not fit the data to their noise level (reduced chi2 = "
            f"{chi2_red:.3g}): the standard deviations understate the error"
        )
    return warnings


def magnitude_only_std_ratio(problem, theta) -> dict[str, float] | None:
    """How much each parameter's standard deviation grows when the fit sees |H| alone
    instead of the complex AFC of the same points, model and weights: the square root of
    the ratio of the diagonals of the two inverse Fisher informations (unscaled; each fit's
    own). At least 1: |H|'s Jacobian rows are the complex rows projected on the radial
    direction. None for a complex fit."""
    if not problem.magnitude:
        return None
    names = problem.space.names
    std = [
        fisher_uncertainty(
            p.jacobian_theta(theta), names, chi2_reduced=math.nan, noise_known=True
        ).std
        for p in (problem, problem.as_complex())
    ]
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = std[0] / std[1]
    return {n: float(r) for n, r in zip(names, ratio)}
