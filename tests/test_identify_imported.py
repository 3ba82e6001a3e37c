"""An AFC measured elsewhere: vibid identify --afc AFC.csv --setup SETUP.json, its one-line
errors, and the report's engineering block against the closed-form constants."""

import json
import math

import numpy as np
import pytest
from afc_files import write_afc_csv
from plate_helpers import PAPER_D

from vibid.cli import main
from vibid.identify.engineering import engineering_constants
from vibid.setup_model import example_setup


def _setup_without_excitation(tmp_path, **specimen):
    doc = example_setup().to_dict()
    del doc["excitation"]
    doc["specimen"].update(specimen)
    p = tmp_path / "setup.json"
    p.write_text(json.dumps(doc))
    return p


def test_engineering_constants_are_the_closed_forms():
    # the paper's strip: E 198 GPa, nu 0.286, h 1 mm -> D = 17.97 N m
    out = engineering_constants("isotropic", ("D", "nu", "beta"), [PAPER_D, 0.286, 0.003],
                                np.diag([0.01**2, 0.0, 0.0]), 0.001, 1e-5)
    assert out["E_Pa"]["value"] == pytest.approx(198e9, rel=1e-12)
    assert out["G_Pa"]["value"] == pytest.approx(198e9 / (2 * 1.286), rel=1e-12)
    # std: D's (E proportional to D) and the thickness's (E ~ h^-3) in quadrature
    rel = math.hypot(0.01 / PAPER_D, 3 * 1e-5 / 0.001)
    assert out["E_Pa"]["std"] == pytest.approx(198e9 * rel, rel=1e-6)
    assert out["nu"]["std"] == 0.0
    ortho = engineering_constants("orthotropic", ("D11", "D12", "D22", "D66", "beta"),
                                  [10.0, 3.0, 5.0, 2.0, 0.003], np.zeros((5, 5)), 0.002)
    assert ortho["nu12"]["value"] == pytest.approx(0.6)
    assert ortho["E1_Pa"]["value"] == pytest.approx(12 * (10 - 9 / 5) / 0.002**3)
    assert ortho["G12_Pa"]["value"] == pytest.approx(12 * 2 / 0.002**3)


def test_an_imported_afc_is_identified_and_reported(tmp_path):
    """The strip's reduced-model AFC (0.3 % noise) as a CSV, with a setup that has no
    excitation: the declared model fits it, nothing is added, the report is strict JSON
    with a content-derived session id and the engineering block."""
    from vibid.identify import build_forward_model, configure

    configure()
    setup = example_setup()
    f = np.linspace(20.0, 900.0, 45)
    fm = build_forward_model(setup, f, theta0={"D": 17.97, "nu": 0.286, "beta": 0.003})
    H = np.asarray(fm.afc(np.array([17.97, 0.286, 0.003])))
    std = 0.003 * np.abs(H) + 1e-3
    rng = np.random.default_rng(4)
    Hn = H + std * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    csv = write_afc_csv(tmp_path / "afc.csv", f, Hn, std)
    setup_path = _setup_without_excitation(tmp_path, thickness_std_m=1e-5)
    report = tmp_path / "report.json"
    args = ["identify", "--afc", str(csv), "--setup", str(setup_path), "--json", str(report),
            "--no-progress", "--restarts", "2"]
    assert main(args) == 0
    text = report.read_text()
    doc = json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    assert doc["effects"] == [] and doc["loop"]["unexplained_residual"] is False
    assert abs(doc["parameters"]["D"]["value"] - 17.97) < 3 * doc["parameters"]["D"]["std"]
    e = doc["engineering"]["E_Pa"]
    assert abs(e["value"] - 198e9) < 3 * e["std"]
    # the thickness's 1 %: through the conversion (h^-3) and the fit (a heavier plate,
    # a larger D: h^+1 without the sensor, less with its 1 g that h does not scale), so
    # between 2 % and 3 % of E
    part = doc["engineering"]["budget"]["E_Pa"]["thickness_m"]
    assert 0.02 * 198e9 < part < 0.03 * 198e9
    assert e["std"] == pytest.approx(math.sqrt(sum(
        v**2 for v in doc["engineering"]["budget"]["E_Pa"].values())), rel=1e-9)
    first = doc["session_id"]
    assert main(args) == 0
    assert json.loads(report.read_text())["session_id"] == first  # derived from the bytes


@pytest.mark.parametrize("content, message", [
    ("frequency_hz,re\n1,2\n", "the header lacks im"),
    ("frequency_hz,re,im\n10,1,x\n20,1,0\n", "line 2: im is not a number"),
    ("frequency_hz,re,im\n10,1,0\n", "fewer than two AFC points"),
    ("frequency_hz,re,im,std\n10,1,0,-1\n20,1,0,1\n", "std must not be negative"),
])
def test_bad_csv_is_one_line(tmp_path, capsys, content, message):
    p = tmp_path / "afc.csv"
    p.write_text(content)
    setup_path = _setup_without_excitation(tmp_path)
    assert main(["identify", "--afc", str(p), "--setup", str(setup_path)]) == 1
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_afc_needs_its_setup(tmp_path, capsys):
    assert main(["identify", "--afc", str(tmp_path / "x.csv")]) == 1
    assert "--afc needs --setup" in capsys.readouterr().err
