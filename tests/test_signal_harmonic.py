"""Joint harmonic fit: bias, efficiency against the Cramér-Rao bound, calibrated uncertainty.

References are independent of the fit's code: the synthetic generator's known truth, the
textbook bounds (Rife & Boorstyn 1974; Kay 1993, ex. 3.14) and an exact Fisher matrix built
here from the time-domain model in amplitude/phase form.
"""

import numpy as np
import pytest

from vibid.hardware_mocks.records import synthetic_step, true_frequency_hz
from vibid.signal import Layout, fit_harmonics
from vibid.signal.flags import settling_chi2
from vibid.signal.ratio import phasor_ratio


def _clean(f_hz, h, fs_hz, n, **kw):
    """Noise-free (base, response) stacked as (2, N)."""
    return np.stack(synthetic_step(f_hz, h, sample_rate_hz=fs_hz, n_samples=n, **kw))


def _noisy(clean, sigma, m, seed):
    rng = np.random.default_rng(seed)
    return clean[None] + np.asarray(sigma)[None, :, None] * rng.standard_normal((m, *clean.shape))


def _h(fit):
    h, cov = phasor_ratio(fit.phasors_m_s2[:, 0, 0], fit.phasors_m_s2[:, 1, 0], fit.fundamental_cov)
    return h, np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1])


# ---------------------------------------------------------------- exactness and convergence


@pytest.mark.parametrize("n", [4000, 4001])
@pytest.mark.parametrize("ppm", [-200.0, 0.0, 137.0])
def test_noise_free_record_gives_h_and_frequency_exactly(n, ppm):
    f, fs, h = 37.3, 2560.0, 0.7 * np.exp(0.9j)
    x = _clean(
        f,
        h,
        fs,
        n,
        clock_offset_ppm=ppm,
        dc_m_s2=(0.3, -2.0),
        drift_m_s2_per_s=(0.05, 0.2),
        harmonics_db=(-30.0, -35.0),
        rng=3,
    )
    fit = fit_harmonics(x, f, fs)
    h_fit = fit.phasors_m_s2[0, 1, 0] / fit.phasors_m_s2[0, 0, 0]
    assert abs(h_fit - h) < 1e-9
    assert fit.frequency_hz[0] == pytest.approx(true_frequency_hz(f, ppm), rel=1e-11)
    assert fit.offset_m_s2[0] == pytest.approx(
        [0.3 + 0.05 * (n - 1) / fs / 2, -2.0 + 0.2 * (n - 1) / fs / 2], rel=1e-8
    )
    assert fit.drift_m_s2_per_s[0] == pytest.approx([0.05, 0.2], rel=1e-7)
    assert np.all(fit.converged)


@pytest.mark.parametrize("ppm", [-200.0, 200.0])
def test_offset_of_a_whole_bin_is_found(ppm):
    """10 kHz over 0.5 s: 200 ppm is one DFT bin; the coarse search must bring Gauss-Newton in."""
    f, fs, n, h = 10_000.0, 100_000.0, 50_000, 0.5 - 0.5j
    x = _clean(f, h, fs, n, clock_offset_ppm=ppm, harmonics_db=(-40.0, -40.0), rng=1)
    fit = fit_harmonics(x, f, fs)
    assert fit.frequency_hz[0] == pytest.approx(true_frequency_hz(f, ppm), rel=1e-12)
    assert abs(fit.phasors_m_s2[0, 1, 0] / fit.phasors_m_s2[0, 0, 0] - h) < 1e-9


def test_known_frequency_mode_uses_the_commanded_frequency():
    x = _clean(50.0, 1.0, 1000.0, 1000, clock_offset_ppm=100.0)
    fit = fit_harmonics(x, 50.0, 1000.0, refine_frequency=False)
    assert fit.frequency_hz[0] == 50.0
    assert fit.frequency_std_hz[0] == 0.0


def test_a_single_iteration_from_far_away_reports_no_convergence():
    x = _clean(100.0, 1.0, 10_000.0, 10_000, clock_offset_ppm=200.0)
    assert not fit_harmonics(x, 100.0, 10_000.0, max_iterations=1).converged[0]


def test_bad_layouts_are_refused():
    x = np.zeros((2, 100))
    with pytest.raises(ValueError, match="fs/2"):
        fit_harmonics(x, 200.0, 1000.0, layout=Layout(1, 3))
    with pytest.raises(ValueError, match="too short"):
        fit_harmonics(np.zeros((2, 12)), 50.0, 1000.0)


# ---------------------------------------------------------------- bias


