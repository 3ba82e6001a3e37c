"""The modal solver reads the terms too: a loss law is applied at each mode's own frequency,
an inertia term lowers the frequencies (library effects frequency_dependent_loss and
added_mass; their AFCs are checked in test_effects_library.py)."""

import numpy as np

from plate_helpers import PAPER_THETA, strip_setup
from vibid.identify import natural_frequencies

STRIP = dict(zip(("D", "nu", "beta"), PAPER_THETA))


def test_a_loss_law_acts_at_each_modes_frequency():
    f0, decay0 = natural_frequencies(strip_setup(), STRIP, 3)
    f, decay = natural_frequencies(strip_setup(), STRIP | {"alpha": 0.5}, 3)
    # decay = Im sqrt(lambda (1 + i beta L(f))) ~ pi f beta L(f), L = (f / 1 kHz)^0.5;
    # the frequencies move only at O(beta^2)
    np.testing.assert_allclose(f, f0, rtol=1e-5)
    np.testing.assert_allclose(decay / decay0, np.sqrt(f0 / 1000.0), rtol=1e-4)


def test_a_point_mass_at_the_sensor_lowers_the_frequencies_as_rayleigh_says():
    """0.3 g at the sensor's centre (the strip: f1 74.94 -> 73.21 Hz) against the same
    0.3 g added to the declared 1 g sensor, spread over its disc (73.21 Hz): the disc's
    radius (1 mm) is small against the bending wavelength, so the two agree to a few 1e-6
    (its rotary inertia and spread are the difference); asserted to 1e-4."""
    m = 3e-4
    f0, _ = natural_frequencies(strip_setup(), STRIP, 2)
    f, _ = natural_frequencies(strip_setup(), STRIP | {"mass_kg": m}, 2)
    heavier = strip_setup(mass_kg=0.001 + m)
    f_disc, _ = natural_frequencies(heavier, STRIP, 2)
    assert 0.9 * f0[0] < f[0] < 0.99 * f0[0]
    np.testing.assert_allclose(f, f_disc, rtol=1e-4)
