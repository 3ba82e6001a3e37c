"""Assembled matrices: symmetry, positivity, rigid-body mass, the sensor disc's area."""

import math

import numpy as np
import pytest
import scipy.sparse.linalg as spla
from skfem import Basis, MeshTri

from plate_helpers import strip_setup
from vibid.identify.model.assembly import Geometry, assemble_plate
from vibid.identify.model.disc import assemble_disc, disc_quadrature
from vibid.identify.model.elements import ElementTriArgyrisLocal
from vibid.identify.model.forms import MODULI, bending_66, translational_inertia
from vibid.identify.model.mesh import Discretisation, plate_mesh

GEOM = Geometry.from_setup(strip_setup())
DISC = Discretisation("argyris", 20, 4, 2)


@pytest.fixture(scope="module")
def mats():
    return assemble_plate(GEOM, DISC)


def test_matrices_symmetric(mats):
    for name in MODULI:
        K = mats.stiffness[name]
        assert abs(K - K.T).max() <= 1e-12 * abs(K).max(), name
    for name, M in mats.inertia.items():
        assert abs(M - M.T).max() <= 1e-12 * abs(M).max(), name


def test_stiffness_and_mass_positive_definite(mats):
    # isotropic moduli with nu = 0.3: the clamped plate has no zero-energy mode
    D = dict(zip(MODULI, (1.0, 0.3, 0.0, 1.0, 0.0, 0.35)))
    K = mats.stiffness_matrix(D)
    M = mats.inertia_matrix()
    lam = spla.eigsh(K, k=3, M=M, sigma=0.0, return_eigenvectors=False)
    assert lam.min() > 0
    lam_m = spla.eigsh(M, k=1, which="LA", return_eigenvectors=False)
    assert lam_m[0] > 0


@pytest.mark.parametrize(
    "name, field, energy",
    [
        # w = x^2: kappa = (2, 0, 0) -> only D11, energy 4 L W
        ("D11", lambda x: x[0] ** 2, lambda L, W: 4 * L * W),
        # w = x^2 y: kappa = (2y, 0, 4x): D16 form 2 * (2y)(2x) * 2 = 16 x y
        ("D16", lambda x: x[0] ** 2 * x[1], lambda L, W: 16 * (L**2 / 2) * (W**2 / 2)),
        # w = x^2 y: (2 w_xy)^2 = 16 x^2
        ("D66", lambda x: x[0] ** 2 * x[1], lambda L, W: 16 * L**3 / 3 * W),
        # w = x^2 y^2: w_xx w_yy = 4 y^2 x^2, D12 form 2 w_xx w_yy = 8 x^2 y^2
        ("D12", lambda x: x[0] ** 2 * x[1] ** 2, lambda L, W: 8 * L**3 / 3 * W**3 / 3),
        ("D22", lambda x: x[0] ** 2 * x[1] ** 2, lambda L, W: 4 * L**5 / 5 * W),
    ],
)
def test_moment_convention_energies(mats, name, field, energy):
    """κ(w)ᵀ K_α κ(w) for clamped polynomial fields against their integrals by hand."""
    from vibid.identify.model.assembly import plate_basis

    basis = plate_basis(GEOM, DISC)
    w = basis.project(field)[mats.free]
    L, W = GEOM.length_m, GEOM.width_m
    assert w @ (mats.stiffness[name] @ w) == pytest.approx(energy(L, W), rel=1e-7)


def test_rigid_translation_carries_plate_and_sensor_mass(mats):
    g = GEOM
    plate = g.density_kg_m3 * g.thickness_m * g.length_m * g.width_m
    assert mats.rigid_mass_kg["plate"] == pytest.approx(plate, rel=1e-12)
    assert mats.rigid_mass_kg["sensor"] == pytest.approx(g.sensor_mass_kg, rel=1e-10)
    assert mats.probe_rigid == pytest.approx(1.0, abs=1e-10)


@pytest.mark.parametrize(
    "disc",
    [
        Discretisation("argyris", 7, 3, 0),
        Discretisation("argyris", 30, 6, 4),
        Discretisation("morley", 57, 11, 0),
        Discretisation("argyris", 40, 8, 0),
    ],
)
@pytest.mark.parametrize("centre", [(0.09, 0.015), (0.0913, 0.0147), (0.001, 0.001)])
def test_disc_area_exact_on_any_mesh(disc, centre):
    mesh = plate_mesh(0.1, 0.02, disc)
    r = 0.001
    cells, P, W = disc_quadrature(mesh, np.array(centre), r)
    assert W.sum() == pytest.approx(math.pi * r**2, rel=1e-9)
    # the first moments put the disc's centroid at its centre
    assert (W * P[0]).sum() / W.sum() == pytest.approx(centre[0], abs=1e-12)
    assert (W * P[1]).sum() / W.sum() == pytest.approx(centre[1], abs=1e-12)
    # second moment about the centre: pi r^4 / 2
    r2 = ((P[0] - centre[0]) ** 2 + (P[1] - centre[1]) ** 2) * W
    assert r2.sum() == pytest.approx(math.pi * r**4 / 2, rel=1e-9)


