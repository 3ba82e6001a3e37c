"""The effects of issue #24, and the elastic clamp, against a model vibid did not write: an
exact Euler-Bernoulli/Rayleigh cantilever (tests/beam_reference.py, solved per frequency
from the beam's closed-form solutions).

A narrow strip with nu = 0 bends as a beam exactly: w = w(x) satisfies the plate's
free-edge conditions (M_yy = D12 w,xx = 0, no twist), so the plate with its rotary inertia
rho h³/12 is a Rayleigh beam of EI = D W, rho A = rho h W, rho I = rho h³ W / 12. The sensor
is a small disc (r = 0.5 mm): to the beam, a rigid body of its mass and rotary inertia
m (r²/4 + h²/12) (the disc's spread and its thickness's share), plus m (h e + e²) for a
centre of mass e above the surface. What remains between them is the FE discretisation and
the disc's footprint, below 1e-5 of a frequency here; each effect moves what is compared
by far more."""

import math

import numpy as np
import pytest

import beam_reference as beam
from plate_helpers import plate_setup
from vibid.identify import build_forward_model, natural_frequencies
from vibid.identify.model.plate import plate_model_for

L, W, H_M, RHO, E = 0.1, 0.01, 0.0005, 7800.0, 200e9
D = E * H_M**3 / 12.0
M_S, R_S, X_S = 2e-4, 0.0005, 0.09
SETUP = plate_setup(L, W, H_M, RHO, x_m=X_S, y_m=W / 2, mass_kg=M_S, radius_m=R_S)
BEAM = dict(
    L=L,
    EI=D * W,
    rhoA=RHO * H_M * W,
    rhoI=RHO * H_M**3 / 12 * W,
    x_s=X_S,
    m=M_S,
    J=M_S * (R_S**2 / 4 + H_M**2 / 12),
)
PLATE = {"D": D, "nu": 0.0, "beta": 0.0}
HEIGHT = 3e-3
DL = 3e-3
K_THETA = 5.0 * D / L  # N/rad per metre of edge: k_r L / EI = 5


@pytest.mark.parametrize(
    "extra, beam_change",
    [
        ({}, {}),
        ({"height_m": HEIGHT}, {"J": BEAM["J"] + M_S * (H_M * HEIGHT + HEIGHT**2)}),
        ({"dL_m": DL}, {"L": L + DL, "x_s": X_S + DL}),
        ({"dL_m": -DL}, {"L": L - DL, "x_s": X_S - DL}),
        ({"k_theta_N_per_rad": K_THETA}, {"k_root": K_THETA * W}),
        (
            {"k_theta_N_per_rad": K_THETA, "dL_m": DL},  # the spring on a stretched plate: k / s²
            {"k_root": K_THETA * W, "L": L + DL, "x_s": X_S + DL},
        ),
    ],
)
def test_natural_frequencies_match_the_beam(extra, beam_change):
    f, _ = natural_frequencies(SETUP, PLATE | extra, 3)
    fb = beam.natural_frequencies_hz(3, **(BEAM | beam_change))
    np.testing.assert_allclose(f, fb, rtol=2e-5)
    if extra:  # and the effect moves them by far more than that
        plain = beam.natural_frequencies_hz(3, **BEAM)
        assert np.abs(fb / plain - 1).max() > 5e-3


def _afc(extra: dict, freqs):
    values = PLATE | extra
    fm = build_forward_model(SETUP, freqs, model=plate_model_for(values), theta0=values)
    assert set(fm.parameter_names) == set(values)
    return np.asarray(fm.afc(np.array([values[n] for n in fm.parameter_names])))


F = np.geomspace(10.0, 900.0, 40)
OMEGA = 2 * math.pi * F


def test_a_stand_resonance_is_the_beam_under_a_rocking_base():
    """H = H_translation + θ(f) H_rotation with the base's rotation θ(f) of a resonance
    at 300 Hz, against the beam whose base turns by θ(f) per metre of translation."""
    beta = 0.02
    res = {"f_hz_1": 300.0, "q_1": 15.0, "theta_rad_per_m_1": 0.5}
    theta_f = 0.5 / (1 - (F / 300.0) ** 2 + 1j * F / (300.0 * 15.0))
    H = _afc({"beta": beta} | res, F)
    Hb = beam.afc(
        OMEGA, **(BEAM | {"EI": BEAM["EI"] * (1 + 1j * beta)}), rotation_per_translation=theta_f
    )
    plain = beam.afc(OMEGA, **(BEAM | {"EI": BEAM["EI"] * (1 + 1j * beta)}))
    assert np.abs(H - Hb).max() < 2e-3 * np.abs(Hb).max()
    assert np.max(np.abs(Hb - plain) / np.abs(plain)) > 0.05  # near 300 Hz, where no mode is
    # the rotation's own response: x_s at low frequency (the sensor's rigid lever)
    assert beam.afc_rotation(np.array([1.0]), **BEAM)[0].real == pytest.approx(X_S, rel=1e-3)


@pytest.mark.parametrize("beta_clamp", [0.0, 0.3])
def test_a_clamp_with_its_own_loss_is_the_beam_on_a_lossy_spring(beta_clamp):
    """A lossless spring (the peaks as sharp as the plate's loss allows) and a frictional
    one (the first mode, which turns the root most, damped far more)."""
    beta = 0.01
    k = {"k_theta_N_per_rad": K_THETA, "beta_clamp": beta_clamp}
    H = _afc({"beta": beta} | k, F)
    Hb = beam.afc(
        OMEGA,
        **(
            BEAM
            | {"EI": BEAM["EI"] * (1 + 1j * beta), "k_root": K_THETA * W * (1 + 1j * beta_clamp)}
        ),
    )
    same_loss = beam.afc(
        OMEGA,
        **(BEAM | {"EI": BEAM["EI"] * (1 + 1j * beta), "k_root": K_THETA * W * (1 + 1j * beta)}),
    )
    assert np.abs(H - Hb).max() < 2e-3 * np.abs(Hb).max()
    assert np.abs(Hb - same_loss).max() > 5e-2 * np.abs(Hb).max()
