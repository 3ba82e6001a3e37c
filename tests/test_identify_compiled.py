"""Compiled code shared across models: one structure per material, one compilation per shape.

The closed loop tries one extended model per candidate; compiled per model, most of its
minutes were compilation. These tests pin the sharing itself (counted with JAX's own
compilation events, not timed) and the pieces that make it exact.
"""

import numpy as np
import pytest

from vibid.identify.engine.profile import recording
from vibid.identify.fit.data import fit_data
from vibid.identify.fit.problem import LeastSquaresProblem, padded_count
from vibid.identify.fit.space import ParameterSpace, from_u_coefficients
from vibid.identify.model.plate import build_forward_model
from vibid.identify.model.structure import embed, embedding, structure_of
from vibid.setup_model import example_setup

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
FREQS = np.linspace(7.5, 1500.0, 120)


def _problem(effects=(), extra=None):
    setup = example_setup()
    values = TRUTH | (extra or {})
    fm = build_forward_model(setup, FREQS, effects=effects, theta0=values)
    box = fm.param.default_bounds(dict(setup.identification.bounds))
    space = ParameterSpace.from_bounds(
        fm.parameter_names, box, {q.name: q.kind for q in fm.param.parameters}
    )
    theta = np.array([values[n] for n in fm.parameter_names])
    H = np.asarray(fm.afc(theta))
    rng = np.random.default_rng(0)
    noisy = H + 1e-3 * (rng.standard_normal(H.size) + 1j * rng.standard_normal(H.size))
    problem = LeastSquaresProblem(fm, fit_data(FREQS, noisy, np.full(FREQS.size, 1e-3)), space)
    return problem, theta


def _exercise(problem, theta):
    u = problem.space.to_u(theta)
    problem.jacobian_theta(theta)
    problem.value_and_grad(u)
    problem.hessian(u)
    problem.chi2_batch(np.stack([u, u]))


def test_candidates_of_one_size_compile_nothing_new():
    declared, theta = _problem()
    _exercise(declared, theta)  # compiles (or loads) the structure's functions
    for effects, extra in (
        (("channel_delay",), {"tau_s": 0.0}),
        (("added_mass",), {"mass_kg": 1e-4}),
        (("frequency_dependent_loss",), {"alpha": 0.0}),
    ):
        candidate, th = _problem(effects, extra)
        assert candidate.model.kernel == declared.model.kernel  # one structure
        assert candidate.model.arrays["K"].shape == declared.model.arrays["K"].shape
        with recording() as prof:
            _exercise(candidate, th)
        assert prof.compilations == 0, effects


@pytest.mark.parametrize(
    "effects, extra",
    [
        ((), {}),
        (("clamp_compliance",), {"k_theta_N_per_rad": 2e4}),
        (("sensor_position",), {"sensor_dy_m": 2e-3}),
    ],
)
def test_structure_code_equals_the_models_own(effects, extra):
    """A model run through its structure's code (every other effect of the library present,
    zeroed) gives the AFC of the model's own code, to rounding."""
    import jax

    from vibid.identify.model.reduced import ReducedKernel, padded_arrays

    problem, theta = _problem(effects, extra)
    fm = problem.model
    assert fm.kernel.model != fm.param  # the structure has more terms
    own = ReducedKernel(fm.param)(
        padded_arrays(fm.basis, 2 * np.pi * FREQS, fm.param, fm.param), jax.numpy.asarray(theta)
    )
    np.testing.assert_allclose(np.asarray(fm.afc(theta)), np.asarray(own), rtol=1e-12, atol=0)


def test_embedding_places_parameters_and_nulls():
    declared, _ = _problem(("clamp_compliance",), {"k_theta_N_per_rad": 2e4})
    model = declared.model.param
    structure = structure_of(model)
    base, index = embedding(model, structure)
    full = embed((base, index), np.array([1.0, 0.2, 0.01, 2e4]))
    values = dict(zip(structure.names, full))
    assert values["D"] == 1.0 and values["k_theta_N_per_rad"] == 2e4
    assert values["tau_s"] == 0.0 and values["gain"] == 1.0 and values["mass_kg"] == 0.0


@pytest.mark.parametrize("p, padded", [(1, 4), (3, 4), (4, 4), (5, 8), (8, 8), (9, 16)])
def test_parameter_padding(p, padded):
    assert padded_count(p) == padded


def test_space_coefficients_map_like_the_space():
    space = ParameterSpace.from_bounds(
        ("D", "nu", "tau_s"), {"D": (1.0, 100.0), "nu": (0.0, 0.5), "tau_s": (-1e-4, 1e-4)}
    )
    u = np.array([[0.3, -0.7, 0.5], [-2.0, 3.0, -1.0]])
    got = np.asarray(from_u_coefficients(space.coefficients(5), np.pad(u, [(0, 0), (0, 2)])))
    np.testing.assert_allclose(got[:, :3], space.from_u(u), rtol=1e-14)
    np.testing.assert_array_equal(got[:, 3:], 0.0)  # the padding's identity maps at u = 0


