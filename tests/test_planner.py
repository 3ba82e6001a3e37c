"""The test planner (issue #28): its noise model against a Monte Carlo of the signal stage,
its settle rule against the one-mode ring-down worked by hand, its predicted uncertainty
against the identification's own on a simulated session, and `vibid plan`."""

import json
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from vibid.cli import main
from vibid.errors import VibidError
from vibid.hardware_mocks.records import synthetic_step
from vibid.planner import parse_prior, parse_targets
from vibid.planner.information import noise_std
from vibid.planner.prior import prior_draws
from vibid.planner.settle import settle_s
from vibid.setup_model import Excitation, example_setup
from vibid.signal.afc import afc_from_records

NAMES = ("D", "nu", "beta")


def test_targets_and_priors_parse_relative_and_absolute_with_one_line_errors():
    d, nu = parse_targets(["D=0.1%", "nu=0.002"], NAMES)
    assert (d.value, d.relative, d.std_of(20.0)) == (0.001, True, pytest.approx(0.02))
    assert (nu.value, nu.relative, nu.std_of(0.3)) == (0.002, False, 0.002)
    priors = parse_prior(["D=17±30%", "nu=0.3+-0.05"], NAMES)
    assert priors["D"].std == pytest.approx(5.1) and priors["nu"].std == 0.05
    for bad, match in (
        (["E=1%"], "E is not a parameter"),
        (["D=0%"], "must be positive"),
        (["D~1"], "expected NAME=VALUE"),
    ):
        with pytest.raises(VibidError, match=match):
            parse_targets(bad, NAMES)
    with pytest.raises(VibidError, match="expected NAME=MEAN±STD"):
        parse_prior(["D=17"], NAMES)


def test_prior_draws_follow_the_normal_prior_and_stay_in_the_box():
    box = {"D": (1.0, 100.0), "nu": (0.0, 0.5), "beta": (1e-4, 0.1)}
    draws = prior_draws(NAMES, box, parse_prior(["D=17±10%"], NAMES), 256, seed=1)
    assert np.mean(draws[:, 0]) == pytest.approx(17.0, rel=0.01)
    assert np.std(draws[:, 0]) == pytest.approx(1.7, rel=0.08)
    # beta not named: log-uniform over a box of three decades, its median the geometric centre
    assert np.median(draws[:, 2]) == pytest.approx(math.sqrt(1e-4 * 0.1), rel=0.15)
    assert np.all((draws[:, 1] > 0) & (draws[:, 1] < 0.5))
    with pytest.raises(VibidError, match="outside the setup's bounds"):
        prior_draws(NAMES, box, parse_prior(["D=170±10%"], NAMES), 8)


def test_noise_model_matches_a_monte_carlo_of_the_signal_stage():
    """s = σ_n sqrt(2/N) sqrt(1 + |H|²) per part: 200 records of the stand's nuisances (DC,
    drift, harmonics, clock offset) fitted by the signal stage; their scatter of Re H and Im H."""
    fs, f, n, noise, h = 25600.0, 210.0, 6400, 0.01, 3.0 - 4.0j
    steps = [
        SimpleNamespace(frequency_hz=f, sample_rate_hz=fs, index=i, status="ok", base=b, response=r)
        for i, (b, r) in enumerate(
            synthetic_step(
                f,
                h,
                sample_rate_hz=fs,
                n_samples=n,
                base_amplitude_m_s2=5.0,
                base_phase_rad=0.3 * i,
                clock_offset_ppm=40.0,
                dc_m_s2=(0.01, -0.02),
                drift_m_s2_per_s=(0.001, 0.002),
                harmonics_db=(-40.0,),
                noise_std_m_s2=(0.05, 0.05),
                rng=i,
            )
            for i in range(200)
        )
    ]
    H = np.array([p.h for p in afc_from_records(steps).points])
    predicted = noise_std(h, n / fs, fs, noise)  # σ_n / A = 0.05 / 5
    scatter = math.sqrt(0.5 * (np.var(H.real, ddof=1) + np.var(H.imag, ddof=1)))
    assert scatter == pytest.approx(predicted, rel=0.12)  # 200 draws: ±7 % (1σ) of scatter


