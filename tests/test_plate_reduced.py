"""The reduced JAX model against the full sparse model; derivatives; refresh; conventions."""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from plate_helpers import PAPER_THETA, strip_model, strip_setup
from vibid.identify import build_forward_model


@pytest.fixture(scope="module")
def local():
    return strip_model("local", "fast", 60)


@pytest.fixture(scope="module")
def full_paper(local):
    return local.afc_full(PAPER_THETA)


def test_local_reduced_matches_full_model(local, full_paper):
    H = np.asarray(local.afc(PAPER_THETA))
    assert np.abs(H - full_paper).max() < 1e-6 * np.abs(full_paper).max()


def test_local_reduced_nearby(local):
    theta = PAPER_THETA * np.array([1.05, 1.04, 1.5])
    H, Hf = np.asarray(local.afc(theta)), local.afc_full(theta)
    assert np.abs(H - Hf).max() < 1e-5 * np.abs(Hf).max()


def test_wide_basis_covers_the_prior_box():
    model = strip_model("wide", "fast", 60)
    for theta in ([2.0, 0.05, 0.01], [80.0, 0.45, 0.001], PAPER_THETA):
        H, Hf = np.asarray(model.afc(np.array(theta))), model.afc_full(np.array(theta))
        assert np.abs(H - Hf).max() < 1e-5 * np.abs(Hf).max(), theta
    batch = np.asarray(model.afc_batch(np.array([PAPER_THETA, [2.0, 0.05, 0.01]])))
    np.testing.assert_allclose(batch[0], np.asarray(model.afc(PAPER_THETA)), rtol=1e-10)


def test_static_limit_and_phase_convention(local):
    """H → 1 as f → 0; past the first resonance the response lags (e^{+iωt}, β > 0)."""
    setup = strip_setup()
    f1 = local.natural_frequencies(PAPER_THETA, 1)[0][0]
    freqs = np.array([1e-3, 0.5, f1, 1.2 * f1])
    model = build_forward_model(
        setup, freqs, theta0=dict(zip(("D", "nu", "beta"), PAPER_THETA)), accuracy="fast"
    )
    H = np.asarray(model.afc(PAPER_THETA))
    assert abs(H[0] - 1) < 1e-9
    # quasi-static: 1 + ω² × (static deflection per unit acceleration) > 1, tiny phase
    assert 0 < H[1].real - 1 < 1e-3 and abs(np.angle(H[1])) < 1e-5
    assert np.angle(H[2]) == pytest.approx(-np.pi / 2, abs=0.05)  # -90° at resonance
    assert np.angle(H[3]) < -np.pi / 2  # lags by more past it


def test_gradient_matches_full_model_adjoint(local):
    """d Re/Im H / dθ of the reduced model against the full model's adjoint derivative."""
    theta = jnp.asarray(PAPER_THETA)
    J = jax.jacfwd(lambda t: local.afc(t))(theta)
    Jf = jax.jacfwd(lambda t: local.afc_full_jax(t))(theta)
    scale = np.abs(np.asarray(Jf)).max(axis=0)
    assert np.all(np.abs(np.asarray(J - Jf)).max(axis=0) < 1e-4 * scale)


def test_loss_gradient_and_hessian_against_finite_differences(local, full_paper):
    data = jnp.asarray(full_paper * (1 + 1e-3))

    def loss(t):
        return jnp.sum(jnp.abs(local.afc(t) - data) ** 2)

    theta = jnp.asarray(PAPER_THETA * np.array([1.01, 0.99, 1.1]))
    grad = jax.jit(jax.grad(loss))
    g = np.asarray(grad(theta))
    Hs = np.asarray(jax.jit(jax.hessian(loss))(theta))
    steps = np.array([1e-6, 1e-6, 1e-5]) * np.asarray(theta)
    for i in range(3):
        e = np.zeros(3)
        e[i] = steps[i]
        fd = (jax.jit(loss)(theta + e) - jax.jit(loss)(theta - e)) / (2 * steps[i])
        assert float(fd) == pytest.approx(g[i], rel=1e-4)
        gfd = (np.asarray(grad(theta + e)) - np.asarray(grad(theta - e))) / (2 * steps[i])
        np.testing.assert_allclose(Hs[:, i], gfd, rtol=1e-3, atol=1e-6 * np.abs(Hs).max())
    np.testing.assert_allclose(Hs, Hs.T, rtol=1e-8)


