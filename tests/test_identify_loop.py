"""The closed loop (identify/loop.py) on data with an undeclared effect: it names the effect,
the declared parameters move back to the truth, the residual ends at the noise level; clean
data get nothing added; and the whole path session -> AFC -> loop -> report."""

import dataclasses
import json

import numpy as np
import pytest
from plate_helpers import strip_setup

from vibid.hardware_mocks.simulated_session import true_afc
from vibid.identify.loop import close_loop

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
F = np.linspace(1500.0 / 60, 1500.0, 60)


def _setup(freqs=F):
    s = strip_setup()
    return dataclasses.replace(s, excitation=dataclasses.replace(s.excitation,
                                                                 frequencies_hz=tuple(freqs)))


def _data(effects: dict, seed: int):
    """The strip's AFC from the full FE model on a finer mesh than the fit's, with noise of
    0.3 % of |H| per point (and a floor), as the signal stage reports for a 0.3 % channel
    noise."""
    H = true_afc(_setup(), TRUTH | effects, F, accuracy="fine")
    sd = 0.003 * np.abs(H) + 1e-3
    rng = np.random.default_rng(seed)
    return H + sd * (rng.standard_normal(F.size) + 1j * rng.standard_normal(F.size)), sd


def _truth_within(result, sigmas=3.0):
    for name, value in TRUTH.items():
        i = result.parameter_names.index(name)
        assert abs(result.values[i] - value) < sigmas * result.std[i], (name, result.values[i],
                                                                       result.std[i])


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_clean_data_get_nothing_added(seed):
    H, sd = _data({}, seed)
    loop = close_loop(_setup(), F, H, sd, seed=seed, restarts=2)
    assert loop.effects == () and not loop.unexplained_residual
    assert loop.rounds == ()  # the declared model fits the noise: nothing is even scored


@pytest.mark.slow
@pytest.mark.parametrize("effect, value", [("channel_delay", {"tau_s": 2e-5}),
                                           ("clamp_compliance", {"k_theta_N_per_rad": 1.6e4})])
def test_an_undeclared_effect_is_found_and_the_declared_parameters_return(effect, value):
    H, sd = _data(value, 7)
    loop = close_loop(_setup(), F, H, sd, seed=0, restarts=2)
    before, after = loop.stages[0].result, loop.final
    assert loop.effects == (effect,)
    assert not loop.unexplained_residual and loop.stages[-1].fits_noise
    assert before.chi2_reduced > 5 and after.chi2_reduced < 1.5  # the error before and after
    _truth_within(after)
    (name, v), = value.items()
    i = after.parameter_names.index(name)
    assert abs(after.values[i] - v) < 3 * after.std[i]
    scores = {s.name: s for s in loop.rounds[0]}
    assert scores[effect].kept and scores[effect].score > 100


@pytest.mark.slow
def test_the_session_path_reports_the_loop(tmp_path):
    """vibid simulate (an undeclared delay on the virtual stand) -> vibid identify -> report."""
    from vibid.cli import main
    from vibid.session import read_session

    freqs = tuple(22.5 * k for k in range(1, 41))
    setup_path = tmp_path / "setup.json"
    setup_path.write_text(_setup(freqs).to_json())
    path = tmp_path / "session.h5"
    assert main(["simulate", str(setup_path), "--out", str(path), "--params", "D=17.97",
                 "nu=0.286", "beta=0.003", "--effect", "channel_delay:tau_s=3e-5",
                 "--seed", "2"]) == 0
    with read_session(path) as r:  # the effect is in the data, not in the declared setup
        assert "tau_s" not in r.setup.to_json()
    truth = json.loads((tmp_path / "session.truth.json").read_text())
    assert truth["parameters"]["tau_s"] == 3e-5
    report = tmp_path / "report.json"
    assert main(["identify", str(path), "--json", str(report), "--no-progress",
                 "--restarts", "2"]) == 0
    doc = json.loads(report.read_text())
    assert [e["name"] for e in doc["effects"]] == ["channel_delay"]
    tau = doc["effects"][0]["parameters"]["tau_s"]
    assert abs(tau["value"] - 3e-5) < 3 * tau["std"]
    stages = doc["loop"]["stages"]
    assert [s["added"] for s in stages] == [None, "channel_delay"]
    assert stages[0]["chi2_reduced"] > 5 * stages[1]["chi2_reduced"]
    assert doc["loop"]["unexplained_residual"] is False
    assert set(doc["parameters"]) == {"D", "nu", "beta"}
    assert {r["candidate"] for r in doc["loop"]["rounds"][0]} >= {"channel_delay", "anisotropy"}
    # --no-loop: the declared model alone
    assert main(["identify", str(path), "--json", str(report), "--no-progress",
                 "--restarts", "2", "--no-loop"]) == 0
    doc = json.loads(report.read_text())
    assert doc["effects"] == [] and len(doc["loop"]["stages"]) == 1
    assert doc["loop"]["unexplained_residual"] is True
