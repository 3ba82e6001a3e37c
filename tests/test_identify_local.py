"""Local methods: the trust-region subproblem, and the paper's local experiment.

Reference data: the independent Ritz plate of ``ritz_toy`` (and, for the paper's strip,
vibid's FE forward model); start from the paper's (+20 % D, +5 % nu, x100 beta).
"""

import numpy as np
import pytest

from ritz_toy import RitzPlateModel
from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify
from vibid.identify.fit.data import fit_data
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.result import Status
from vibid.identify.fit.space import ParameterSpace
from vibid.identify.fit.trust_region import gauss_newton, solve_subproblem, trust_region
from vibid.setup_model import example_setup

TRUE = np.array([17.97, 0.286, 0.003])
PAPER_START = TRUE * np.array([1.2, 1.05, 100.0])


@pytest.mark.parametrize("seed", range(6))
def test_subproblem_is_the_constrained_minimum(seed):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((3, 3))
    B = A + A.T  # indefinite in general
    g = rng.standard_normal(3)
    radius = 0.3 + rng.random()
    p, _ = solve_subproblem(g, B, radius)
    assert np.linalg.norm(p) <= radius * (1 + 1e-9)
    m = lambda q: g @ q + 0.5 * q @ B @ q  # noqa: E731
    # brute force over the ball (sphere surface + interior samples)
    q = rng.standard_normal((20000, 3))
    q *= (radius * rng.random((20000, 1)) ** (1 / 3)) / np.linalg.norm(q, axis=1, keepdims=True)
    sphere = q / np.linalg.norm(q, axis=1, keepdims=True) * radius
    best = min(
        np.min(np.einsum("ij,j->i", s, g) + 0.5 * np.einsum("ij,jk,ik->i", s, B, s))
        for s in (q, sphere)
    )
    assert m(p) <= best + 1e-9


def test_hard_case_subproblem():
    B = np.diag([-2.0, 1.0, 3.0])
    g = np.array([0.0, 1.0, 1.0])  # no component along the negative eigenvector
    p, on_boundary = solve_subproblem(g, B, 1.0)
    assert on_boundary and np.linalg.norm(p) == pytest.approx(1.0)
    assert abs(p[0]) > 0.5


@pytest.fixture(scope="module")
def toy_problem():
    setup = example_setup()
    f = np.linspace(0, 600, 201)
    fm = RitzPlateModel(setup, f)
    H = np.asarray(fm.afc(TRUE))
    space = ParameterSpace.from_bounds(fm.parameter_names, setup.identification.bounds)
    return LeastSquaresProblem(fm, fit_data(f, H), space), setup, f, H, fm


@pytest.mark.parametrize("method", ["exact", "bfgs", "lm"])
def test_paper_start_recovers_all_three(toy_problem, method):
    problem = toy_problem[0]
    u0 = problem.space.to_u(PAPER_START)
    r = (
        gauss_newton(problem, u0)
        if method == "lm"
        else trust_region(problem, u0, hessian=method, max_iter=1000)
    )
    assert r.status is Status.CONVERGED, r.message
    np.testing.assert_allclose(r.theta, TRUE, rtol=1e-6)
    losses = [h.loss for h in r.history]
    if method != "lm":  # trust region: the iterate's loss never increases
        assert all(b <= a for a, b in zip(losses, losses[1:]))
        assert r.history[-1].radius > 0


def test_a_decrement_tolerance_stops_early_within_it_of_the_minimum(toy_problem):
    """``decrement_tol`` (a loop's start, polished later): the run stops once the Newton
    decrement is below it, and its chi2 then lies within about that of the minimum's (the
    noisy toy AFC: chi2 ~ its 400 residuals)."""
    _, setup, f, H, fm = toy_problem
    rng = np.random.default_rng(5)
    std = np.full(f.size, 0.02 * np.abs(H).max())
    noisy = H + std * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    space = ParameterSpace.from_bounds(fm.parameter_names, setup.identification.bounds)
    problem = LeastSquaresProblem(fm, fit_data(f, noisy, std), space)
    u0 = space.to_u(PAPER_START)
    strict = trust_region(problem, u0, max_iter=1000)
    early = trust_region(problem, u0, max_iter=1000, decrement_tol=1.0)
    assert strict.converged and early.converged
    assert early.n_iterations < strict.n_iterations
    assert 0.0 <= early.loss - strict.loss <= 2.0
    assert 300 < strict.loss < 500


