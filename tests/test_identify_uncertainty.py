"""Uncertainty: the Fisher covariance against an analytic case and against Monte Carlo."""

import numpy as np
import pytest

from ritz_toy import RitzPlateModel
from vibid.identify.fit.data import fit_data
from vibid.identify.fit.local import LOCAL_METHODS
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.space import ParameterSpace
from vibid.identify.fit.uncertainty import fisher_uncertainty
from vibid.setup_model import example_setup

TRUE = np.array([17.97, 0.286, 0.003])


def test_linear_regression_covariance_is_exact():
    """Straight line y = a + b x with noise s: cov = s^2 (X^T X)^-1 (textbook)."""
    x = np.linspace(0, 1, 11)
    s = 0.1
    X = np.stack([np.ones_like(x), x], 1)
    J = X / s  # weighted residual Jacobian
    unc = fisher_uncertainty(J, ("a", "b"), chi2_reduced=1.0, noise_known=True)
    np.testing.assert_allclose(unc.covariance, s**2 * np.linalg.inv(X.T @ X), rtol=1e-12)
    # unknown noise: scaled by the reduced chi-square
    unc2 = fisher_uncertainty(J, ("a", "b"), chi2_reduced=4.0, noise_known=False)
    np.testing.assert_allclose(unc2.std, 2 * unc.std, rtol=1e-12)
    # corr(a, b) = -mean(x) / sqrt(mean(x^2)) for a line fit
    assert unc.correlation[0, 1] == pytest.approx(-x.mean() / np.sqrt(np.mean(x**2)))


def test_insensitive_parameter_is_flagged_not_nan():
    J = np.array([[1.0, 0.0], [2.0, 0.0], [0.5, 0.0]])
    unc = fisher_uncertainty(J, ("a", "b"), chi2_reduced=1.0, noise_known=True)
    assert np.isinf(unc.std[1]) and np.isfinite(unc.std[0])
    assert any("does not depend on b" in w for w in unc.warnings)


def test_monte_carlo_scatter_matches_reported_std():
    """50 noisy replicates of the strip's AFC (0-1000 Hz, 1 % noise), each fitted from the
    truth with one compiled problem: the reported std agree with the scatter within 25 %."""
    setup = example_setup()
    f = np.linspace(0, 1000, 201)
    fm = RitzPlateModel(setup, f)
    H = np.asarray(fm.afc(TRUE))
    sd = 0.01 * np.abs(H).max()
    std = np.full(f.size, sd)
    space = ParameterSpace.from_bounds(fm.parameter_names, setup.identification.bounds)
    base = LeastSquaresProblem(fm, fit_data(f, H, std), space)
    rng = np.random.default_rng(7)
    u0 = space.to_u(TRUE)
    est, rep = [], []
    for _ in range(50):
        Hn = H + sd * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
        problem = base.with_data(Hn, std)
        r = LOCAL_METHODS["newton"](problem, u0)
        assert r.converged, r.message
        est.append(r.theta)
        chi2r = r.loss / problem.dof
        rep.append(
            fisher_uncertainty(
                problem.jacobian_theta(r.theta), space.names, chi2_reduced=chi2r, noise_known=True
            ).std
        )
    est, rep = np.array(est), np.array(rep)
    scatter = est.std(axis=0, ddof=1)
    reported = rep.mean(axis=0)
    np.testing.assert_allclose(reported, scatter, rtol=0.25)
    # and unbiased within the scatter of the mean
    assert np.all(np.abs(est.mean(axis=0) - TRUE) < 4 * scatter / np.sqrt(50))
