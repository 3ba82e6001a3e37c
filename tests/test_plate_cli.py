"""`vibid modes`."""

import json

import pytest

from vibid.cli import main
from vibid.setup_model import example_setup


@pytest.fixture()
def setup_file(tmp_path):
    p = tmp_path / "setup.json"
    p.write_text(example_setup().to_json())
    return p


def test_modes_table_and_json(setup_file, tmp_path, capsys):
    out = tmp_path / "modes.json"
    rc = main(
        [
            "modes",
            str(setup_file),
            "--params",
            "D=17.97",
            "nu=0.286",
            "beta=0.003",
            "--n",
            "3",
            "--accuracy",
            "fast",
            "--json",
            str(out),
        ]
    )
    assert rc == 0
    doc = json.loads(out.read_text())
    assert set(doc) == {"frequency_hz", "decay_1_per_s"}
    assert len(doc["frequency_hz"]) == 3
    assert doc["frequency_hz"][0] == pytest.approx(74.94, abs=0.01)
    # a single loss factor: gamma = omega * Im sqrt(1 + i beta) / Re sqrt(1 + i beta)
    assert doc["decay_1_per_s"][0] == pytest.approx(2 * 3.14159265 * 74.94 * 0.0015, rel=1e-3)
    assert "74.94" in capsys.readouterr().out


@pytest.mark.parametrize(
    "params, message",
    [
        (["D=17.97", "nu=0.3"], "match no model"),
        (["D=abc", "nu=0.3", "beta=0.01"], "must be a number"),
        (["D17", "nu=0.3", "beta=0.01"], "NAME=VALUE"),
        (["D=-1", "nu=0.3", "beta=0.01"], "must be positive"),
    ],
)
def test_modes_bad_input_one_line(setup_file, capsys, params, message):
    assert main(["modes", str(setup_file), "--params", *params]) == 1
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_modes_missing_file(tmp_path, capsys):
    assert main(["modes", str(tmp_path / "nope.json"), "--params", "D=1", "nu=0.3", "beta=0"]) == 1
    assert "no such file" in capsys.readouterr().err


@pytest.mark.parametrize(
    "params, message",
    [
        (["D=17.97", "nu=0.286", "beta=0.003", "D=18"], "--params: D is given twice"),
        (
            ["D=17.97", "nu=0.7", "beta=0.003"],
            "--params: nu (Poisson's ratio) must lie in (-1, 0.5), got 0.7",
        ),
        (["D=-5", "nu=0.3", "beta=0.003"], "--params: D (a stiffness) must be positive, got -5"),
        (
            ["D=17.97", "nu=0.3", "beta=-0.01"],
            "--params: beta (the loss factor) cannot be negative, got -0.01",
        ),
        (["D=1e999", "nu=0.3", "beta=0.003"], "--params: D must be a finite number, got '1e999'"),
        (
            ["D=17.97", "nu=0.3", "beta=0.003", "mass_kg=1"],
            ("--params: mass_kg (the added mass) 1.0 kg outweighs the specimen"),
        ),
    ],
)
def test_modes_refuses_params_as_simulate_does(
    setup_file, tmp_path, capsys, monkeypatch, params, message
):
    """issue 62: `vibid modes` reads --params with `vibid simulate`'s readers: a name given
    twice is refused (never the last one silently), and so is a value its parameter's rule
    or the declared specimen rules out, in the same one line, before any model is built."""
    from vibid.hardware_mocks import simulated_session as simulated
    from vibid.identify.model import plate

    monkeypatch.setattr(plate, "natural_frequencies", lambda *a, **k: pytest.fail("computed"))
    monkeypatch.setattr(simulated, "simulate_session", lambda *a, **k: pytest.fail("simulated"))
    assert main(["modes", str(setup_file), "--params", *params]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"vibid modes: error: {message}") and err.count("\n") == 1, err
    out = tmp_path / "S.h5"
    assert main(["simulate", str(setup_file), "--out", str(out), "--params", *params]) == 1
    assert capsys.readouterr().err == err.replace("vibid modes:", "vibid simulate:", 1)
