"""The one 'fits the noise' test (identify/fit/noise.py) against analytic quantiles and Monte
Carlo: chi2 quantile, Ljung-Box and runs tests of the residual's whiteness."""

import math

import numpy as np
import pytest

from vibid.identify.fit.noise import chi2_limit, fits, fits_noise, ljung_box_p, runs_test_p


def test_chi2_limit_is_the_analytic_quantile():
    # chi-square with 2 dof is exponential with mean 2: P(X > x) = exp(-x / 2)
    assert chi2_limit(2, 0.999) == pytest.approx(-2 * math.log(1e-3), rel=1e-12)
    assert fits_noise(13.8, 2, True) is True and fits_noise(13.9, 2, True) is False
    assert fits_noise(1e9, 2, False) is None
    assert fits_noise(math.inf, 400, True) is False


def test_without_noise_the_strategy_judges_the_relative_residual():
    # unknown noise: every weight is RMS |H|, so chi2 over the real numbers fitted (2 per
    # point, 1 for |H| alone) is the relative mean square
    assert fits(2 * 100 * 0.009**2, 197, 200, noise_known=False)
    assert not fits(2 * 100 * 0.011**2, 197, 200, noise_known=False)
    assert fits(100 * 0.009**2, 97, 100, noise_known=False)
    assert not fits(100 * 0.011**2, 97, 100, noise_known=False)


def test_white_residuals_pass_at_the_nominal_rate():
    rng = np.random.default_rng(1)
    p_lb = np.array([ljung_box_p(rng.standard_normal(400)) for _ in range(400)])
    p_runs = np.array([runs_test_p(rng.standard_normal(400)) for _ in range(400)])
    # p-values of a correct test are uniform: 5 % below 0.05 (binomial sd 1.1 %)
    assert 0.02 < np.mean(p_lb < 0.05) < 0.09
    assert 0.02 < np.mean(p_runs < 0.05) < 0.09


def test_a_structured_residual_is_caught_though_chi2_fits():
    rng = np.random.default_rng(2)
    f = np.linspace(0, 1, 400)
    r = rng.standard_normal(400) * 0.9 + 0.45 * np.sin(2 * np.pi * 3 * f)
    assert fits_noise(float(r @ r), 397, True)  # chi2 alone sees nothing
    assert ljung_box_p(r) < 1e-6
    # the runs test only sees signs: weaker here, but it catches a drift that dominates
    assert runs_test_p(0.3 * rng.standard_normal(400) + np.sin(2 * np.pi * 3 * f)) < 1e-6


def test_runs_test_counts_runs_exactly():
    # 20 alternating signs: 20 runs against 11 expected, variance 10 * 9 / 19
    p = runs_test_p(np.array([1.0, -1.0] * 10))
    z = (20 - 11) / math.sqrt(90 / 19)
    assert p == pytest.approx(math.erfc(z / math.sqrt(2)), rel=1e-12)
