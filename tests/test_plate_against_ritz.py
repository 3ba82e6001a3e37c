"""vibid's plate against the independent polynomial Ritz plate of tests/ritz_plate.py (no
mesh, no Argyris elements; the same energies, the sensor a disc of spread mass): the paper's
strip with nu = 0 and its 1 g sensor, centred and 3 mm off the centre line, where the
sensor excites the torsion modes (which the exact beam of tests/beam_reference.py cannot
hold)."""

import dataclasses

import numpy as np
import pytest

import beam_sessions as bs
import ritz_plate as rs
from vibid.identify.model.plate import build_forward_model, natural_frequencies, plate_model

TRUTH = {"D": 17.97, "nu": 0.0, "beta": 0.003}


def _setup(dy_m):
    s = bs.setup()
    r = dataclasses.replace(s.sensors.response, y_m=s.sensors.response.y_m + dy_m)
    return dataclasses.replace(s, sensors=dataclasses.replace(s.sensors, response=r))


@pytest.mark.parametrize("dy_m", [0.0, 0.003])
def test_the_modes_bending_and_torsion_agree_with_the_ritz_plate(dy_m):
    """Six modes to 5e-6 (measured at most 3.5e-6, the second torsion mode with the sensor
    off the centre line; the bending modes 2e-8 to 4e-7; the Ritz basis converges from
    above, 3.9e-5 at 14 x 8 functions where it has 30 x 16)."""
    f_vibid, _ = natural_frequencies(_setup(dy_m), TRUTH | {"beta": 0.0}, 6)
    f_ritz = rs.natural_frequencies_hz(TRUTH["D"], TRUTH["nu"], 6, ys=0.010 + dy_m)
    assert np.all(np.abs(f_ritz / f_vibid - 1) < 5e-6)


@pytest.mark.parametrize("dy_m, tol", [(0.0, 3e-4), (0.003, 1e-3)])
def test_the_afc_agrees_with_the_ritz_plate(dy_m, tol):
    """H on the beam sessions' 60 steps (25-1500 Hz): centred within 3e-4 of H (measured
    1.4e-4, beside the 1467 Hz resonance); 3 mm off the centre line within 1e-3 (measured
    4.3e-4 at 950 Hz, 9 Hz above the first torsion mode, where the Ritz basis is still
    converging on the nearly concentrated sensor: 1.9e-3 at 22 x 12 functions, 8.4e-4 at
    26 x 16, 4.3e-4 at 30 x 16, towards vibid's, which a finer mesh moves by 1e-5)."""
    fm = build_forward_model(_setup(dy_m), bs.F, model=plate_model("isotropic"), theta0=TRUTH)
    H_vibid = np.asarray(fm.afc_full(np.array([TRUTH[n] for n in fm.parameter_names])))
    H_ritz = rs.afc(bs.F, TRUTH["D"], TRUTH["nu"], TRUTH["beta"], ys=0.010 + dy_m)
    assert np.max(np.abs(H_vibid / H_ritz - 1)) < tol