@pytest.mark.parametrize(
    "f_hz, fs_hz, n",
    [
        (37.3, 2560.0, 4000),
        (10_000.0, 100_000.0, 20_001),
    ],  # 58.3 cycles; 2000.1 cycles (0.4 bin at 200 ppm)
)
def test_h_is_unbiased_across_clock_offsets(f_hz, fs_hz, n):
    """Clock offsets -200..+200 ppm, harmonics at -40 dB, DC, drift, non-integer cycles."""
    h_true = 0.8 * np.exp(-2.1j)
    sigma = (0.01, 0.02)
    m = 40
    z_all = []
    for j, ppm in enumerate(np.linspace(-200.0, 200.0, 9)):
        clean = _clean(
            f_hz,
            h_true,
            fs_hz,
            n,
            clock_offset_ppm=ppm,
            dc_m_s2=(0.5, -0.3),
            drift_m_s2_per_s=(0.2, -0.1),
            harmonics_db=(-40.0, -40.0),
            base_phase_rad=0.3 * j,
            rng=j,
        )
        fit = fit_harmonics(_noisy(clean, sigma, m, seed=100 + j), f_hz, fs_hz)
        h, s_re, s_im = _h(fit)
        # mean error against its own standard error: unbiased within uncertainty
        for part, s in ((np.real(h - h_true), s_re), (np.imag(h - h_true), s_im)):
            assert abs(part.mean()) < 4.0 * s.mean() / np.sqrt(m), (ppm, part.mean(), s.mean())
        z_all.append(np.concatenate([np.real(h - h_true) / s_re, np.imag(h - h_true) / s_im]))
    z = np.concatenate(z_all)
    # each error against its own std: standard normal (mean 0, variance 1)
    assert abs(z.mean()) < 4.0 / np.sqrt(z.size)
    assert z.var() == pytest.approx(1.0, abs=0.15)


# ---------------------------------------------------------------- efficiency


def _exact_crb(f_hz, fs_hz, n, amplitudes, sigma, n_harmonics, refine):
    """Inverse Fisher matrix of the joint model in amplitude/phase form, phases at the centre.

    Parameters per channel: dc, drift, A_k, φ_k (k = 1..K); then ω if refined. Harmonic phases
    are arbitrary (the bound does not depend on them); harmonic amplitudes are 1 % of A_1.
    Returns var(A_1), var(φ_1) per channel and var(ω).
    """
    t = (np.arange(n) - (n - 1) / 2) / fs_hz
    w = 2 * np.pi * f_hz
    cols_all = []
    for c, a1 in enumerate(amplitudes):
        block = [np.ones(n), t]
        for k in range(1, n_harmonics + 1):
            ak, phk = (a1 if k == 1 else 0.01 * a1), 0.4 * k
            block += [np.cos(k * w * t + phk), -ak * np.sin(k * w * t + phk)]
        cols_all.append(np.array(block).T / sigma[c])
    p = cols_all[0].shape[1]
    jac = np.zeros((2 * n, 2 * p + (1 if refine else 0)))
    jac[:n, :p], jac[n:, p : 2 * p] = cols_all
    if refine:
        for c, a1 in enumerate(amplitudes):
            d = sum(
                -(a1 if k == 1 else 0.01 * a1) * k * t * np.sin(k * w * t + 0.4 * k)
                for k in range(1, n_harmonics + 1)
            )
            jac[c * n : (c + 1) * n, -1] = d / sigma[c]
    cov = np.linalg.inv(jac.T @ jac)
    var_a = np.array([cov[2, 2], cov[p + 2, p + 2]])
    var_phi = np.array([cov[3, 3], cov[p + 3, p + 3]])
    var_w = cov[-1, -1] if refine else 0.0
    return var_a, var_phi, var_w


