"""Checks of the Timoshenko reference beam (tests/timoshenko_reference.py) against independent
results: the Rayleigh-beam reference (tests/beam_reference.py) in the shear-rigid limit, Huang's
(1961) closed-form cantilever frequency equation, static Timoshenko beam theory for the
low-frequency limit, and its own result with the beam cut finer (the multiple shooting)."""

import numpy as np
import pytest
from scipy.optimize import brentq

import beam_reference as br
import huang_cantilever as huang
import timoshenko_reference as tr

# the titanium strip of shared/data/real-titanium (as in test_effect_transverse_shear.py):
# nu = 0, G = E / 2; h / L = 0.03
L, B, H, RHO, E, KAPPA = 0.0996, 0.020, 0.003, 4550.0, 110e9, 5 / 6
EI, RHOA, RHOI = E * H**3 * B / 12, RHO * B * H, RHO * B * H**3 / 12
KGA = KAPPA * E / 2 * B * H
STRIP = dict(L=L, EI=EI, kGA=KGA, rhoA=RHOA, rhoI=RHOI)
OMEGA = 2 * np.pi * np.geomspace(10.0, 5000.0, 300)  # the frequencies of use
BODY_M, BODY_J = 2e-3, 3e-8  # an accelerometer: 2 g, radius of gyration ~4 mm


def cantilever(shear: bool, n: int = 2):
    """The strip's clamped-free frequencies, Hz (Huang 1961: tests/huang_cantilever.py)."""
    return huang.frequencies_hz(n, L=L, B=B, H=H, rho=RHO, E=E, kappa=KAPPA, shear=shear)


# ------------------------------------------------------------ shear-rigid limit = Rayleigh
@pytest.mark.parametrize(
    "x_s, m, J",
    [(L, BODY_M, BODY_J), (0.7 * L, BODY_M, BODY_J), (L, 0, 0)],
    ids=["body-at-tip", "body-inside", "no-body"],
)
@pytest.mark.parametrize(
    "k_root", [None, 2000.0, 2000.0 * (1 + 0.01j)], ids=["clamp", "spring", "lossy-spring"]
)
@pytest.mark.parametrize("loss", [0.0, 0.003])
def test_shear_rigid_limit_is_the_rayleigh_reference(x_s, m, J, k_root, loss):
    """kGA = 1e14 EI / L^2: the shear terms are s^2 lambda^2 < 1e-12 up to 5 kHz (lambda < 9).
    Measured over the 18 cases: max relative difference 5e-11 - 4e-10 (next to resonances),
    median 3e-14 - 5e-14, over 300 frequencies 10 Hz - 5 kHz (|H| from 2e-3 at the
    antiresonance of the inside body to 585)."""
    EIc = EI * (1 + 1j * loss)
    body = dict(x_s=x_s, m=m, J=J, k_root=k_root)
    h_t = tr.afc(OMEGA, L=L, EI=EIc, kGA=1e14 * EI / L**2, rhoA=RHOA, rhoI=RHOI, **body)
    h_r = br.afc(OMEGA, L=L, EI=EIc, rhoA=RHOA, rhoI=RHOI, **body)
    rel = np.abs(h_t / h_r - 1)
    assert rel.max() < 1e-8
    assert np.median(rel) < 1e-12
    assert np.abs(h_r).max() > 10  # the range crosses resonances


def test_finite_shear_stiffness_is_resolved():
    """Not a vacuous limit: the real strip's shear lowers the 2nd resonance by 0.29 %, so the
    AFCs of the two models differ by far more than the test's 1e-8 near it (measured: 3.2)."""
    h_t = tr.afc(OMEGA, **STRIP, x_s=L)
    h_r = br.afc(OMEGA, L=L, EI=EI, rhoA=RHOA, rhoI=RHOI, x_s=L)
    assert np.abs(h_t / h_r - 1).max() > 0.1


# ------------------------------------------------------------------------ Huang (1961)
def test_natural_frequencies_match_huang():
    """Measured: relative differences 1e-16 and 4e-16 (240.06 Hz, 1499.08 Hz)."""
    huang = cantilever(True, 2)
    f = tr.natural_frequencies_hz(2, **STRIP)
    np.testing.assert_allclose(f, huang, rtol=1e-12)
    # and without shear (kGA -> infinity) Huang's Rayleigh-beam frequencies
    f_rigid = tr.natural_frequencies_hz(2, **dict(STRIP, kGA=1e14 * EI / L**2))
    np.testing.assert_allclose(f_rigid, cantilever(False, 2), rtol=1e-10)


