"""A reference specimen of known modulus calibrates the clamp's free length
(vibid.identify.assess.reference), checked on data from a model vibid did not write: the exact
beam of tests/beam_reference.py, its free length 3 mm longer than the declared one (a clamp
whose line lies inside its jaws), the sensor moving out with the free end."""

import json

import numpy as np
import pytest

import beam_sessions as bs
from vibid.cli import main
from vibid.identify.assess.reference import Reference, calibrate_free_length
from vibid.setup_model import Identification

#: the clamp's line inside its jaws: the beam's free span is this much longer than declared
INSIDE_M = 0.003
#: the beam's modulus: its EI is D W with nu 0 (beam_sessions.TRUTH)
E_BEAM = 12 * bs.TRUTH["D"] / bs.H_M**3


def _identified(effects):
    """(the declared setup, the declared strip identified from the beam's AFC with
    ``effects``): nu held near the beam's 0 (a beam has no plate action to tell it), as a
    lab holds a reference's known Poisson's ratio."""
    from vibid.identify import configure
    from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify

    configure()
    setup = bs.setup()
    setup = type(setup)(
        **{
            **setup.__dict__,
            "identification": Identification(
                "isotropic", {"D": (1.0, 100.0), "nu": (-0.005, 0.005), "beta": (1e-4, 0.1)}
            ),
        }
    )
    H, sd = bs.data(effects, seed=1)
    return setup, identify(
        setup,
        Measurement(bs.F, H, sd),
        ModelChoice(kinds={"nu": ("logit", -0.005, 0.005)}),
        SearchOptions(method="local", start=dict(bs.TRUTH)),
    )


def _E(result):
    p = result.parameters
    return 12 * p["D"] * (1 - p["nu"] ** 2) / bs.H_M**3


@pytest.fixture(scope="module")
def long_beam():
    return _identified({"dL_m": INSIDE_M})


def test_a_known_modulus_gives_the_clamps_free_length(long_beam):
    """The beam 3 mm longer than declared comes out with E 11 % low (its own first four
    frequencies fall by the factors² 0.887 to 0.891; a bare strip's (100 / 103)⁴ is 0.888);
    the known E gives its free length back to 0.02 mm, and a beam of the declared length
    gives the declared length."""
    setup, res = long_beam
    assert _E(res) / E_BEAM == pytest.approx(0.887, abs=0.003)
    cal = calibrate_free_length(setup, res, Reference(E_BEAM))
    assert cal.converged
    assert cal.offset_m == pytest.approx(INSIDE_M, abs=2e-5)
    assert 0 < cal.free_length_std_m < 2e-5  # 0.3 % noise on 60 steps
    assert cal.identified_pa == pytest.approx(_E(res), rel=1e-9)
    assert "+3.00 mm" in cal.sentence() and "inside the jaws" in cal.sentence()
    setup, res = _identified({})
    assert abs(calibrate_free_length(setup, res, Reference(E_BEAM)).offset_m) < 2e-5


def test_the_references_own_uncertainty_enters_the_free_length(long_beam):
    """The reference's part, ``|∂L/∂ ln E_ref| u(E_ref)/E_ref`` from the refit's Fisher
    information, against the free lengths the refit finds for the modulus and for it 4 %
    higher (a finite difference: the same data, another reference)."""
    setup, res = long_beam
    exact = calibrate_free_length(setup, res, Reference(E_BEAM))
    uncertain = calibrate_free_length(setup, res, Reference(E_BEAM, 0.04 * E_BEAM))
    higher = calibrate_free_length(setup, res, Reference(1.04 * E_BEAM))
    step = higher.free_length_m - exact.free_length_m
    assert step == pytest.approx(exact.free_length_m * (1.04**0.25 - 1), rel=0.15)
    part = np.sqrt(uncertain.free_length_std_m**2 - exact.free_length_std_m**2)
    assert part == pytest.approx(step, rel=0.05)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--reference-E=-5e9"], "the reference modulus must be a positive number of Pa"),
        (
            ["--reference-E", "198e9", "--reference-E-std", "nan"],
            "the reference modulus's std must be 0 Pa or more",
        ),
        (["--reference-E-std", "3e9"], "--reference-E-std goes with --reference-E"),
    ],
)
def test_a_bad_reference_is_one_line_before_any_fit(tmp_path, capsys, args, message):
    afc, setup = tmp_path / "afc.csv", tmp_path / "setup.json"
    afc.write_text("frequency_hz,re,im\n100,1,0\n200,1,0\n")
    setup.write_text(json.dumps(bs.setup().to_dict()))
    assert main(["identify", "--afc", str(afc), "--setup", str(setup), *args]) == 1
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_the_report_and_the_console_carry_the_calibration(long_beam):
    """The pipeline's ``reference`` block (the report's, docs/formats.md, "What vibid adds to the formats") and
    its console line; a model without a modulus along the length says why, one line."""
    from types import SimpleNamespace

    from vibid.identify.assess import reference_block
    from vibid.report import plausibility_lines

    setup, res = long_beam
    block = reference_block(setup, res, Reference(E_BEAM))
    assert block["free_length_m"] - block["declared_length_m"] == pytest.approx(INSIDE_M, abs=2e-5)
    assert block["modulus_Pa"] == E_BEAM and block["converged"] is True
    assert plausibility_lines({"reference": block}) == [block["note"]]
    assert reference_block(setup, res, None) is None
    odd = SimpleNamespace(plate_model=SimpleNamespace(model="membrane"), parameters={})
    said = reference_block(setup, odd, Reference(E_BEAM))
    assert said == {
        "note": "reference specimen: no modulus along the length was identified "
        "(membrane model): a reference specimen cannot calibrate the "
        "clamp"
    }


def test_the_reported_std_covers_the_monte_carlo_spread():
    """Ten noise draws of the long beam, Poisson's ratio left free as a lab without a known ν
    would: the reported std (the data's part, Birge-scaled by the beam–plate misfit, χ²/dof
    ≈ 53) covers the free lengths' spread over the draws (measured: 13.5 µm against 6.7 µm).
    Left free, the plate bends ν to 0.20 on a beam, which has no plate action, and the free
    length comes out 3.29 mm: the known E means another D at another ν, which is why ν's
    uncertainty is part of the std on real strips."""
    from vibid.identify import configure
    from vibid.identify.fit import Measurement, SearchOptions, identify

    configure()
    setup = bs.setup()
    found = []
    for seed in range(10):
        H, sd = bs.data({"dL_m": INSIDE_M}, seed=seed)
        res = identify(
            setup,
            Measurement(bs.F, H, sd),
            search=SearchOptions(method="local", start=dict(bs.TRUTH)),
        )
        found.append(calibrate_free_length(setup, res, Reference(E_BEAM)))
    spread = np.std([c.offset_m for c in found], ddof=1)
    reported = np.mean([c.free_length_std_m for c in found])
    assert spread < reported < 5 * spread
    assert np.mean([c.offset_m for c in found]) == pytest.approx(3.29e-3, abs=3e-5)