@pytest.mark.parametrize("refine", [False, True])
def test_amplitude_and_phase_variances_reach_the_cramer_rao_bound(refine):
    """4000 records: the sample variance is known to ±2.2 %, the 10 % band is ±4.5 sigma."""
    f, fs, n, m = 50.37, 1024.0, 1024, 4000
    h = 0.6 * np.exp(0.8j)
    sigma = np.array([0.05, 0.03])
    amplitudes = np.array([1.0, abs(h)])
    clean = _clean(
        f,
        h,
        fs,
        n,
        dc_m_s2=(0.2, 0.1),
        drift_m_s2_per_s=(0.1, -0.2),
        harmonics_db=(-40.0, -40.0),
        rng=5,
    )
    fit = fit_harmonics(_noisy(clean, sigma, m, seed=7), f, fs, refine_frequency=refine)
    x = fit.phasors_m_s2[:, :, 0]
    var_a = np.abs(x).var(axis=0, ddof=1)
    phase = np.angle(x * np.exp(-1j * np.angle(x.mean(axis=0))))
    var_phi = phase.var(axis=0, ddof=1)

    # textbook bounds (single sinusoid; with the phase at the record centre they hold for an
    # estimated frequency too): var A >= 2σ²/N, var φ >= 2σ²/(N A²)
    crb_a = 2 * sigma**2 / n
    crb_phi = 2 * sigma**2 / (n * amplitudes**2)
    assert var_a / crb_a == pytest.approx([1.0, 1.0], abs=0.10)
    assert var_phi / crb_phi == pytest.approx([1.0, 1.0], abs=0.10)

    # the exact bound of the full model (nuisance terms, shared frequency) agrees
    exact_a, exact_phi, exact_w = _exact_crb(f, fs, n, amplitudes, sigma, 3, refine)
    assert var_a / exact_a == pytest.approx([1.0, 1.0], abs=0.10)
    assert var_phi / exact_phi == pytest.approx([1.0, 1.0], abs=0.10)
    if refine:
        # frequency: var ω >= 1 / Σ_c A_c² N (N² - 1) / (24 σ_c² fs²), information adding over channels
        crb_w = 1.0 / np.sum(amplitudes**2 * n * (n**2 - 1) / (24 * sigma**2 * fs**2))
        var_w = (2 * np.pi * fit.frequency_hz).var(ddof=1)
        assert var_w / crb_w == pytest.approx(1.0, abs=0.10)
        assert exact_w == pytest.approx(crb_w, rel=0.02)


# ---------------------------------------------------------------- calibration


def test_reported_uncertainty_matches_the_monte_carlo_scatter():
    """1000 records: the sample std is known to ±2.2 %, the 15 % band is ±6.7 sigma."""
    f, fs, n, m = 123.4, 5120.0, 3000, 1000
    h = 2.5 * np.exp(1.2j)
    sigma = np.array([0.02, 0.08])
    clean = _clean(
        f,
        h,
        fs,
        n,
        clock_offset_ppm=-150.0,
        dc_m_s2=(1.0, 0.5),
        drift_m_s2_per_s=(0.3, 0.3),
        harmonics_db=(-40.0, -40.0),
        rng=11,
    )
    fit = fit_harmonics(_noisy(clean, sigma, m, seed=12), f, fs)
    h_fit, s_re, s_im = _h(fit)
    assert s_re.mean() / np.real(h_fit).std(ddof=1) == pytest.approx(1.0, abs=0.15)
    assert s_im.mean() / np.imag(h_fit).std(ddof=1) == pytest.approx(1.0, abs=0.15)
    assert fit.frequency_std_hz.mean() / fit.frequency_hz.std(ddof=1) == pytest.approx(
        1.0, abs=0.15
    )
    assert fit.noise_std_m_s2.mean(axis=0) == pytest.approx(sigma, rel=0.01)
    # the settling statistics are χ² with 1 (amplitude) and 2 (H) degrees of freedom: on clean
    # records their means are 1 and 2 (each known to ±4.5 %)
    amp_chi2, h_chi2 = settling_chi2(fit.half_phasors_m_s2, fit.half_cov)
    assert amp_chi2.mean(axis=0) == pytest.approx([1.0, 1.0], abs=0.2)
    assert h_chi2.mean() == pytest.approx(2.0, abs=0.3)


@pytest.mark.parametrize("n", [6400, 6401])
def test_residual_of_each_half_is_the_plain_least_squares_residual(n):
    """The fit's residual sums of squares over the first and the second half of the record
    (the centre sample of an odd record in neither), against numpy's least squares of the
    same model (offset, drift, 3 harmonics) at the fitted frequency, on the whole record."""
    fs, f = 25600.0, 210.0
    base, response = synthetic_step(
        f, 2.0 - 1.0j, sample_rate_hz=fs, n_samples=n, noise_std_m_s2=(1e-3, 1e-3), rng=4
    )
    t = np.arange(n) / fs
    response = response + 0.05 * np.exp(-8.0 * t) * np.cos(2 * np.pi * 251.0 * t)  # a ring
    x = np.stack([base, response])
    fit = fit_harmonics(x, f, fs, layout=Layout(1, 3))
    tc = t - t.mean()
    w = 2 * np.pi * fit.frequency_hz[0]
    a = np.stack([np.ones(n), tc] + [g(k * w * tc) for g in (np.cos, np.sin) for k in (1, 2, 3)], 1)
    h = n // 2
    for c in range(2):
        r = x[c] - a @ np.linalg.lstsq(a, x[c], rcond=None)[0]
        expected = [r[:h] @ r[:h], r[n - h :] @ r[n - h :]]
        np.testing.assert_allclose(fit.residual_ss_halves[0, c], expected, rtol=2e-3)
    first, second = fit.residual_ss_halves[0, 1]
    assert first > 2 * second  # the ring dies out: the first half holds more
