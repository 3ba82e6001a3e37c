"""The closed loop on a session vibid did not simulate: the exact Timoshenko cantilever of
tests/timoshenko_reference.py (shear deformation and rotary inertia), a thick strip
(100 x 20 x 3 mm titanium, nu = 0, h/L = 0.03, a 0.5 g sensor of 3 mm radius on the centre
line 10 mm from the tip) on 90 steps up to 4.5 kHz (three bending modes; the shear lowers
the third by two bandwidths), 0.3 % noise. Declared Kirchhoff, the loop names the transverse
shear alone, among every candidate, and the truth comes back."""

import dataclasses

import numpy as np
import pytest

import timoshenko_reference as tim
from loop_data import noisy
from plate_helpers import plate_setup
from vibid.identify.loop import close_loop
from vibid.setup_model import Identification

L, W, H, RHO, E, KAPPA, BETA = 0.100, 0.020, 0.003, 4550.0, 110e9, 5 / 6, 0.003
MASS_KG, RADIUS_M, X_S = 0.5e-3, 0.003, 0.09
D = E * H**3 / 12  # nu = 0: 247.5 N m
TRUTH = {"D": D, "nu": 0.0, "beta": BETA}
F = np.linspace(50.0, 4500.0, 90)


def _setup():
    s = plate_setup(L, W, H, density=RHO, x_m=X_S, y_m=W / 2, mass_kg=MASS_KG, radius_m=RADIUS_M)
    return dataclasses.replace(
        s,
        excitation=dataclasses.replace(s.excitation, frequencies_hz=tuple(map(float, F))),
        identification=Identification(
            "isotropic", {"D": (D / 5, D * 5), "nu": (-0.3, 0.5), "beta": (1e-4, 0.1)}
        ),
    )


def _session(seed=0):
    """(H, std): the Timoshenko beam, its sensor a rigid body of the disc's inertia."""
    c = 1 + 1j * BETA
    H_beam = tim.afc(
        2 * np.pi * F,
        L=L,
        EI=D * W * c,
        kGA=KAPPA * E / 2 * W * H * c,
        rhoA=RHO * H * W,
        rhoI=RHO * H**3 / 12 * W,
        x_s=X_S,
        m=MASS_KG,
        J=MASS_KG * (RADIUS_M**2 / 4 + H**2 / 12),
    )
    return noisy(H_beam, seed)


@pytest.mark.slow
def test_the_shear_of_a_timoshenko_beam_is_named_alone_and_the_truth_comes_back():
    """Declared: chi2_red 86, D 1.3 % low; named in round 0, its refit lowering chi2 from
    15 186 to 167 where its score along the secant was 806 (ranked seventh: a candidate
    without parameters is refitted whenever its score passes); chi2_red 0.94, D 247.500 +-
    0.009, nu -0.005 +- 0.005. With a 1 g sensor of 4 mm radius D lands 3.7 std (8e-5)
    high: vibid's sensor is a disc of spread mass on a plate that deforms under it, the
    beam's a rigid body (1e-3 of H at 4.4 kHz, with shear or without)."""
    H, sd = _session()
    loop = close_loop(_setup(), F, H, sd, seed=0, restarts=1)
    assert loop.stages[0].result.chi2_reduced > 10
    assert loop.effects == ("transverse_shear",)
    assert not loop.unexplained_residual
    r = loop.final
    for n, v in TRUTH.items():
        assert abs(r.parameters[n] - v) < 3 * r.parameter_std[n], (n, r.parameters[n])
