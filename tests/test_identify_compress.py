"""A long AFC fitted on its compressed problem (vibid.identify.fit.compress): the Gauss
quadrature's identities, and the real titanium strip's 11 960 FFT bins fitted on a few
hundred nodes to the same minimum as on every bin, within 0.1 of each parameter's std."""

import gzip
from pathlib import Path

import numpy as np
import pytest

from vibid.identify.fit.compress import TOL_STD, compressed, gauss_nodes, lagrange_matrix, project

DATA = Path(__file__).parent / "data"


def test_gauss_nodes_make_the_lagrange_polynomials_orthogonal():
    rng = np.random.default_rng(3)
    f = np.sort(rng.uniform(180.0, 260.0, 400))
    w = rng.uniform(0.2, 5.0, f.size) * 1e6
    for q in (4, 12, 16):
        nodes, W = gauss_nodes(f, w, q)
        L = lagrange_matrix(nodes, f)
        assert f.min() < nodes.min() and nodes.max() < f.max()
        assert np.allclose(L.T @ (w[:, None] * L), np.diag(W), rtol=0, atol=1e-12 * W.max())
        # a quadrature exact to degree 2q - 1: the moments of the measure
        t = (f - 200.0) / 60.0
        tn = (nodes - 200.0) / 60.0
        assert np.allclose(
            [W @ tn**k for k in range(2 * q)],
            [w @ t**k for k in range(2 * q)],
            rtol=1e-10,
            atol=1e-6,
        )


def test_the_projection_keeps_chi2_of_every_interpolant():
    rng = np.random.default_rng(4)
    f = np.linspace(500.0, 520.0, 300)
    w = rng.uniform(0.5, 2.0, f.size)
    d = rng.normal(size=f.size) + 1j * rng.normal(size=f.size)
    nodes, W = gauss_nodes(f, w, 12)
    c, kappa = project(f, w, d, nodes, W)
    L = lagrange_matrix(nodes, f)
    for _ in range(3):
        h = rng.normal(size=12) + 1j * rng.normal(size=12)
        full = w @ np.abs(L @ h - d) ** 2
        assert W @ np.abs(h - c) ** 2 + kappa == pytest.approx(full, rel=1e-11)
    assert kappa >= 0


def titanium_problem(magnitude: bool = False):
    """The real titanium AFC (shared/data/real-titanium, all 11 960 bins) and the declared
    isotropic problem on it (on |H| alone with ``magnitude``), with the declared fit's start
    (also benchmarks/compress.py's)."""
    from vibid.cli.modes import load_setup
    from vibid.identify.fit.data import fit_data
    from vibid.identify.fit.problem import LeastSquaresProblem
    from vibid.identify.fit.space import ParameterSpace
    from vibid.identify.model.plate import build_forward_model, plate_model

    with gzip.open(DATA / "titanium_afc.csv.gz", "rt") as fh:
        f, re, im, std = np.loadtxt(fh, delimiter=",", skiprows=1, unpack=True)
    setup = load_setup(DATA / "titanium_setup.json")
    model = plate_model("isotropic")
    start = {"D": 300.0, "nu": -0.65, "beta": 0.0195}
    box = model.default_bounds(dict(setup.identification.bounds))
    space = ParameterSpace.from_bounds(model.names, box, {q.name: q.kind for q in model.parameters})
    fm = build_forward_model(setup, f, model=model, theta0=start)
    problem = LeastSquaresProblem(fm, fit_data(f, re + 1j * im, std, magnitude=magnitude), space)
    return problem, space.to_u(np.array([start[n] for n in model.names]))


@pytest.fixture(scope="module", params=[False, True], ids=["complex", "magnitude"])
def titanium(request):
    return titanium_problem(magnitude=request.param)


@pytest.mark.slow
def test_the_titanium_strip_fitted_on_its_compressed_problem(titanium):
    """The complex AFC, and |H| alone (whose bands interpolate |H|)."""
    from vibid.identify.fit.local import _METHODS, LOCAL_METHODS

    problem, u0 = titanium
    short = compressed(problem, u0)
    assert short.n_points < problem.n_points / 10  # a few hundred nodes for 11 960 bins
    # chi2 there equals the full one to within what the bound allows (2 TOL |r| + TOL²)
    full = problem.chi2(u0)
    assert abs(short.chi2(u0) - full) < 2 * TOL_STD * np.sqrt(full) + TOL_STD**2
    every_bin = _METHODS["newton"](problem, u0)
    on_nodes = LOCAL_METHODS["newton"](problem, u0)
    assert every_bin.converged and on_nodes.converged
    J = problem.jacobian_theta(every_bin.theta)
    std = np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    shift = (on_nodes.theta - every_bin.theta) / std
    assert np.all(np.abs(shift) < 0.1), shift
    assert on_nodes.loss == pytest.approx(problem.chi2(on_nodes.u), rel=1e-12)
    assert on_nodes.loss == pytest.approx(every_bin.loss, rel=1e-6)


def test_no_bands_where_the_model_is_not_finite(monkeypatch):
    """A start where the model has no value (an orthotropic start whose stiffness matrix is
    not positive definite: the titanium strip's anisotropy refit) keeps the whole problem,
    where the bands' Fisher matrix used to stop the refit with 'Eigenvalues did not
    converge'."""
    from vibid.identify.fit.problem import LeastSquaresProblem

    problem, u0 = titanium_problem()
    real = LeastSquaresProblem.jacobian_and_residuals_theta

    def with_nan(self, theta):
        J, r = real(self, theta)
        return J, np.where(np.arange(r.size) == 7, np.nan, r)

    assert compressed(problem, u0) is not problem
    monkeypatch.setattr(LeastSquaresProblem, "jacobian_and_residuals_theta", with_nan)
    assert compressed(problem, u0) is problem


@pytest.mark.slow
def test_a_neighbouring_start_run_on_the_last_runs_nodes_reaches_the_same_minimum(monkeypatch):
    """A refit's starts share their compression (vibid.identify.fit.local.run_local): the
    second start, run on the first run's nodes without building its own, still ends on the
    full data's minimum within 0.1 std (its end point is confirmed on every bin)."""
    from vibid.identify.fit import local
    from vibid.identify.fit.local import _METHODS, run_local

    problem, u0 = titanium_problem()
    first, near = run_local("newton", problem, u0)
    assert near is not None and near.on(problem) is near.short
    assert near.on(problem.with_sigma(problem.sigma * 2)) is None  # other weights: own nodes
    built = []
    monkeypatch.setattr(local, "compressed", lambda *a: built.append(1) or compressed(*a))
    u1 = u0 + np.where(np.arange(u0.size) == 1, 0.3, 0.0)  # nu moved
    second, _ = run_local("newton", problem, u1, near)
    every_bin = _METHODS["newton"](problem, u1)
    assert first.converged and second.converged and every_bin.converged
    J = problem.jacobian_theta(every_bin.theta)
    std = np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    assert np.all(np.abs((second.theta - every_bin.theta) / std) < 0.1)
    assert second.loss == pytest.approx(every_bin.loss, rel=1e-6)
    assert built == []  # the first run's nodes served: no compression built for it
