"""The model's own error split into a parameter bias and an unexplained remainder, and
Richardson's extrapolation of the discretisation error over three meshes
(vibid.identify.model.model_error), against constructions whose answer is known exactly."""

import math

import numpy as np
import pytest

from vibid.identify.model.model_error import (
    MIN_ORDER,
    convergence_order,
    richardson,
    split_model_error,
)


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


def _levels(h, p, rng, n=30):
    """AFCs H(h) = H_inf + C h^p on the cell sizes ``h`` (C complex per point)."""
    H_inf = rng.standard_normal(n) + 1j * rng.standard_normal(n) + 3.0
    C = 1e-3 * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    return H_inf, [H_inf + C * x**p for x in h]


@pytest.mark.parametrize("p", [2.0, 4.0, 6.0])
def test_an_exact_power_law_is_extrapolated_to_its_limit(p):
    """Cells 3/2 and 2/3 of the model's (the forward model's family): the order and the
    error H_inf - H come back to round-off, whatever the error's shape along frequency."""
    rng = np.random.default_rng(int(p))
    H_inf, (Hc, H, Hf) = _levels([1.5, 1.0, 2 / 3], p, rng)
    ext = richardson(Hc, H, Hf, 2 / 3, 1.5)
    assert ext.order == pytest.approx(p, rel=1e-8) and not ext.limited
    assert ext.ratio == pytest.approx(1.5**-p, rel=1e-10)
    np.testing.assert_allclose(ext.factor * (Hf - H), H_inf - H, rtol=1e-8, atol=1e-14)
    # the finer step alone misses the finer mesh's own error, (2/3)^p of the model's
    assert np.linalg.norm(Hf - H - (H_inf - H)) == pytest.approx(
        (2 / 3) ** p * np.linalg.norm(H_inf - H), rel=1e-8
    )


def test_unequal_steps_solve_the_order():
    """Cells 1.4 and 0.6 times the model's (a plate whose counts do not divide by 3)."""
    rng = np.random.default_rng(3)
    H_inf, (Hc, H, Hf) = _levels([1.4, 1.0, 0.6], 5.0, rng)
    ext = richardson(Hc, H, Hf, 0.6, 1.4)
    assert ext.order == pytest.approx(5.0, rel=1e-8)
    np.testing.assert_allclose(ext.factor * (Hf - H), H_inf - H, rtol=1e-8, atol=1e-14)
    # for equal steps the equation is ratio = s^p
    assert convergence_order(1.5**-3.5, 2 / 3, 1.5) == pytest.approx(3.5, rel=1e-9)


def test_no_convergence_is_bounded_by_the_slowest_order_trusted():
    """A finer step as large as the coarser one (no convergence), or no coarser mesh: the
    error is (H_f - H) / (1 - s_f^MIN_ORDER), not the finer step alone; a finer step that
    moves nothing has nothing to extrapolate."""
    rng = np.random.default_rng(4)
    H = rng.standard_normal(20) + 2.0 + 0j
    step = 1e-3 * rng.standard_normal(20)
    for ext in (
        richardson(H - step, H, H + step, 2 / 3, 1.5),
        richardson(None, H, H + step, 2 / 3, 1.0),
    ):
        assert ext.limited and ext.order == MIN_ORDER
        assert ext.factor == pytest.approx(1 / (1 - (2 / 3) ** MIN_ORDER))
    ext = richardson(H - step, H, H, 2 / 3, 1.5)
    assert ext.factor == 1.0 and math.isinf(ext.order) and not ext.limited
