"""Where the AFC holds information about the plate: Fisher information per step, per draw.

A step at frequency ``f`` recorded for ``T`` seconds measures ``H(f)`` with a standard
uncertainty per real and imaginary part of (the phasor fit of white noise, both channels of
noise ``σ_n`` relative to the base amplitude, ``N = T f_s`` samples; first order in the
ratio of two noisy phasors)::

    s(f, T) = σ_n · sqrt(2 / N) · sqrt(1 + |H(f)|²)

and adds the Fisher information ``F = (J_reᵀ J_re + J_imᵀ J_im) / σ²`` with ``J = ∂H/∂θ``
(for a magnitude-only test ``F = ∇|H| ∇|H|ᵀ / σ²``) and ``σ² = s² + e²``, ``e`` the model's
own error estimate (the finer mesh and the reduction check, as the identification weighs its
points). The mesh's error is, to first order, an error ``ε`` in the stiffness: it is
measured once at the prior's median, as the least-squares ``ε`` of the signed error on
``D ∂H/∂D``, and carried to every draw as ``ε |D ∂H/∂D|``; the reduction's part scales with
``|H|``: the same least-squares problem, Jacobian and weights as
the identification (:class:`~vibid.identify.fit.problem.LeastSquaresProblem`), so the
uncertainty predicted here is the report's, less re-records. A longer record shrinks ``s``
but not ``e``: the information a frequency can give is bounded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Information:
    """Per draw ``m`` and candidate frequency ``k``: the information of a unit-variance
    point ``G[m, k]`` (p, p), ``H[m, k]``, the noise ``s_1s[m, k]`` of a one-second record;
    per candidate the model error ``e[k]``; each draw's modes ``f_n[m]``, ``peak[m]`` (|H|
    at resonance) and loss ``beta[m]``."""

    frequency_hz: np.ndarray
    G: np.ndarray
    H: np.ndarray
    s_1s: np.ndarray
    e: np.ndarray
    f_n: np.ndarray
    peak: np.ndarray
    beta: np.ndarray


def fisher(info: Information, index, record_s) -> np.ndarray:
    """(m, n, p, p) information of steps ``index`` recorded ``record_s`` (n,) seconds."""
    var = info.s_1s[:, index] ** 2 / np.asarray(record_s, float)[None, :] + info.e[:, index] ** 2
    return info.G[:, index] / var[:, :, None, None]


def noise_std(H, record_s, sample_rate_hz: float, noise: float):
    """``s(f, T)`` above: standard uncertainty per part of a step's ``H``."""
    n = np.asarray(record_s, float) * sample_rate_hz
    return noise * np.sqrt(2.0 / n) * np.sqrt(1.0 + np.abs(H) ** 2)


#: where a mode is sampled: its response's phase this far from the phase at resonance,
#: degrees (±45°: the half-power points)
PHASES_DEG = np.arange(-75.0, 76.0, 15.0)


def across_mode(f_n, beta, phases_deg=PHASES_DEG) -> np.ndarray:
    """Frequencies across a mode's half-power band, evenly in phase: where the one-mode
    response ``1 / (f_n²(1 + iβ) − f²)`` is ``φ`` from its phase at ``f_n``,
    ``f = f_n √(1 − β tan φ)`` (φ = ±45° the half-power points). (..., len(phases))."""
    t = np.tan(np.radians(np.asarray(phases_deg, float)))
    f_n = np.asarray(f_n, float)[..., None]
    b = np.asarray(beta, float)[..., None]
    return f_n * np.sqrt(np.maximum(1.0 - b * t, 1e-12))


def candidate_frequencies(
    band_hz, f_n: np.ndarray, beta: np.ndarray, n_grid: int = 240
) -> np.ndarray:
    """A geometric grid over the band, and for every draw's every mode in the band, points
    across its half-power band evenly in phase (:func:`across_mode`): where the
    information may be."""
    lo, hi = band_hz
    out = [np.geomspace(lo, hi, n_grid)]
    for fm, b in zip(f_n, beta):
        inside = fm[(fm > lo) & (fm < hi)]
        out.append(across_mode(inside, b).ravel())
    f = np.unique(np.round(np.concatenate(out), 6))
    return f[(f >= lo) & (f <= hi)]


