"""An orthotropic plate (150 x 100 x 2 mm, D11/D22 = 10) identified from a box prior, on
vibid's FE forward model. The data come from a finer discretisation ("fine": 32 x 21
cells, 6 corner levels, through its own local reduced basis, 5e-8 of max|H| from its full
model) than the fit's (16 x 11 cells), plus noise of 1e-3 max|H|. Three resonances lie in
the band for four stiffnesses, so the search needs the peak matching of
vibid.identify.fit.peaks; about 75 s on two cores, hence marked slow
(it still runs by default and in CI)."""

import dataclasses

import numpy as np
import pytest

from vibid.setup_model import Identification, example_setup

TRUE = {"D11": 50.0, "D12": 1.5, "D22": 5.0, "D66": 3.0, "beta": 0.005}


def plate_setup(freqs):
    s = example_setup()
    return dataclasses.replace(
        s,
        specimen=dataclasses.replace(
            s.specimen,
            name="orthotropic 150x100x2",
            length_m=0.150,
            width_m=0.100,
            thickness_m=0.002,
            density_kg_m3=1550.0,
        ),
        sensors=dataclasses.replace(
            s.sensors, response=dataclasses.replace(s.sensors.response, x_m=0.130, y_m=0.070)
        ),
        excitation=dataclasses.replace(s.excitation, frequencies_hz=tuple(freqs)),
        identification=Identification(
            "orthotropic",
            {
                "D11": (5.0, 500.0),
                "D12": (0.0, 10.0),
                "D22": (0.5, 50.0),
                "D66": (0.3, 30.0),
                "beta": (1e-4, 0.1),
            },
        ),
    )


@pytest.mark.slow
def test_orthotropic_plate_from_a_box_prior():
    from vibid.identify import build_forward_model
    from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify

    f = np.linspace(5.0, 600.0, 150)
    setup = plate_setup(f)
    fm = build_forward_model(setup, f, model="orthotropic")
    truth = build_forward_model(setup, f, model="orthotropic", theta0=TRUE, accuracy="fine")
    theta = np.array([TRUE[n] for n in fm.parameter_names])
    H = np.asarray(truth.afc(theta))
    sd = 1e-3 * np.abs(H).max()
    rng = np.random.default_rng(0)
    Hn = H + sd * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    res = identify(
        setup,
        Measurement(f, Hn, np.full(f.size, sd)),
        ModelChoice(forward_model=fm),
        SearchOptions(restarts=2, seed=0),
    )
    assert res.converged, res.message
    assert res.chi2_reduced < 1.5  # the right basin: wrong ones give 2 to 13
    # within 5 reported standard deviations of the truth, and the large moduli to 2 %
    assert np.all(np.abs(res.values - theta) < 5 * res.std), (res.values, res.std)
    for name in ("D11", "D22", "D66"):
        assert res.parameters[name] == pytest.approx(TRUE[name], rel=0.02)
