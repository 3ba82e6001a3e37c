"""The model's own error split into a parameter bias and an unexplained remainder
(vibid.identify.model.model_error), against constructions whose answer is known exactly."""

import numpy as np
import pytest

from vibid.identify.model.model_error import split_model_error


def _setup(rng, n=40, p=3):
    sigma = rng.uniform(0.5, 2.0, n)
    J = rng.standard_normal((2 * n, p)) * np.array([1.0, 30.0, 0.01])  # badly scaled columns
    return n, p, sigma, J


def test_an_error_the_parameters_reproduce_is_all_bias():
    rng = np.random.default_rng(0)
    n, p, sigma, J = _setup(rng)
    bias = np.array([0.3, -0.002, 40.0])
    delta = J @ bias  # in residual units
    d = (delta[:n] + 1j * delta[n:]) * sigma
    split = split_model_error(J, d, 0.0, sigma)
    assert split.bias == pytest.approx(bias, rel=1e-10)
    assert np.max(split.point_std) < 1e-9 * np.max(np.abs(d))
    assert split.covariance == pytest.approx(np.outer(bias, bias), rel=1e-10)


def test_an_error_orthogonal_to_the_jacobian_stays_in_the_weights():
    rng = np.random.default_rng(1)
    n, p, sigma, J = _setup(rng)
    q = rng.standard_normal(2 * n)
    Q, _ = np.linalg.qr(J)
    q -= Q @ (Q.T @ q)  # no parameter change explains q
    bias = np.array([-1.0, 0.01, 5.0])
    delta = J @ bias + q
    d = (delta[:n] + 1j * delta[n:]) * sigma
    reduction = rng.uniform(0, 0.1, n)
    split = split_model_error(J, d, reduction, sigma)
    assert split.bias == pytest.approx(bias, rel=1e-9)
    # per point: the remainder's RMS over its real and imaginary parts, in data units,
    # and the reduction error in quadrature
    rest = np.sqrt((q[:n] ** 2 + q[n:] ** 2) / 2) * sigma
    assert split.point_std == pytest.approx(np.sqrt(rest**2 + reduction**2), rel=1e-9)


def test_no_error_gives_no_bias_and_non_finite_rows_are_ignored():
    rng = np.random.default_rng(2)
    n, p, sigma, J = _setup(rng)
    split = split_model_error(J, np.zeros(n, complex), 0.01, sigma)
    assert np.all(split.bias == 0) and split.point_std == pytest.approx(np.full(n, 0.01))
    bias = np.array([0.1, 0.2, 0.3])
    delta = J @ bias
    d = (delta[:n] + 1j * delta[n:]) * sigma
    J_bad = J.copy()
    J_bad[3] = np.nan
    split = split_model_error(J_bad, d, 0.0, sigma)
    assert split.bias == pytest.approx(bias, rel=1e-9) and np.all(np.isfinite(split.point_std))