def test_parameterisations_agree():
    """The isotropic plate written as orthotropic/monoclinic moduli, and one loss written per
    modulus (the direct path), give the same AFC."""
    setup = strip_setup()
    freqs = np.linspace(10, 1500, 40)
    D, nu, beta = PAPER_THETA
    iso = build_forward_model(
        setup, freqs, theta0={"D": D, "nu": nu, "beta": beta}, accuracy="fast"
    )
    ortho_p = {"D11": D, "D12": nu * D, "D22": D, "D66": (1 - nu) * D / 2, "beta": beta}
    ortho = build_forward_model(setup, freqs, model="orthotropic", theta0=ortho_p, accuracy="fast")
    mono = build_forward_model(
        setup, freqs, model="monoclinic", theta0=dict(ortho_p, D16=0.0, D26=0.0), accuracy="fast"
    )
    pml = build_forward_model(
        setup,
        freqs,
        theta0={"D": D, "nu": nu, "beta11": beta, "beta12": beta, "beta66": beta},
        per_modulus_loss=True,
        accuracy="fast",
    )
    H = np.asarray(iso.afc(PAPER_THETA))
    scale = np.abs(H).max()
    for m, th in (
        (ortho, [D, nu * D, D, (1 - nu) * D / 2, beta]),
        (mono, [D, nu * D, D, (1 - nu) * D / 2, 0.0, 0.0, beta]),
        (pml, [D, nu, beta, beta, beta]),
    ):
        assert np.abs(np.asarray(m.afc(np.array(th))) - H).max() < 1e-6 * scale, m.parameter_names
    # unequal losses: direct path against the full model (the basis holds real modes, so
    # strongly non-proportional damping costs a little accuracy)
    th = np.array([D, nu, 0.002, 0.004, 0.006])
    assert np.abs(np.asarray(pml.afc(th)) - pml.afc_full(th)).max() < 1e-5 * scale


def test_refresh_keeps_or_rebuilds(local):
    assert local.refresh(PAPER_THETA) is local
    far = local.refresh(PAPER_THETA * np.array([1.6, 0.7, 1.0]))
    assert far is not local and far.kind == "local"
    np.testing.assert_allclose(far.theta0, PAPER_THETA * np.array([1.6, 0.7, 1.0]))


def test_a_model_rebuilt_at_its_own_coefficients_is_itself_unchecked(local, monkeypatch):
    """``refresh`` and ``rebuilt`` at the coefficients the basis was built at return the
    model without the full-model check (a rebuild would give the same basis); the loss
    factor moves no coefficient. ``rebuilt`` elsewhere is a local basis built there,
    unchecked, whose AFC matches the full model there."""
    monkeypatch.setattr(type(local), "check", lambda self, theta: pytest.fail("checked"))
    other_loss = PAPER_THETA * np.array([1.0, 1.0, 3.0])
    assert local.refresh(other_loss) is local and local.rebuilt(other_loss) is local
    th = PAPER_THETA * np.array([1.6, 0.7, 1.0])
    far = local.rebuilt(th)
    assert far is not local and far.kind == "local"
    np.testing.assert_allclose(far.theta0, th)
    H = np.asarray(far.afc(th))
    assert np.abs(H - far.afc_full(th)).max() < 1e-5 * np.abs(H).max()


def test_model_error_estimates_the_discretisation_error(local):
    """The estimate is small against the AFC and covers the difference to a fine model."""
    err = local.model_error(PAPER_THETA)
    H = np.asarray(local.afc(PAPER_THETA))
    assert err.shape == H.shape and np.all(err >= 0)
    assert err.max() < 1e-3 * np.abs(H).max()
    fine = strip_model("local", "default", 60)
    diff = np.abs(np.asarray(fine.afc(PAPER_THETA)) - H)
    # the actual error of "fast" (seen from "default") is within 3 sigma of the estimate
    assert np.all(diff <= 3 * np.sqrt(2) * err + 1e-9 * np.abs(H).max())


def test_the_same_model_built_twice_is_the_same_to_the_last_bit(local):
    """The reduced basis comes from ARPACK, which left to itself starts from a random
    vector: then two builds differed at rounding level and the identification of one
    session with one seed gave different answers from run to run."""
    again = strip_model("local", "fast", 60)
    assert np.array_equal(np.asarray(again.afc(PAPER_THETA)), np.asarray(local.afc(PAPER_THETA)))
    f, _ = local.natural_frequencies(PAPER_THETA, 3)
    f2, _ = again.natural_frequencies(PAPER_THETA, 3)
    assert np.array_equal(f, f2)


def test_largest_eigenvalue_of_a_pencil_whose_mass_rounding_left_indefinite():
    # K = diag(1, 4, 9), M = diag(1, 1, -1e-18): eigh needs a Cholesky factor of M and
    # fails; the pencil's eigenvalues are 1, 4 and -9e18, the largest |λ| 9e18
    from vibid.identify.model.reduced import largest_eigenvalue

    K, M = np.diag([1.0, 4.0, 9.0]), np.diag([1.0, 1.0, -1e-18])
    with pytest.raises(np.linalg.LinAlgError):
        import scipy.linalg as sla

        sla.eigh(K, M)
    assert largest_eigenvalue(K, M) == pytest.approx(9e18, rel=1e-12)
    assert largest_eigenvalue(K, np.diag([1.0, 2.0, 3.0])) == pytest.approx(3.0, rel=1e-12)


