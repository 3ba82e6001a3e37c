"""Bad input at the command line's edge (issue 62, "never hang, never silently wrong"): one
line on stderr naming the option, exit code 1, no traceback, and no work started first.

Every case here was accepted (rc 0, a plan or a session of an impossible specimen written),
failed only after the work, or printed a traceback before this issue's changes. The long
stages are replaced by functions that fail the test if reached: a check that comes after
the work shows as that failure.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from campaign_fakes import fake_stand, fast_config, short_setup  # noqa: E402
from vibid.cli import main  # noqa: E402

EXAMPLES = Path(__file__).parent.parent / "examples"
STRIP = str(EXAMPLES / "strip_setup.json")


def _reached(what):
    def reached(*_a, **_k):
        raise AssertionError(f"{what} started before the options were checked")

    return reached


def one_line(capsys, command: str) -> str:
    """The one line on stderr (nothing on stdout), without its prefix."""
    out, err = capsys.readouterr()
    assert out == "", out
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err and "internal error" not in err, err
    prefix = f"vibid {command}: error: "
    assert err.startswith(prefix), err
    return err[len(prefix) : -1]


# -- vibid plan ---------------------------------------------------------------------------
@pytest.fixture
def no_planning(monkeypatch):
    import vibid.planner

    monkeypatch.setattr(vibid.planner, "plan_test", _reached("planning"))


@pytest.mark.parametrize("cap", ["0", "-10", "nan", "inf", "1e999"])
def test_plan_refuses_a_stand_time_cap_that_is_not_a_positive_number(
    cap, tmp_path, no_planning, capsys
):
    out = tmp_path / "p.json"
    assert (
        main(["plan", STRIP, "--target", "D=1%", "--max-stand-time", cap, "--out", str(out)]) == 1
    )
    line = one_line(capsys, "plan")
    assert line.startswith("--max-stand-time ") and "positive number of seconds" in line, line
    assert not out.exists()


@pytest.mark.parametrize(
    "options, says",
    [
        (["--target", "D=1e999%"], "--target 'D=1e999%': 1e999 is not a finite number"),
        (
            ["--target", "D=1%", "--prior", "D=10±1e999"],
            "--prior 'D=10±1e999': 1e999 is not a finite",
        ),
        (
            ["--target", "D=1%", "--prior", "D=1e999±1"],
            "--prior 'D=1e999±1': 1e999 is not a finite",
        ),
        (["--target", "D=1%", "D=2%"], "--target: D is given twice"),
        (["--target", "D=1%", "--prior", "D=10±1", "D=20±1"], "--prior: D is given twice"),
        (["--target", "D=1%", "--prior", "D=1000±1"], "--prior D: the mean 1000 is outside"),
    ],
)
def test_plan_refuses_targets_and_priors_that_are_not_numbers_or_given_twice(
    options, says, tmp_path, no_planning, capsys
):
    assert main(["plan", STRIP, *options, "--out", str(tmp_path / "p.json")]) == 1
    assert one_line(capsys, "plan").startswith(says)


def test_plan_refuses_an_unwritable_out_before_planning(tmp_path, no_planning, capsys):
    target = tmp_path / "no-such-folder" / "p.json"
    assert main(["plan", STRIP, "--target", "D=1%", "--out", str(target)]) == 1
    assert one_line(capsys, "plan") == (
        f"{target}: cannot write: the folder {target.parent} does not exist"
    )


def test_plan_refuses_to_write_over_its_own_setup(tmp_path, no_planning, capsys):
    setup = tmp_path / "setup.json"
    setup.write_text(Path(STRIP).read_text())
    before = setup.read_text()
    assert main(["plan", str(setup), "--target", "D=1%", "--out", str(setup)]) == 1
    assert "is the setup itself" in one_line(capsys, "plan")
    assert setup.read_text() == before


# -- vibid simulate -----------------------------------------------------------------------
@pytest.fixture
def no_simulation(monkeypatch):
    import vibid.hardware_mocks.simulated_session

    monkeypatch.setattr(
        vibid.hardware_mocks.simulated_session, "simulate_session", _reached("the simulation")
    )


IMPOSSIBLE = [
    (
        ["--effect", "added_mass:mass_kg=-1"],
        "--effect added_mass: mass_kg (the added mass) cannot be negative",
    ),
    (
        ["--effect", "added_mass:mass_kg=1e6"],
        "--effect added_mass: mass_kg (the added mass) 1000000.0 kg "
        "outweighs the specimen that carries it (0.01584 kg)",
    ),
    (
        ["--effect", "clamp_compliance:k_theta_N_per_rad=0"],
        "--effect clamp_compliance: k_theta_N_per_rad (a stiffness) must be positive, got 0.0",
    ),
    (
        ["--effect", "stand_resonance:f_hz=660,q=-5,theta_rad_per_m=0.3"],
        "--effect stand_resonance: q (a quality factor) must be positive, got -5.0",
    ),
    (
        ["--effect", "channel_delay:tau_s=1e-5,tau_s=2e-5"],
        "--effect channel_delay: tau_s is given twice",
    ),
    (
        ["--effect", "channel_delay:tau_s=nan"],
        "--effect channel_delay: tau_s must be a finite number",
    ),
    (
        ["--effect", "free_length:dL_m=-0.1"],
        "--effect free_length: dL_m (the free length's change) -0.1 m leaves no free length",
    ),
    (["--effect", "sensor_position:sensor_dy_m=0.006"], "--effect sensor_position: sensor_dy_m"),
    (
        ["--params", "D=-5", "nu=0.3", "beta=0.003"],
        "--params: D (a stiffness) must be positive, got -5.0",
    ),
    (
        ["--params", "D=18", "nu=0.7", "beta=0.003"],
        "--params: nu (Poisson's ratio) must lie in (-1, 0.5), got 0.7",
    ),
    (
        ["--params", "D=18", "nu=-1", "beta=0.003"],
        "--params: nu (Poisson's ratio) must lie in (-1, 0.5), got -1.0",
    ),
    (
        ["--params", "D=18", "nu=0.5", "beta=0.003"],
        "--params: nu (Poisson's ratio) must lie in (-1, 0.5), got 0.5",
    ),
    (
        ["--params", "D=18", "nu=0.3", "beta=-0.01"],
        "--params: beta (the loss factor) cannot be negative",
    ),
    (["--params", "D=18", "D=19", "nu=0.3", "beta=0.003"], "--params: D is given twice"),
    (
        ["--params", "D=1e999", "nu=0.3", "beta=0.003"],
        "--params: D must be a finite number, got '1e999'",
    ),
    (
        [
            "--params",
            "D=18",
            "nu=0.3",
            "beta=0.003",
            "tau_s=1e-5",
            "--effect",
            "channel_delay:tau_s=2e-5",
        ],
        "tau_s: given by --params and by --effect",
    ),
]


@pytest.mark.parametrize("options, says", IMPOSSIBLE, ids=[" ".join(o) for o, _ in IMPOSSIBLE])
def test_simulate_refuses_an_impossible_specimen_naming_its_option(
    options, says, tmp_path, no_simulation, capsys
):
    out = tmp_path / "S.h5"
    assert main(["simulate", STRIP, "--out", str(out), *options]) == 1
    assert one_line(capsys, "simulate").startswith(says)
    assert not out.exists() and not (tmp_path / "S.truth.json").exists()


def test_simulate_takes_possible_values_as_given(tmp_path, monkeypatch, capsys):
    import vibid.hardware_mocks.simulated_session

    simulated = {}
    monkeypatch.setattr(
        vibid.hardware_mocks.simulated_session,
        "simulate_session",
        lambda out, setup, truth, **kw: simulated.update(truth),
    )
    out = tmp_path / "S.h5"
    assert (
        main(
            [
                "simulate",
                STRIP,
                "--out",
                str(out),
                "--params",
                "D=17.97",
                "nu=-0.2",
                "beta=0",
                "--effect",
                "added_mass:mass_kg=3e-4",
                "stand_resonance:f_hz=660,q=30,theta_rad_per_m=-0.3",
                "stand_resonance:f_hz=900,q=2,theta_rad_per_m=0",
            ]
        )
        == 0
    )
    assert simulated == {
        "D": 17.97,
        "nu": -0.2,
        "beta": 0.0,
        "mass_kg": 3e-4,
        "f_hz_1": 660.0,
        "q_1": 30.0,
        "theta_rad_per_m_1": -0.3,
        "f_hz_2": 900.0,
        "q_2": 2.0,
        "theta_rad_per_m_2": 0.0,
    }
    truth = json.loads((tmp_path / "S.truth.json").read_text())
    assert truth["parameters"] == simulated


# -- vibid campaign --resume --------------------------------------------------------------
@pytest.fixture
def no_campaign(monkeypatch):
    """The flow and the stand fail the test if reached."""
    import vibid.acquisition.stand
    import vibid.flows.campaign
    import vibid.flows.server

    monkeypatch.setattr(vibid.flows.campaign, "campaign_flow", _reached("the Prefect flow"))
    monkeypatch.setattr(vibid.flows.server, "tie_temporary_server", lambda: None)
    monkeypatch.setattr(vibid.acquisition.stand, "open_stand", _reached("the stand"))


def _session(tmp_path, chooser=None, n=10):
    from vibid.acquisition.campaign import run_campaign

    path = tmp_path / "s.h5"
    run_campaign(short_setup(n), fake_stand(seed=7), path, fast_config(), chooser=chooser)
    return path


def _setup_file(tmp_path, setup):
    path = tmp_path / "setup.json"
    path.write_text(setup.to_json())
    return str(path)


@pytest.mark.parametrize("record_only", [False, True])
def test_resuming_a_complete_session_is_refused_in_one_line_before_the_flow(
    record_only, tmp_path, no_campaign, capsys
):
    out = _session(tmp_path)
    argv = [
        "campaign",
        _setup_file(tmp_path, short_setup()),
        "--stand",
        "simulated",
        "--out",
        str(out),
        "--resume",
    ] + (["--record-only"] if record_only else [])
    assert main(argv) == 1
    line = one_line(capsys, "campaign")
    assert (
        line == f"{out}: the session is already complete (10 steps): nothing to resume "
        "(vibid replay identifies it)"
    )
    assert "continue with" not in line


def test_resuming_with_another_setup_is_refused_in_one_line_before_the_flow(
    tmp_path, no_campaign, capsys
):
    out = _session(tmp_path)
    assert (
        main(
            [
                "campaign",
                _setup_file(tmp_path, short_setup(11)),
                "--stand",
                "simulated",
                "--out",
                str(out),
                "--resume",
            ]
        )
        == 1
    )
    line = one_line(capsys, "campaign")
    assert line.startswith(
        f"{out}: its declared setup differs from the one given; resume a "
        "session only with the setup it was started with"
    )


class Scripted:
    """A chooser that plays one batch, then stops (campaign_fakes' stand plays it)."""

    def __init__(self, attribute):
        self.attribute = attribute

    def plan(self, session_path, start):
        from vibid.acquisition.plan import Pause, StepCommand, record_samples

        for index, f in enumerate((60.0, 120.0)):
            yield StepCommand(
                index, index + 1, f, 0.05, record_samples(f, 25600.0, fast_config().timing), 25600.0
            )
        yield Pause()
        return "one batch"


def _adaptive_attribute(target="D=1%"):
    from vibid.parameters import MODEL_PARAMETERS
    from vibid.planner.adaptive import AdaptiveOptions
    from vibid.planner.prior import parse_targets

    names = MODEL_PARAMETERS["isotropic"]
    return AdaptiveOptions(parse_targets([target], names), (40.0, 130.0), 600.0, 4).attribute()


def test_resuming_an_adaptive_session_with_other_options_is_refused_in_one_line(
    tmp_path, no_campaign, capsys
):
    out = _session(tmp_path, chooser=Scripted(_adaptive_attribute()))
    setup = _setup_file(tmp_path, short_setup())
    assert (
        main(
            [
                "campaign",
                setup,
                "--stand",
                "simulated",
                "--out",
                str(out),
                "--resume",
                "--target",
                "D=2%",
            ]
        )
        == 1
    )
    line = one_line(capsys, "campaign")
    assert line.startswith(f"--out {out}: an adaptive campaign started with other options (")
    assert line.endswith(
        "resume it without --target: --resume continues with the options it records"
    )


def test_resuming_an_adaptive_session_with_its_own_options_reaches_the_flow(
    tmp_path, monkeypatch, no_campaign, capsys
):
    import vibid.flows.campaign

    out = _session(tmp_path, chooser=Scripted(_adaptive_attribute()))
    called = {}

    def flow(*_a, **kw):
        called.update(kw)
        raise KeyboardInterrupt  # stop here: the checks are passed

    monkeypatch.setattr(vibid.flows.campaign, "campaign_flow", flow)
    setup = _setup_file(tmp_path, short_setup())
    for given in ([], ["--target", "D=1%"]):
        assert (
            main(["campaign", setup, "--stand", "simulated", "--out", str(out), "--resume", *given])
            == 1
        )
        assert capsys.readouterr().err == "vibid campaign: interrupted\n"
        assert called.pop("adaptive") == _adaptive_attribute() and called["resume"] is True


class _FailedState:
    """What campaign_flow(..., return_state=True) gives for a failed run."""

    def __init__(self, error, message):
        self.error, self.message, self.name = error, message, "Failed"

    def is_completed(self):
        return False

    def result(self, raise_on_failure=True):
        return self.error


def test_a_resume_refused_inside_the_flow_is_its_one_line_without_continue_with(
    tmp_path, monkeypatch, no_campaign, capsys
):
    import vibid.flows.campaign
    from vibid.acquisition.campaign import CampaignError

    out = tmp_path / "s.h5"
    refused = CampaignError(
        f"{out}: its declared setup differs from the one given; resume a "
        "session only with the setup it was started with"
    )

    def flow(*_a, **kw):  # the file appears meanwhile (another process), the flow refuses it
        out.write_bytes(b"")
        return _FailedState(refused, str(refused))

    monkeypatch.setattr(vibid.flows.campaign, "campaign_flow", flow)
    assert (
        main(
            [
                "campaign",
                _setup_file(tmp_path, short_setup()),
                "--stand",
                "simulated",
                "--out",
                str(out),
                "--report",
                str(tmp_path / "report"),
            ]
        )
        == 1
    )
    assert one_line(capsys, "campaign") == str(refused)


# -- progress -----------------------------------------------------------------------------
def _progress(eta_s):
    from vibid.acquisition.campaign import StepProgress

    return StepProgress(3, 8, 225.0, 3.412, -12.3, eta_s, "ok", 5.0, 1.0, "", 0.01, 0.5, 0.2)


def test_an_adaptive_campaigns_log_says_nothing_of_the_time_left(tmp_path, monkeypatch):
    """Its steps to come are not known: no "about nan s left" (the flow's step log line)."""
    import contextlib

    import vibid.acquisition.stand
    from vibid.flows.campaign import acquire

    @contextlib.contextmanager
    def stand(*_a, **_k):
        yield fake_stand(seed=7)

    monkeypatch.setattr(vibid.acquisition.stand, "open_stand", stand)
    lines = []
    logger = SimpleNamespace(
        info=lambda fmt, *a: lines.append(fmt % a), warning=lambda fmt, *a: lines.append(fmt % a)
    )
    result = acquire(
        short_setup(),
        stand="simulated",
        config=fast_config(),
        out=tmp_path / "a.h5",
        logger=logger,
        chooser=Scripted(_adaptive_attribute()),
    )
    assert result.run_status == "complete"
    steps = [x for x in lines if x.startswith("step ")]
    assert len(steps) == 2, lines
    assert not any("nan" in x or "left" in x for x in steps), steps


def test_the_time_left_is_said_once_it_can_be_estimated():
    from vibid.cli.campaign import progress_line
    from vibid.flows.campaign import step_line

    assert step_line(_progress(95.2)) == (
        "step 4/8: 225.00 Hz, |H| 3.412, phase -12.3 deg, ok (about 95 s left)"
    )
    assert step_line(_progress(math.nan)) == "step 4/8: 225.00 Hz, |H| 3.412, phase -12.3 deg, ok"
    assert progress_line(_progress(130.0)).endswith("left 2 min 10 s")
    assert "left" not in progress_line(_progress(math.nan))


# -- vibid validate -----------------------------------------------------------------------
def test_validate_says_a_missing_file_is_missing_in_one_line(tmp_path, capsys):
    missing = tmp_path / "missing.h5"
    assert main(["validate", str(missing)]) == 1
    out, err = capsys.readouterr()
    assert (out, err) == ("", f"vibid validate: {missing}: no such file\n")
    assert main(["validate", str(tmp_path)]) == 1
    assert (
        capsys.readouterr().err
        == f"vibid validate: {tmp_path}: is a directory, not a session file\n"
    )


def test_reading_a_missing_session_names_no_location_inside_it(tmp_path):
    from vibid.errors import VibidError
    from vibid.session import read_session

    missing = tmp_path / "missing.h5"
    with pytest.raises(VibidError) as info:
        read_session(missing)
    assert str(info.value) == f"{missing}: no such file"


@pytest.mark.parametrize("cap", ["0", "inf", "nan", "-5"])
def test_an_adaptive_campaign_refuses_a_cap_that_is_no_positive_number(
    cap, tmp_path, no_campaign, capsys
):
    out = tmp_path / "a.h5"
    assert (
        main(
            [
                "campaign",
                _setup_file(tmp_path, short_setup()),
                "--stand",
                "simulated",
                "--out",
                str(out),
                "--adaptive",
                "--target",
                "D=1%",
                "--max-stand-time",
                cap,
            ]
        )
        == 1
    )
    assert (
        one_line(capsys, "campaign") == f"--max-stand-time {float(cap)!r}: must be a positive "
        "number of seconds"
    )
    assert not out.exists()