def information(
    setup,
    names,
    draws: np.ndarray,
    band_hz,
    *,
    noise: float,
    extra_hz=(),
    magnitude: bool = False,
    n_modes: int = 8,
    plate=None,
    bounds: dict | None = None,
    more_hz=(),
    grid: bool = True,
) -> Information:
    """The information of the setup's plate over the prior's ``draws`` (m, p), at candidate
    frequencies in ``band_hz`` (and ``more_hz``, e.g. across a resonance the plate model
    does not have) followed by ``extra_hz`` (e.g. the setup's own sweep, or the steps
    measured so far). ``plate``: a :class:`~vibid.identify.model.terms.PlateModel` (the
    declared material with the effects a fit found; default the setup's material) and
    ``bounds`` its prior box. ``grid`` False: at ``extra_hz`` alone (a plan's steps judged
    on other draws)."""
    from vibid.identify.fit.data import fit_data
    from vibid.identify.fit.problem import LeastSquaresProblem
    from vibid.identify.fit.space import ParameterSpace
    from vibid.identify.model.plate import build_forward_model

    extra = np.asarray(extra_hz, float)
    f_top = max(band_hz[1], float(extra.max()) if extra.size else 0.0)
    coarse = build_forward_model(
        setup, np.geomspace(band_hz[0], f_top, 64), model=plate, bounds=bounds
    )
    if tuple(coarse.parameter_names) != tuple(names):
        raise ValueError("the draws' parameters differ from the model's")
    f_n, peak = coarse.modes_batch(draws)
    f_n, peak = f_n[:, :n_modes], peak[:, :n_modes]
    beta = draws[:, list(names).index("beta")] if "beta" in names else np.full(len(draws), 1e-3)
    cand = candidate_frequencies(band_hz, f_n, beta) if grid else np.zeros(0)
    more = np.asarray(more_hz, float)
    if more.size:  # rounded as the grid is: a caller finds them again by their rounded value
        more = np.round(more[(more >= band_hz[0]) & (more <= band_hz[1])], 6)
        cand = np.unique(np.concatenate([cand, more]))
    freqs = np.concatenate([cand, extra])
    model = coarse.on_frequencies(freqs)
    data = fit_data(freqs, np.zeros(freqs.size), np.ones(freqs.size))
    problem = LeastSquaresProblem(model, data, ParameterSpace.from_bounds(names, model.bounds))
    K = freqs.size
    per_s, Hs, s1, dH_dD = [], [], [], []
    for theta in draws:
        J, r = problem.jacobian_and_residuals_theta(theta)  # σ = 1, data 0: r = (Re H, Im H)
        H = r[:K] + 1j * r[K:]
        Jc = J[:K] + 1j * J[K:]
        if magnitude:
            g = (np.conj(H)[:, None] * Jc).real / np.maximum(np.abs(H), 1e-300)[:, None]
            G = g[:, :, None] * g[:, None, :]
        else:
            G = np.einsum("ki,kj->kij", Jc.real, Jc.real) + np.einsum(
                "ki,kj->kij", Jc.imag, Jc.imag
            )
        s = noise_std(H, 1.0, setup.daq.sample_rate_hz, noise)
        per_s.append(G)
        dH_dD.append(Jc[:, 0])
        Hs.append(H)
        s1.append(s)
    e = _model_error(
        model, np.median(draws, axis=0), np.asarray(Hs), np.asarray(dH_dD), draws[:, 0]
    )
    return Information(
        freqs,
        np.asarray(per_s),
        np.asarray(Hs),
        np.asarray(s1),
        np.asarray(e),
        np.asarray(f_n),
        np.asarray(peak),
        np.asarray(beta),
    )


def _model_error(model, centre, H, dH_dD, D) -> np.ndarray:
    """(m, k) the model's error per part at each draw (see the module docstring); the first
    parameter is the stiffness (``D`` or ``D11``)."""
    d, reduction = model.model_error_parts(centre)
    J = np.asarray(model.afc(centre + np.eye(centre.size)[0] * centre[0] * 1e-6))
    sens = (J - np.asarray(model.afc(centre))) / 1e-6  # D ∂H/∂D at the median
    eps = float(np.real(np.vdot(sens, d)) / max(np.vdot(sens, sens).real, 1e-300))
    rel_red = float(np.max(reduction / np.maximum(np.abs(np.asarray(model.afc(centre))), 1e-300)))
    mesh = eps * np.abs(D[:, None] * dH_dD)
    return np.sqrt(mesh**2 / 2.0 + (rel_red * np.abs(H)) ** 2)
