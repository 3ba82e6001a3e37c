"""Each mode's resonance peak in |H| (vibid.identify.model.modal.mode_heights), against the
exact Rayleigh beam of tests/beam_reference.py: the paper's strip with nu = 0 and its 1 g
sensor on the centre line bends as that beam, and no torsion is excited or seen."""

import math

import numpy as np

import beam_reference as beam
import beam_sessions as bs
from vibid.identify.model.modal import seen
from vibid.identify.model.plate import natural_mode_heights


def test_bending_heights_are_the_exact_beams_peaks_and_torsion_is_hidden():
    """``height_k`` is beta times mode k's peak in |H|: the exact beam's peaks (searched on a
    fine grid, loss factor 0.003) agree to 2e-5, 7e-4 and 5e-3 for the first three bending
    modes (the smaller a peak, the more the other modes' tails add to it); the torsion
    modes' heights are rounding noise, 1e-17 of the first's."""
    f_hz, height = natural_mode_heights(bs.setup(), bs.TRUTH, 8)
    kw = bs._beam({})
    beam_hz = beam.natural_frequencies_hz(3, **(kw | {"EI": kw["EI"].real}))
    shown = seen(height)
    assert np.count_nonzero(~shown[f_hz < 1500]) == 1  # the first torsion, 961 Hz
    assert np.allclose(f_hz[shown][:3], beam_hz, rtol=5e-4)
    for fk, hk in zip(beam_hz, height[shown][:3]):
        grid = np.linspace(0.99 * fk, 1.01 * fk, 4001)
        peak = np.abs(beam.afc(2 * math.pi * grid, **kw)).max()
        assert abs(hk / (bs.TRUTH["beta"] * peak) - 1) < 0.01, (fk, hk, peak)
    assert np.all(height[~shown] < 1e-12 * height.max())


def test_a_sensor_off_the_centre_line_sees_the_torsion():
    """3 mm off the centre line the first torsion's peak is 0.6 % of the first bending
    mode's: seen, though small."""
    f_hz, height = natural_mode_heights(bs.setup(), bs.TRUTH | {"sensor_dy_m": 0.003}, 8)
    torsion = int(np.argmin(np.abs(f_hz - 950)))
    assert 3e-3 < height[torsion] / height.max() < 1e-2 and seen(height)[torsion]
