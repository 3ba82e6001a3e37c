"""``sensor_position``: the response sensor ``dy`` across the width from its declared place.

The independent reference is the declared model itself with the sensor declared ``dy``
further (its disc assembled there from scratch): the effect interpolates the field under
the disc across the width, so the two agree to the interpolation's error, far below the
effect itself. The strip is the real titanium strip's geometry (99.6 x 20 x 3 mm, a 1.7 g
sensor of radius 3.8 mm centred 5.5 mm off the centre line), where the torsion mode above
the band makes the sensor's position visible in the AFC.
"""

import numpy as np
import pytest

from plate_helpers import plate_setup
from vibid.identify import build_forward_model
from vibid.identify.effects.sensor_position import places

TI = dict(x_m=0.0956, y_m=0.0155, mass_kg=0.0017, radius_m=0.0038)
THETA = {"D": 220.0, "nu": 0.33, "beta": 0.005}
F = np.linspace(40.0, 1500.0, 120)


def _setup(dy=0.0):
    return plate_setup(0.0996, 0.02, 0.003, density=4550.0, **(TI | {"y_m": TI["y_m"] + dy}))


def _effect_model(dy):
    return build_forward_model(
        _setup(), F, effects=("sensor_position",), theta0=THETA | {"sensor_dy_m": dy}
    )


@pytest.fixture(scope="module")
def effect_model():
    return _effect_model(-3e-3)


def test_places_keep_the_disc_on_the_plate():
    # 0.7 mm of room towards the near edge, 11.7 mm towards the far one: the default box
    # [-5, 5] mm is reachable on [-5, 0.7] mm
    at = places(0.0155, 0.0038, 0.02)
    assert min(at) == pytest.approx(-5e-3)
    assert max(at) <= 0.7e-3
    assert len(set(at)) == 3 and 0.0 not in at
    # a centred sensor of the same disc reaches the whole box, both ways
    at = places(0.010, 0.0038, 0.02)
    assert min(at) == pytest.approx(-5e-3) and max(at) == pytest.approx(5e-3)


@pytest.mark.parametrize("dy", [-3e-3, -1e-3, 0.5e-3])
def test_moving_the_sensor_equals_declaring_it_moved(effect_model, dy):
    if dy != -3e-3:
        effect_model = _effect_model(dy)  # its reduced basis built there
    th = np.array([THETA["D"], THETA["nu"], THETA["beta"], dy])
    H = effect_model.afc_full(th)
    moved = build_forward_model(_setup(dy), F, theta0=THETA)
    H_ref = moved.afc_full(th[:3])
    plain = effect_model.afc_full(th * np.array([1, 1, 1, 0]))
    scale = np.abs(H_ref)
    # the effect itself is a few per cent of |H| somewhere in the band ...
    assert np.max(np.abs(plain - H_ref) / scale) > 0.02
    # ... and its interpolation error a hundred times smaller
    assert np.max(np.abs(H - H_ref) / scale) < 2e-4
    f_eff, _ = effect_model.natural_frequencies(th, 3)
    f_ref, _ = moved.natural_frequencies(th[:3], 3)
    assert np.allclose(f_eff, f_ref, rtol=1e-6)
    # the reduced model follows the full one
    assert np.max(np.abs(np.asarray(effect_model.afc(th)) - H) / np.abs(H).max()) < 1e-6


def test_the_torsion_mode_is_seen_in_proportion_to_the_offset(effect_model):
    # towards the centre line the sensor sees less of the torsion mode above the band:
    # |H| at the top of the band moves towards the centred sensor's
    th = np.array([THETA["D"], THETA["nu"], THETA["beta"], 0.0])
    centred = build_forward_model(_setup(-5.5e-3), F, theta0=THETA).afc_full(th[:3])
    declared = effect_model.afc_full(th)
    halfway = effect_model.afc_full(th + np.array([0, 0, 0, -2.75e-3]))
    top = F > 1400
    gap = np.abs(declared[top]) - np.abs(centred[top])
    assert np.all(np.abs(gap) > 0.01 * np.abs(centred[top]))
    # the torsional share goes as the offset (response) times the offset (coupling by the
    # sensor's mass): about a quarter of it is left halfway
    left = (np.abs(halfway[top]) - np.abs(centred[top])) / gap
    assert np.all((left > 0.15) & (left < 0.35))