def test_disc_integrates_a_quadratic_exactly():
    # ∫_disc x^2 = pi r^2 (xc^2 + r^2/4), through the element's basis (Argyris reproduces x^2)
    mesh = plate_mesh(0.1, 0.02, Discretisation("argyris", 12, 3, 1))
    basis = Basis(mesh, ElementTriArgyrisLocal(), intorder=10)
    xc, yc, r = 0.0913, 0.0147, 0.002
    mass, grad, area = assemble_disc(basis, (xc, yc), r)
    x2 = basis.project(lambda x: x[0] ** 2)
    one = basis.project(lambda x: 1.0 + 0.0 * x[0])
    assert one @ (mass @ x2) == pytest.approx(math.pi * r**2 * (xc**2 + r**2 / 4), rel=1e-9)
    # ∫_disc ∇(x^2)·∇(x^2) = ∫ 4 x^2
    assert x2 @ (grad @ x2) == pytest.approx(4 * math.pi * r**2 * (xc**2 + r**2 / 4), rel=1e-9)


def test_local_argyris_spans_scikit_fems_argyris():
    from skfem import ElementTriArgyris

    mesh = MeshTri.init_tensor(np.linspace(0, 0.1, 9), np.linspace(0, 0.02, 3))
    mats = []
    for elem in (ElementTriArgyris(), ElementTriArgyrisLocal()):
        b = Basis(mesh, elem, intorder=10)
        mats.append((bending_66.assemble(b), translational_inertia.assemble(b)))
    for a, b in zip(*mats):
        assert abs(a - b).max() <= 1e-7 * abs(a).max()


def test_mass_matrix_is_mesh_independent_for_sensor():
    # the sensor's rigid-body mass is m on a coarse, a fine and a corner-refined mesh
    for disc in (Discretisation("argyris", 10, 2, 0), Discretisation("argyris", 30, 6, 3)):
        m = assemble_plate(GEOM, disc)
        assert m.rigid_mass_kg["sensor"] == pytest.approx(GEOM.sensor_mass_kg, rel=1e-10)
        assert m.sensor_area_m2 == pytest.approx(math.pi * GEOM.sensor_radius_m**2, rel=1e-10)


@pytest.mark.parametrize("centre", [(0.09, 0.015), (0.0913, 0.0147), (0.001, 0.001)])
def test_disc_matrices_positive_semidefinite(centre):
    """``∫_disc φ_i φ_j`` is a Gram matrix: no negative eigenvalue, whatever the centre
    (on a vertex, inside a cell, tangent to the plate's edges)."""
    mesh = plate_mesh(0.1, 0.02, Discretisation("argyris", 40, 8, 0))
    basis = Basis(mesh, ElementTriArgyrisLocal(), intorder=10)
    mass, grad, _ = assemble_disc(basis, centre, 0.001)
    for A in (mass, grad):
        idx = np.unique(A.nonzero()[0])
        dense = A[idx][:, idx].toarray()
        scale = np.abs(np.diag(dense)).max()
        # the matrix is a Gram matrix of ~60 functions: round-off only below zero
        assert np.linalg.eigvalsh(dense).min() >= -1e-9 * scale


def test_edge_rotation_matrix_integrates_the_slope_along_the_clamp():
    """Hook for a rotational spring along x = 0: ∫ w,x v,x dy; for w = x + x y it is
    ∫_0^W (1 + y)^2 dy."""
    from vibid.identify.model.assembly import edge_rotation_matrix, plate_basis

    K = edge_rotation_matrix(GEOM, DISC)
    w = plate_basis(GEOM, DISC).project(lambda x: x[0] + x[0] * x[1])
    W = GEOM.width_m
    assert w @ (K @ w) == pytest.approx(((1 + W) ** 3 - 1) / 3, rel=1e-8)


def test_shared_pattern_sums_match_scipys_term_by_term():
    """Matrices of different patterns, stored on their union, combine with real and complex
    coefficients into the same matrix scipy's term-by-term sum gives."""
    import scipy.sparse as sp

    from vibid.identify.model.assembly import SharedPattern

    rng = np.random.default_rng(3)
    mats = {
        ("K", f"k{i}"): sp.random(40, 40, density=0.1, random_state=i, format="csr")
        for i in range(3)
    } | {("M", "m"): sp.identity(40, format="csr")}
    pattern = SharedPattern.of(mats)
    c = {"k0": 2.0 + 0.5j, "k1": -1.5, "k2": 0.25j}
    m = {"m": -((2 * math.pi * 30.0) ** 2)}
    got = pattern.matrix(pattern.data("K", c) + pattern.data("M", m))
    want = sum(v * mats["K", k] for k, v in c.items()) + m["m"] * mats["M", "m"]
    assert got.format == "csc" and got.shape == (40, 40)
    assert abs(got - want).max() <= 1e-14 * abs(want).max()
    assert abs(pattern.matrix(pattern.data("M", {"m": 1.0})) - mats["M", "m"]).max() == 0.0
    assert (
        abs(pattern.matrix(pattern.data("K", {"k1": 3.0})) - 3.0 * mats["K", "k1"]).max() <= 1e-15
    )
    x = rng.standard_normal(40)
    assert np.allclose(got @ x, want @ x, rtol=1e-13, atol=1e-13)