def test_non_convergence_is_reported(toy_problem):
    problem = toy_problem[0]
    r = trust_region(problem, problem.space.to_u(PAPER_START), max_iter=3)
    assert r.status is Status.MAX_ITERATIONS and not r.converged
    assert "did not converge" in r.message


def test_identify_local_from_paper_start(toy_problem):
    _, setup, f, H, fm = toy_problem
    res = identify(
        setup,
        Measurement(f, H),
        ModelChoice(forward_model=fm),
        SearchOptions(method="local", start=dict(zip(("D", "nu", "beta"), PAPER_START))),
    )
    assert res.converged
    np.testing.assert_allclose(res.values, TRUE, rtol=1e-6)
    assert np.all(np.isfinite(res.std))
    assert res.rel_rms_residual < 1e-8


@pytest.fixture(scope="module")
def fe_strip_600():
    from vibid.identify import build_forward_model

    setup = example_setup()
    f = np.linspace(0, 600, 201)
    return setup, f, build_forward_model(setup, f)


@pytest.mark.slow
def test_paper_start_on_the_fe_strip(fe_strip_600):
    """The paper's section 6.2 experiment on vibid's own plate model (data from the full
    FE model, fit with the reduced one)."""
    setup, f, fm = fe_strip_600
    H = np.asarray(fm.afc_full(TRUE))
    res = identify(
        setup,
        Measurement(f, H),
        ModelChoice(forward_model=fm),
        SearchOptions(
            method="local", start=dict(zip(("D", "nu", "beta"), PAPER_START)), refresh=False
        ),
    )
    assert res.converged, res.message
    np.testing.assert_allclose(res.values, TRUE, rtol=1e-6)


def test_one_peak_band_converges_along_the_curved_valley():
    """0-200 Hz holds one resonance: D and nu lie along a long, bending valley of chi2
    (~1e8 times stiffer across than along it). Data from a slightly different model (3
    instead of 4 beam functions across the width), so the minimum is small but not zero.
    The straight trust-region steps of Algorithm 4.1 crawled along it with a radius of
    ~1e-4 and hit the iteration limit; with the second-order correction the run must
    reach the minimum that an independent method (MINPACK's LM from the truth) finds,
    and say it converged."""
    from scipy.optimize import least_squares

    setup = example_setup()
    f = np.linspace(0, 200, 201)
    fm = RitzPlateModel(setup, f)
    H = np.asarray(RitzPlateModel(setup, f, n_y=3).afc(TRUE))
    space = ParameterSpace.from_bounds(fm.parameter_names, setup.identification.bounds)
    problem = LeastSquaresProblem(fm, fit_data(f, H), space)
    ref = least_squares(
        problem.residuals,
        space.to_u(TRUE),
        jac=problem.jacobian,
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    theta_ref, chi2_ref = space.theta(ref.x), 2 * ref.cost
    assert 0 < chi2_ref < 1e-10  # tiny, not zero
    r = trust_region(problem, space.to_u(TRUE * np.array([1.1, 1.3, 1.0])), max_iter=100)
    assert r.status is Status.CONVERGED, r.message
    assert r.n_iterations <= 100
    np.testing.assert_allclose(r.theta, theta_ref, rtol=1e-5)
    assert r.loss <= chi2_ref * (1 + 1e-6)
    losses = [h.loss for h in r.history]
    assert all(b <= a for a, b in zip(losses, losses[1:]))
