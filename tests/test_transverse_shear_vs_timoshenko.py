"""``transverse_shear`` against the exact Timoshenko beam of tests/timoshenko_reference.py, on a
thick strip (100 x 20 x 3 mm titanium, nu = 0, h/L = 0.03) whose band holds three bending
modes (226, 1460, 4120 Hz): the first-order correction places the three shifted modes as
Timoshenko does where the sensor has no mass; it misses the shear under the sensor's own
inertia force and the shear deflection in the forced response, the two known defects marked
below (issue #25: no loop test of the transverse shear alone on independent data can pass
before they are mended)."""

import numpy as np
import pytest
import timoshenko_reference as tim
from plate_helpers import plate_setup

from vibid.identify.model.forward import build_forward_model, natural_frequencies, plate_model

L, W, H, RHO, E, KAPPA, BETA = 0.100, 0.020, 0.003, 4550.0, 110e9, 5 / 6, 0.003
D = E * H**3 / 12  # nu = 0
TRUTH = {"D": D, "nu": 0.0, "beta": BETA}
X_S, RADIUS = 0.09, 0.004


def _setup(mass_kg):
    return plate_setup(L, W, H, density=RHO, x_m=X_S, y_m=W / 2, mass_kg=mass_kg,
                       radius_m=RADIUS)


def _beam(mass_kg, loss=0.0, shear=True):
    """The Timoshenko beam of the strip, its sensor a rigid body of the disc's inertia."""
    c = (1 + 1j * loss) if loss else 1.0  # real for the natural frequencies
    return dict(L=L, EI=D * W * c, rhoA=RHO * H * W, rhoI=RHO * H**3 / 12 * W,
                kGA=KAPPA * E / 2 * W * H * c * (1.0 if shear else 1e12),
                x_s=X_S, m=mass_kg, J=mass_kg * (RADIUS**2 / 4 + H**2 / 12))


def _shifts(mass_kg):
    """(vibid's relative shear shift of the three bending modes, Timoshenko's)."""
    setup = _setup(mass_kg)
    f_k, _ = natural_frequencies(setup, TRUTH | {"beta": 0.0}, 6)
    f_s, _ = natural_frequencies(setup, TRUTH | {"beta": 0.0}, 6,
                                 effects=("transverse_shear",))
    rayleigh = tim.natural_frequencies_hz(3, **_beam(mass_kg, shear=False))
    timoshenko = tim.natural_frequencies_hz(3, **_beam(mass_kg))
    bending = [int(np.argmin(np.abs(f_k - f))) for f in rayleigh]  # the third is torsion
    # the Kirchhoff plate is the Rayleigh beam here (nu = 0, a centred sensor)
    np.testing.assert_allclose(f_k[bending], rayleigh, rtol=2e-4)
    return f_s[bending] / f_k[bending] - 1, timoshenko / rayleigh - 1


def test_three_shifted_modes_match_timoshenko_where_the_sensor_has_no_mass():
    plate, beam = _shifts(0.0)
    # the shifts themselves: -4.2e-4, -2.9e-3, -6.8e-3 (the third mode two bandwidths at
    # beta = 0.003); first order leaves -1.7e-7, -3.1e-6, -2.5e-5
    np.testing.assert_allclose(beam, [-4.18e-4, -2.90e-3, -6.82e-3], rtol=0.01)
    assert np.all(np.abs(plate - beam) < [1e-6, 1e-5, 5e-5])


@pytest.mark.xfail(strict=True, reason=(
    "known defect of transverse_shear (issue #25): its inertia matrices hold the shear under "
    "the plate's own inertia load, not under the sensor's: with a 1 g sensor on the 27 g "
    "strip the three shifts come out 7 %, 6 % and 2 % short (-3.79e-4 against -4.06e-4, "
    "-2.73e-3 against -2.89e-3, -6.68e-3 against -6.83e-3), 18 % with 3 g"))
def test_three_shifted_modes_match_timoshenko_with_a_1_g_sensor():
    plate, beam = _shifts(1e-3)
    assert np.all(np.abs(plate / beam - 1) < 0.02)


@pytest.mark.xfail(strict=True, reason=(
    "known defect of transverse_shear (issue #25): the term corrects the modes' frequencies "
    "(an inertia) but not the forced response between them; the likely causes: the sensor "
    "reads the bending deflection without the shear deflection, and the rigid base "
    "motion's inertia load shears nothing in the term (not yet shown one by one). "
    "Against Timoshenko's AFC the error grows smoothly from 0.02 % at 100 Hz to 4 % at "
    "4.4 kHz (massless sensor), while the shear itself changes H by up to 15 %"))
def test_the_forced_response_with_shear_matches_timoshenko():
    f_hz = np.array([100.0, 400.0, 800.0, 1200.0, 1800.0, 2500.0, 3000.0, 3500.0, 4400.0])
    setup = _setup(0.0)
    model = plate_model("isotropic", effects=("transverse_shear",))
    fm = build_forward_model(setup, f_hz, model=model, theta0=TRUTH)
    H_vibid = np.asarray(fm.afc_full(np.array([TRUTH[n] for n in fm.parameter_names])))
    H_beam = tim.afc(2 * np.pi * f_hz, **_beam(0.0, loss=BETA))
    assert np.max(np.abs(H_vibid / H_beam - 1)) < 0.005  # 0.3 % noise: a fit would see it