def test_afc_poles_are_huangs_frequencies():
    """The undamped tip AFC (real) has its poles at Huang's frequencies: the sign change of
    1/H, found by brentq within +-1e-6 of them. Measured: relative distance <= 7e-16."""
    for f in cantilever(True, 2):
        w0 = 2 * np.pi * f

        def inv(w):
            return (1 / tr.afc(w, **STRIP, x_s=L)).real

        assert inv(w0 * (1 - 1e-6)) * inv(w0 * (1 + 1e-6)) < 0
        pole = brentq(inv, w0 * (1 - 1e-6), w0 * (1 + 1e-6), xtol=1e-300, rtol=1e-15)
        assert abs(pole / w0 - 1) < 1e-12


def test_natural_frequencies_with_a_body_are_the_afc_poles():
    """With a body inside and a root spring, the determinant's roots are where 1/H(x_s) = 0."""
    beam = dict(STRIP, x_s=0.7 * L, m=BODY_M, J=BODY_J, k_root=2000.0)
    for f in tr.natural_frequencies_hz(3, **beam):
        w0 = 2 * np.pi * f
        below, above = (1 / tr.afc(w0 * np.array([1 - 1e-9, 1 + 1e-9]), **beam)).real
        assert below * above < 0


# ------------------------------------------------------------------- low-frequency limit
@pytest.mark.parametrize("m", [0.0, BODY_M])
def test_low_frequency_limit_is_rigid_plus_static_timoshenko_deflection(m):
    """H(0) = 1 exactly; H = 1 + omega^2 delta + O(omega^4), delta the static tip deflection of
    the Timoshenko cantilever under its own weight per unit acceleration and the tip mass's:
    rhoA L^4 / 8 EI + rhoA L^2 / 2 kGA + m L^3 / 3 EI + m L / kGA (J and rhoI enter at
    omega^4). Measured: (H - 1) / (omega^2 delta) - 1 = 1.8e-5 (2.3e-5 with the body) at 1 Hz,
    4 times that at 2 Hz: the omega^2 term (f / f1 = 1 / 240, squared); Richardson's
    extrapolation of the two to omega = 0 leaves 1e-9 / 2e-9 (the next, omega^4 term). The
    shear part of delta is 7e-4 of it: resolved by a factor ~3e5."""
    beam = dict(STRIP, x_s=L, m=m, J=BODY_J if m else 0.0)
    assert tr.afc(0.0, **beam) == 1.0
    assert abs(tr.afc(1e-3, **beam) - 1) < 1e-11
    delta = RHOA * L**4 / (8 * EI) + RHOA * L**2 / (2 * KGA) + m * L**3 / (3 * EI) + m * L / KGA
    w = 2 * np.pi * np.array([1.0, 2.0])
    err = ((tr.afc(w, **beam) - 1) / (w**2 * delta) - 1).real
    assert np.all(np.abs(err) < 1e-4)
    assert err[1] / err[0] == pytest.approx(4.0, rel=1e-3)  # O(omega^2)
    at_zero = (4 * err[0] - err[1]) / 3
    assert abs(at_zero) < 1e-8
    shear_part = (RHOA * L**2 / (2 * KGA) + m * L / KGA) / delta
    assert shear_part > 1e4 * abs(at_zero)  # the check resolves the shear deflection


# ------------------------------------------------------------------ the multiple shooting
def test_cutting_finer_changes_nothing():
    """The result does not depend on the cuts (tr._STEP: the largest |lambda| ell per
    sub-segment, 1 by default): 0.25 and 3 agree to ~1e-11 on the strip up to 5 kHz. On a hard
    case, a 0.5 mm steel strip up to 50 kHz (kL ~ 60), the cuts agree to ~1e-12, while one
    transfer matrix over each segment (a huge step) is wrong by orders of magnitude."""
    body = dict(x_s=0.7 * L, m=BODY_M, J=BODY_J, k_root=2000.0)
    steel = dict(
        L=L,
        EI=200e9 * B * 0.0005**3 / 12,
        kGA=KAPPA * 200e9 / 2.6 * B * 0.0005,
        rhoA=7800 * B * 0.0005,
        rhoI=7800 * B * 0.0005**3 / 12,
    )
    hard = 2 * np.pi * np.geomspace(5e3, 5e4, 12)
    cases = [(STRIP, EI * (1 + 0.003j), OMEGA[::5]), (steel, steel["EI"] * (1 + 0.003j), hard)]
    base = [tr.afc(om, **dict(beam, EI=EIc), **body) for beam, EIc, om in cases]
    step = tr._STEP
    try:
        for factor in (0.25, 3.0):
            tr._STEP = step * factor
            for (beam, EIc, om), h0 in zip(cases, base):
                h = tr.afc(om, **dict(beam, EI=EIc), **body)
                assert np.abs(h / h0 - 1).max() < 1e-9
        tr._STEP = 1e6
        beam, EIc, om = cases[1]
        assert np.abs(tr.afc(om, **dict(beam, EI=EIc), **body) / base[1] - 1).max() > 1e-3
    finally:
        tr._STEP = step
