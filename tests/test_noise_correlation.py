"""The residual's autocorrelation time (``fit.noise.autocorrelation_time``), against the
closed form of an AR(1) sequence, ``(1 + rho) / (1 - rho)``, and by Monte Carlo: the least-
squares estimates from correlated residuals scatter by ``sqrt(tau)`` times what white
residuals of the same size would give, which is what the loop's scaled standard
deviations add (``loop.rounds.scaled_by_misfit``)."""

import numpy as np
import pytest

from vibid.identify.fit.noise import autocorrelation_time


def _ar1(rng, rho, n):
    from scipy.signal import lfilter

    e = rng.standard_normal(n) * np.sqrt(1 - rho**2)
    e[0] /= np.sqrt(1 - rho**2)
    return lfilter([1.0], [1.0, -rho], e)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9])
def test_the_autocorrelation_time_of_an_ar1_sequence(rho):
    rng = np.random.default_rng(3)
    taus = [autocorrelation_time(_ar1(rng, rho, 20000)) for _ in range(10)]
    assert np.mean(taus) == pytest.approx((1 + rho) / (1 - rho), rel=0.06)


def test_a_smooth_residual_spans_many_points_and_white_noise_one():
    f = np.linspace(0.0, 1.0, 4000)
    assert autocorrelation_time(np.sin(2 * np.pi * 3 * f)) > 50
    assert autocorrelation_time(np.random.default_rng(0).standard_normal(4000)) < 1.1


def test_the_scatter_of_a_fit_to_correlated_residuals_grows_by_sqrt_tau():
    """A straight line fitted by least squares to AR(1) noise (rho 0.8, tau 9): over 400
    draws, the scatter of the intercept and slope is sqrt(tau) times the white-noise
    formula's, with tau estimated from each draw's own residual."""
    rng = np.random.default_rng(11)
    n, rho = 2000, 0.8
    x = np.linspace(-1.0, 1.0, n)
    A = np.column_stack([np.ones(n), x])
    est, std = [], []
    for _ in range(400):
        y = _ar1(rng, rho, n)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ coef
        s2 = r @ r / (n - 2)
        cov = s2 * np.linalg.inv(A.T @ A) * autocorrelation_time(r)
        est.append(coef)
        std.append(np.sqrt(np.diag(cov)))
    ratio = np.std(est, axis=0) / np.mean(std, axis=0)
    assert ratio == pytest.approx([1.0, 1.0], abs=0.12)


def test_a_parameter_that_explains_nothing_gains_about_the_misfit_scale_times_chi2():
    """Monte Carlo of what the loop's judge assumes (``fit.noise.misfit_scale``): a residual
    50 times the noise's variance and correlated along frequency (AR(1), rho 0.9, tau 19,
    800 points on a shuffled grid), and a refit of one parameter that explains nothing (a
    smooth shape, fitted by least squares as a refit does). The likelihood ratio passes
    the white-noise test (chi-square's 0.99 quantile) in nearly every draw; in units of
    the reduced chi2 times tau, both estimated from each draw's own residual, it passes
    about as often as that quantile allows (4 of 400 expected; 12 is beyond 3.5 sigma)."""
    from types import SimpleNamespace

    from scipy.stats import chi2

    from vibid.identify.fit.noise import misfit_scale

    rng = np.random.default_rng(17)
    n, birge = 800, 50.0
    x = np.linspace(-1.0, 1.0, n)
    order = rng.permutation(n)
    shape = np.cos(np.pi * x) + 0.5 * x
    q = chi2.ppf(0.99, 1)
    white = scaled = 0
    taus = []
    for _ in range(400):
        r = np.sqrt(birge) * _ar1(rng, 0.9, n)
        gain = (shape @ r) ** 2 / (shape @ shape)
        result = SimpleNamespace(
            used=np.ones(n, bool),
            frequency_hz=(100.0 + 800.0 * x)[order],
            model_afc=r[order],
            H=np.zeros(n),
            weights=np.ones(n),
            magnitude=True,
            noise_known=True,
            chi2_reduced=r @ r / n,
        )
        b, tau = misfit_scale(result)
        taus.append(tau)
        white += gain > q
        scaled += gain > q * b * tau
    assert np.mean(taus) == pytest.approx(19.0, rel=0.15)
    assert white / 400 > 0.8
    assert scaled / 400 <= 0.03


def test_a_fit_at_the_noise_has_no_misfit_scale():
    from types import SimpleNamespace

    from vibid.identify.fit.noise import misfit_scale

    fit = SimpleNamespace(noise_known=True, chi2_reduced=0.97)
    assert misfit_scale(fit) == (1.0, 1.0)
    assert misfit_scale(SimpleNamespace(noise_known=False, chi2_reduced=40.0)) == (1.0, 1.0)


def test_a_narrow_change_sees_fewer_neighbours_of_a_smooth_misfit():
    """Monte Carlo of the judge's units for a narrow effect
    (``fit.noise.correlation_along``): a residual 50 times the noise's variance, AR(1) with
    rho 0.98 (tau 99) over 4000 points, and a refit of one parameter that explains
    nothing and moves the model only over a few points (a resonance 6 points wide, the
    titanium strip's 982 Hz feature against its residual correlated over 856). The
    expected likelihood ratio is ``b jᵀCj / jᵀj`` with C the AR(1) correlation: 14.9 b
    here, not 99 b (the draws' mean: 14.4 b); ``correlation_along``, estimated from each
    draw's own residual, finds 14.7 on average, and the likelihood ratio in its units
    passes chi-square's 0.99 quantile in 1 % of the draws. Along a smooth change it is
    tau (0.98 of it)."""
    from types import SimpleNamespace

    from scipy.stats import chi2

    from vibid.identify.fit.noise import correlation_along, misfit_scale

    rng = np.random.default_rng(23)
    n, birge, rho = 4000, 50.0, 0.98
    x = np.arange(n, dtype=float)
    z = (x - 2100.0) / 3.0
    narrow = z / (1.0 + z**2)  # the dispersive part of a resonance's change, 6 points wide
    smooth = np.cos(np.pi * x / n)
    lags = np.abs(x[:, None] - x[None, :])
    exact = float(narrow @ (rho**lags) @ narrow / (narrow @ narrow))
    assert exact < 99.0 / 5
    q = chi2.ppf(0.99, 1)
    along, gains, passed, smooth_tau = [], [], 0, []
    for _ in range(200):
        r = np.sqrt(birge) * _ar1(rng, rho, n)
        result = SimpleNamespace(
            used=np.ones(n, bool),
            frequency_hz=100.0 + x,
            model_afc=r,
            H=np.zeros(n),
            weights=np.ones(n),
            magnitude=True,
            noise_known=True,
            chi2_reduced=r @ r / n,
        )
        b, _ = misfit_scale(result)
        t = correlation_along(result, SimpleNamespace(model_afc=r + narrow))
        gain = (narrow @ r) ** 2 / (narrow @ narrow)
        along.append(t)
        gains.append(gain / b)
        passed += gain > q * b * t
        smooth_tau.append(
            correlation_along(result, SimpleNamespace(model_afc=r + smooth))
            / misfit_scale(result)[1]
        )
    assert np.mean(along) == pytest.approx(exact, rel=0.15)
    assert np.mean(gains) == pytest.approx(exact, rel=0.2)  # what the judge's units assume
    assert passed / 200 <= 0.03
    assert np.mean(smooth_tau) == pytest.approx(1.0, abs=0.1)