@pytest.mark.parametrize("material", ["isotropic", "orthotropic"])
def test_coefficient_derivatives_by_complex_step_equal_autodiff(material):
    """The basis's stiffness and inertia sensitivities (complex step) against jax.jacfwd, for
    a model with every effect of the library at once, at a point off every null."""
    from vibid.identify.effects import EFFECTS
    from vibid.identify.model.materials import Material
    from vibid.identify.model.reduced import _coefficient_jacobians
    from vibid.identify.model.terms import PlateModel

    model = PlateModel(Material(material, False), ())
    for term in EFFECTS.values():
        model = model.with_effect(term)
    model = model.for_geometry(SimpleNamespace(length_m=0.1))  # the free length's stretch
    rng = np.random.default_rng(3)
    theta = np.array(
        [
            {
                "nu": 0.3,
                "beta": 0.01,
                "sensor_dy_m": 2e-3,
                "G13_Pa": 4e10,
                "mass_kg": 3e-4,
                "tau_s": 2e-5,
                "k_theta_N_per_rad": 1.6e4,
                "dL_m": 2e-3,
                "height_m": 3e-3,
                "beta_clamp": 0.05,
                "f_hz_1": 660.0,
                "q_1": 30.0,
                "theta_rad_per_m_1": 0.3,
            }.get(n, 1.0)
            * rng.uniform(0.8, 1.2)
            * (18.0 if n.startswith("D") else 1.0)
            for n in model.names
        ]
    )
    Js, Jm = _coefficient_jacobians(model, theta)
    th = jnp.asarray(theta)
    np.testing.assert_allclose(
        Js,
        jax.jacfwd(lambda t: model.moduli(t, jnp))(th),
        rtol=1e-13,
        atol=1e-13 * np.abs(Js).max(),
    )
    np.testing.assert_allclose(
        Jm,
        jax.jacfwd(lambda t: model.inertia(t, jnp))(th),
        rtol=1e-13,
        atol=1e-13 * np.abs(Jm).max(),
    )
    assert np.count_nonzero(Jm) >= 3  # the added mass, the shear's and the moved sensor's
    # at the moved sensor's null (dy = 0) its cubic law's derivative is exactly 0, as
    # autodiff's: a rounding residue there would add a spurious column to the basis
    theta[model.names.index("sensor_dy_m")] = 0.0
    _, Jm = _coefficient_jacobians(model, theta)
    exact = np.asarray(jax.jacfwd(lambda t: model.inertia(t, jnp))(jnp.asarray(theta)))
    np.testing.assert_array_equal(Jm != 0, exact != 0)


def test_the_modes_below_the_cut_off_are_those_of_one_large_solve():
    """The basis's modes (few asked first, then as many as the count so far says a plate
    needs) against one shift-invert solve for 60: the same frequencies and shapes, up to
    the first mode above the cut-off, on a plate that needs 46."""
    import scipy.sparse.linalg as spla

    from plate_helpers import plate_setup
    from vibid.identify.model import reduced
    from vibid.identify.model.modal import arpack_start

    setup = plate_setup(0.15, 0.10, 0.002)
    model = build_forward_model(
        setup, np.linspace(50.0, 3200.0, 20), theta0={"D": 50.0, "nu": 0.3, "beta": 0.01}
    )
    s, m = reduced._coefficients(model.param, model.theta0)
    K = model.mats.stiffness_matrix(dict(zip(model.mats.stiffness, s))).tocsc()
    M = model.mats.inertia_matrix(dict(zip(model.mats.inertia, m))).tocsc()
    lu = reduced.spd_lu(K)
    Phi, f_hz = reduced._modes(K, M, lu, 6, 96, 9000.0)
    lam, Psi = spla.eigsh(K, k=60, M=M, sigma=0.0, which="LM", v0=arpack_start(K.shape[0]))
    order = np.argsort(lam)
    f_ref, Psi = np.sqrt(lam[order]) / (2 * np.pi), Psi[:, order]
    n = f_hz.size
    assert n == np.searchsorted(f_ref, 9000.0) + 1 == 46
    np.testing.assert_allclose(f_hz, f_ref[:n], rtol=1e-9)
    # the shapes span the same space (M-orthonormal): each reference shape is in it
    coeff = Phi.T @ (M @ Psi[:, : n - 1])
    np.testing.assert_allclose(np.sum(coeff**2, axis=0), 1.0, atol=1e-8)