def test_modes_and_chi2_from_one_decomposition_equal_the_separate_calls():
    """The peak search's tie-break reads the modes and chi2 off one modal decomposition
    per member: the same numbers as the two calls it replaces (modes, chi2_batch), with
    an effect that rocks the base too (a second load vector)."""
    problem, theta = _problem(
        ("stand_resonance",), {"f_hz_1": 660.0, "q_1": 30.0, "theta_rad_per_m_1": 0.3}
    )
    fm = problem.model
    thetas = np.stack([theta, theta * np.r_[1.05, 0.9, 2.0, np.ones(theta.size - 3)]])
    f_hz, height = fm.modes_batch(thetas)
    f2, h2, H = fm.modes_afc_batch(thetas)
    np.testing.assert_allclose(f2, f_hz, rtol=1e-12)
    np.testing.assert_allclose(h2, height, rtol=1e-10)
    np.testing.assert_allclose(H, np.asarray(fm.afc_batch(thetas)), rtol=1e-12, atol=1e-14)
    U = np.array([problem.space.to_u(t) for t in thetas])
    # (chi2_batch maps U back to theta: a round trip's last digits)
    np.testing.assert_allclose(problem.chi2_of_afc(H), problem.chi2_batch(U), rtol=1e-8)
    assert problem.chi2_of_afc(H)[0] < 0.5 * problem.chi2_of_afc(H)[1]  # truth vs moved


@pytest.mark.parametrize("magnitude", [False, True])
def test_reverse_mode_gradient_equals_the_forward_jacobians(magnitude):
    """The trust region's chi2 and gradient (one reverse-mode pass) equal ``|r|²`` and
    ``2 Jᵀ r`` from the forward-mode Jacobian, and a central difference of chi2, away
    from the minimum (clamp and sensor offset moved: 6 parameters, padded to 8)."""
    problem, theta = _problem(
        ("clamp_compliance", "sensor_position"), {"k_theta_N_per_rad": 2e4, "sensor_dy_m": 2e-3}
    )
    if magnitude:
        d = problem.data
        problem = LeastSquaresProblem(
            problem.model, fit_data(FREQS, np.abs(d.H), d.std, magnitude=True), problem.space
        )
    u = problem.space.to_u(theta) + np.linspace(-0.02, 0.03, theta.size)
    f, g = problem.value_and_grad(u)
    J = problem.jacobian(u)
    r = problem.residuals(u)
    np.testing.assert_allclose(f, r @ r, rtol=1e-12)
    np.testing.assert_allclose(g, 2 * J.T @ r, rtol=1e-9, atol=1e-9 * np.abs(g).max())
    h = 1e-6
    fd = [(problem.chi2(u + h * e) - problem.chi2(u - h * e)) / (2 * h) for e in np.eye(u.size)]
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6 * np.abs(g).max())


def test_padding_a_basis_changes_nothing(monkeypatch):
    """A basis padded with dummy unknowns to any size gives the same AFC, and the same
    exact Hessian of chi2, as unpadded (the pad sizes are a matter of speed only: a strip's
    15 unknowns padded to 16 instead of 32 cut the Hessian threefold)."""
    import jax
    import jax.numpy as jnp

    from vibid.identify.model import reduced

    problem, theta = _problem(("clamp_compliance",), {"k_theta_N_per_rad": 2e4})
    fm = problem.model
    n = fm.basis.size
    H_data = jnp.asarray(problem.data.H)
    got = []
    for size in (n, n + 1, n + 17):
        monkeypatch.setattr(reduced, "PAD_SIZES", (size,))
        arrays = reduced.padded_arrays(fm.basis, 2 * np.pi * FREQS, fm.param, fm.param)
        assert arrays["K"].shape[-1] == size
        kernel = reduced.ReducedKernel(fm.param)

        def chi2(t, arrays=arrays, kernel=kernel):
            r = (kernel(arrays, t) - H_data) / 1e-3
            return jnp.sum(r.real**2 + r.imag**2)

        t = jnp.asarray(theta)
        got.append((np.asarray(kernel(arrays, t)), np.asarray(jax.hessian(chi2)(t))))
    for H, B in got[1:]:
        # rounding only: at the resonance below 1400 Hz an LU (one per frequency, the
        # direct path) of the padded and unpadded systems differ by 1.5e-11 relative
        np.testing.assert_allclose(H, got[0][0], rtol=3e-11, atol=0)
        np.testing.assert_allclose(B, got[0][1], rtol=1e-8, atol=1e-8 * np.abs(B).max())
