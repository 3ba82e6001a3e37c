"""The elastic clamp (effects/clamp_compliance.py) against independent references: the rigid
clamp it tends to, and Euler-Bernoulli beam theory for a cantilever on a rotational spring."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from plate_helpers import PAPER_THETA, plate_setup, strip_setup
from vibid.cli import main
from vibid.identify import build_forward_model, natural_frequencies

STRIP = dict(zip(("D", "nu", "beta"), PAPER_THETA))


def spring_cantilever_lambda(K: float, n: int = 1) -> float:
    """The n-th root λ = βL of an Euler-Bernoulli cantilever whose root turns against a
    rotational spring, ``K = k_r L / EI`` (w(0) = 0, EI w''(0) = k_r w'(0), w''(L) =
    w'''(L) = 0): ω = λ² √(EI / (ρA L⁴)). K → ∞ is the clamped beam (1.8751...)."""

    def det(lam):
        ch, sh, c, s = math.cosh(lam), math.sinh(lam), math.cos(lam), math.sin(lam)
        return np.linalg.det(np.array([[ch + c, sh, -s], [sh - s, ch, -c], [2 * lam, -K, -K]]))

    grid = np.linspace(1e-3, 3.0 * n + 2.0, 4000)
    vals = np.array([det(x) for x in grid])
    roots = [
        brentq(det, a, b)
        for a, b, fa, fb in zip(grid[:-1], grid[1:], vals[:-1], vals[1:])
        if fa * fb < 0
    ]
    return roots[n - 1]


def test_beam_reference_reproduces_the_clamped_and_pinned_limits():
    assert spring_cantilever_lambda(1e9) == pytest.approx(1.875104, abs=1e-5)
    assert spring_cantilever_lambda(1e9, 2) == pytest.approx(4.694091, abs=1e-5)
    assert spring_cantilever_lambda(1e-9) < 1e-3 * 1.9**1 + 0.05  # a rigid rotation (ω -> 0)


def test_a_stiff_spring_reproduces_the_rigid_clamp():
    """k_θ = 1e11 N/rad: the clamp's compliance D / (k_θ L) ~ 2e-9 shifts nothing at 1e-6."""
    f0, _ = natural_frequencies(strip_setup(), STRIP, 6)
    f1, _ = natural_frequencies(strip_setup(), STRIP | {"k_theta_N_per_rad": 1e11}, 6)
    np.testing.assert_allclose(f1, f0, rtol=1e-6)


@pytest.mark.parametrize("K", [0.5, 5.0, 50.0])
def test_first_frequency_matches_a_beam_on_a_rotational_spring(K):
    """A narrow strip with nu = 0 and a massless sensor: w = w(x) then satisfies the plate's
    free-edge conditions exactly (M_yy = D12 w,xx = 0, no twist), so plate and beam differ
    only by the plate's rotary inertia, -(h²/24) ∫w'² / ∫w² ~ 4e-6 here, and the FE
    discretisation (~1e-6): asserted to 2e-5."""
    L, W, h, rho, E = 0.1, 0.01, 0.0005, 7800.0, 200e9
    D = E * h**3 / 12.0
    setup = plate_setup(L, W, h, rho, x_m=0.09, y_m=0.005, mass_kg=0.0, radius_m=0.001)
    k_theta = K * D / L  # per metre of edge: k_r L / EI = k_θ W L / (D W)
    f, _ = natural_frequencies(
        setup, {"D": D, "nu": 0.0, "beta": 0.0, "k_theta_N_per_rad": k_theta}, 1
    )
    lam = spring_cantilever_lambda(K)
    beam = lam**2 * math.sqrt(D / (rho * h)) / L**2 / (2 * math.pi)
    assert f[0] == pytest.approx(beam, rel=2e-5)
    clamped, _ = natural_frequencies(setup, {"D": D, "nu": 0.0, "beta": 0.0}, 1)
    assert f[0] < clamped[0] * (1 - 1e-3)  # and the spring really softens the plate


def test_reduced_model_with_the_clamp_matches_the_full_model_and_its_derivative():
    """Every evaluator reads the term: reduced (JAX) against full (sparse LU), values and
    the exact derivative with respect to k_θ (the full model's adjoint)."""
    import jax

    f = np.linspace(7.5, 1500.0, 60)
    theta0 = STRIP | {"k_theta_N_per_rad": 1.6e4}
    fm = build_forward_model(strip_setup(), f, effects=("clamp_compliance",), theta0=theta0)
    assert fm.parameter_names == ("D", "nu", "beta", "k_theta_N_per_rad")
    th = np.array([theta0[n] for n in fm.parameter_names])
    H, Hf = np.asarray(fm.afc(th)), fm.afc_full(th)
    scale = np.abs(Hf).max()
    assert np.abs(H - Hf).max() < 1e-6 * scale
    J = np.asarray(jax.jacfwd(fm.afc)(th))[:, 3]
    Jf = np.asarray(jax.jacfwd(fm.afc_full_jax)(th))[:, 3]
    assert np.abs(J - Jf).max() < 1e-5 * np.abs(Jf).max()
    # the spring matters at this stiffness: the first resonance moves by far more than that
    rigid = build_forward_model(strip_setup(), f, theta0=STRIP)
    assert np.abs(np.asarray(rigid.afc(th[:3])) - H).max() > 1e-2 * scale


def test_modes_command_takes_the_clamp_parameter(tmp_path, capsys):
    p = tmp_path / "setup.json"
    p.write_text(strip_setup().to_json())
    args = ["modes", str(p), "--n", "1", "--params", "D=17.97", "nu=0.286", "beta=0.003"]
    assert main(args) == 0
    rigid = float(capsys.readouterr().out.split()[-2])
    assert main(args + ["k_theta_N_per_rad=16000"]) == 0
    soft = float(capsys.readouterr().out.split()[-2])
    assert 0.9 * rigid < soft < 0.999 * rigid
    assert main(args + ["k_theta_N_per_rad=-5"]) == 1
    # the catalogue's one wording for a value, as vibid simulate says it
    assert (
        "--params: k_theta_N_per_rad (a stiffness) must be positive, got -5.0"
        in capsys.readouterr().err
    )