def test_settle_is_the_ring_down_of_the_jump_to_a_third_of_the_noise():
    """One mode at 100 Hz, β = 0.01 (τ = 1/(π f_n β) = 0.318 s), peak |H| 50: from rest to
    99 Hz, recorded 0.5 s (inside the half-power band: the fit passes the ring whole)."""
    f_n, beta, peak, noise = np.array([100.0]), 0.01, np.array([50.0]), 1e-4
    g = 50 * 1j * 0.01 * 99.0**2 / (100.0**2 - 99.0**2 + 1j * 0.01 * 100.0**2)
    tau = 1 / (math.pi * 100 * 0.01)
    detuning = math.pi * 1.0 * 0.5  # |f − f_n| T π = 1.57: passes 1/1.57 of the ring
    hand = tau * math.log(abs(g) / detuning / (noise / 3))
    assert settle_s(99.0, None, noise, 0.5, f_n, peak, beta) == pytest.approx(hand, rel=1e-12)
    # a step to the same frequency leaves nothing to ring; far above, the jump is tiny
    assert settle_s(99.0, 99.0, noise, 0.5, f_n, peak, beta) == 0.0
    assert settle_s(5000.0, 4900.0, noise, 0.5, f_n, peak, beta) == 0.0


@pytest.fixture(scope="module")
def strip(tmp_path_factory):
    """A 40-step sweep of the example strip, simulated at the truth (full FE model, 0.04 %
    noise), identified without the loop."""
    from vibid.identify.engine.runtime import configure

    configure()
    d = tmp_path_factory.mktemp("plan")
    setup = replace(
        example_setup(), excitation=Excitation(tuple(7.5 * k for k in range(1, 41)), 0.5)
    )
    (d / "setup.json").write_text(setup.to_json())
    assert (
        main(
            [
                "simulate",
                str(d / "setup.json"),
                "--out",
                str(d / "s.h5"),
                "--params",
                "D=17.97",
                "nu=0.286",
                "beta=0.003",
                "--noise",
                "4e-4",
            ]
        )
        == 0
    )
    assert (
        main(
            ["identify", str(d / "s.h5"), "--no-loop", "--no-progress", "--json", str(d / "r.json")]
        )
        == 0
    )
    return setup, json.loads((d / "r.json").read_text()), d


def test_predicted_uncertainty_is_the_identifications(strip):
    """At the truth, the planner's information (noise, model error, the fit's Jacobian)
    predicts the std the identification reports for the simulated sweep."""
    from vibid.hardware_mocks.simulated_session import StandConditions
    from vibid.planner.design import data_std
    from vibid.planner.information import information

    setup, report, _ = strip
    f = np.asarray(setup.excitation.frequencies_hz)
    info = information(
        setup, NAMES, np.array([[17.97, 0.286, 0.003]]), (7.5, 300.0), noise=4e-4, extra_hz=f
    )
    n = info.frequency_hz.size - f.size
    predicted = data_std(info, n + np.arange(f.size), np.full(f.size, StandConditions().record_s))[
        0
    ]
    reported = np.sqrt(np.diag(report["identification"]["covariance"]))
    assert predicted[:2] == pytest.approx(reported[:2], rel=0.05)  # D, nu
    assert predicted[2] == pytest.approx(reported[2], rel=0.5)  # beta: its model error's sign


def test_vibid_plan_writes_a_setup_the_campaign_plays_and_says_what_it_predicts(strip, capsys):
    from vibid.acquisition.plan import plan_summary
    from vibid.acquisition.stand_config import StandConfig
    from vibid.setup_model import parse_setup

    _, _, d = strip
    out = d / "planned.json"
    args = [
        "plan",
        str(d / "setup.json"),
        "--target",
        "D=0.01%",
        "--prior",
        "D=20±30%",
        "nu=0.3±0.05",
        "beta=0.003±50%",
        "--noise",
        "4e-4",
        "--draws",
        "8",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "plan " in text and "setup's sweep" in text and "std D (median / 90 %)" in text
    assert "prior draws the plan was not chosen on" in text  # judged on held-out draws
    planned = parse_setup(out.read_text())
    f = planned.excitation.frequencies_hz
    assert list(f) == sorted(f) and 8 <= len(f) < 40
    assert len(planned.excitation.settle_s) == len(f) == len(planned.excitation.record_s)
    commands = plan_summary(planned, StandConfig()).commands
    assert [c.settle_s for c in commands] == list(planned.excitation.settle_s)
    assert main(["plan", str(d / "setup.json"), "--target", "E=1%", "--out", str(out)]) == 1
    assert "E is not a parameter" in capsys.readouterr().err
    assert (
        main(
            [
                "plan",
                str(d / "setup.json"),
                "--target",
                "D=1%",
                "--band",
                "5-200",
                "--out",
                str(out),
            ]
        )
        == 1
    )
    assert capsys.readouterr().err.strip().endswith("expected LOW:HIGH in Hz, e.g. 5:2000")
