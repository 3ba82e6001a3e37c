"""Natural frequencies against published plate values and the Euler–Bernoulli limit."""

import math

import numpy as np
import pytest

from plate_helpers import PAPER_THETA, plate_setup, strip_setup
from vibid.identify import natural_frequencies
from vibid.identify.model.modal import frequencies_and_decays

RHO = 7920.0
THIN = 1e-4  # m: rotary inertia ~ (h/a)^2, negligible


def test_square_cantilever_matches_ritz():
    """λ = ω a² √(ρh/D) of a square cantilever plate, ν = 0.3, against the converged
    Rayleigh–Ritz values 3.471, 8.507, 21.29, 27.20, 30.96 (Leissa, NASA SP-160)."""
    a, D = 0.1, 1.0
    s = plate_setup(a, a, THIN, RHO, x_m=0.09, y_m=0.05, mass_kg=0.0, radius_m=0.001)
    f, _ = natural_frequencies(s, {"D": D, "nu": 0.3, "beta": 0.0}, 5, accuracy="fast")
    lam = 2 * np.pi * f * a**2 * math.sqrt(RHO * THIN / D)
    np.testing.assert_allclose(lam, [3.471, 8.507, 21.29, 27.20, 30.96], rtol=5e-3)


def _beam_ratio(width_m, nu=0.3, D=1.0, L=0.1):
    s = plate_setup(
        L, width_m, THIN, RHO, x_m=0.09, y_m=width_m / 2, mass_kg=0.0, radius_m=width_m / 4
    )
    f, _ = natural_frequencies(s, {"D": D, "nu": nu, "beta": 0.0}, 3, accuracy="fast")
    beta_l = np.array([1.8751, 4.6941, 7.8548])
    beam = beta_l**2 / L**2 * math.sqrt(D * (1 - nu**2) / (RHO * THIN)) / (2 * math.pi)
    return f / beam - 1


def test_narrow_strip_tends_to_euler_bernoulli_beam():
    """A strip's bending modes tend to the cantilever's (β_n L = 1.8751, 4.6941, 7.8548)
    with bending stiffness D (1 − ν²) per width, the error shrinking like the width."""
    wide, narrow = _beam_ratio(0.002), _beam_ratio(0.001)
    assert np.abs(narrow).max() < 2e-3  # D instead of D(1 - nu^2) would be 4.6 % off
    np.testing.assert_allclose(wide / narrow, 2.0, rtol=0.1)


def test_paper_strip_first_frequency_and_decay():
    f, g = natural_frequencies(strip_setup(), dict(zip(("D", "nu", "beta"), PAPER_THETA)), 6)
    assert f[0] == pytest.approx(74.94, abs=0.01)
    assert np.all(np.diff(f) > 0)
    # one loss factor: Λ = (1 + iβ) λ, so γ/ω = Im √(1+iβ) / Re √(1+iβ)
    root = np.sqrt(1 + 0.003j)
    np.testing.assert_allclose(g / (2 * np.pi * f), root.imag / root.real, rtol=1e-9)


def test_per_modulus_losses_complex_eigenproblem():
    """Equal per-modulus loss factors (complex Arnoldi path) give the real-mode result;
    a loss only on D66 damps the torsion-dominated mode most."""
    setup = strip_setup()
    D, nu, beta = PAPER_THETA
    same = {"D": D, "nu": nu, "beta11": beta, "beta12": beta, "beta66": beta}
    f1, g1 = natural_frequencies(setup, same, 4)
    f0, g0 = natural_frequencies(setup, {"D": D, "nu": nu, "beta": beta}, 4)
    np.testing.assert_allclose(f1, f0, rtol=1e-9)
    np.testing.assert_allclose(g1, g0, rtol=1e-7)
    shear = {"D": D, "nu": nu, "beta11": 0.0, "beta12": 0.0, "beta66": beta}
    _, gs = natural_frequencies(setup, shear, 4)
    q = gs / g0  # fraction of each mode's energy in the D66 term
    assert np.argmax(q) == 2  # the third mode (790 Hz) is the first torsion mode
    assert q[0] < 0.05 and q[2] > 0.5


def test_sensor_without_mass_adds_nothing():
    params = dict(zip(("D", "nu", "beta"), PAPER_THETA))
    a, _ = natural_frequencies(strip_setup(mass_kg=0.0), params, 4, accuracy="fast")
    b, _ = natural_frequencies(
        strip_setup(mass_kg=0.0, x_m=0.05, radius_m=0.004), params, 4, accuracy="fast"
    )
    np.testing.assert_allclose(a, b, rtol=1e-9)
    c, _ = natural_frequencies(strip_setup(), params, 4, accuracy="fast")
    assert c[0] < a[0] * 0.97  # the 1 g sensor on a 16 g strip lowers the first mode


def test_frequencies_and_decays_branch():
    f, g = frequencies_and_decays(np.array([(2 * np.pi * 10) ** 2 * (1 + 0.01j)]))
    assert f[0] == pytest.approx(10 * np.sqrt(1 + 0.01j).real)
    assert g[0] > 0
