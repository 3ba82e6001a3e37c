"""`vibid campaign` through campaign_flow on the simulated stand, under one Prefect test server.

One short campaign (the paper's strip, 21 short steps to 900 Hz, an undeclared 20 µs channel
delay in the stand configuration's virtual specimen, and an injected generator fault at the
fourth step) is run once for the module through the CLI: the fault ends the first attempt
(`aborted`, stand fault), the flow reopens the stand and resumes; the session completes,
validates, and holds every step of the setup once, in order; acquisition ran in the main
thread; the report finds the delay. Replaying the recorded session gives the campaign's own
AFC bit for bit and its parameters to 1e-12 relative (fixed seeds).
"""

import contextlib
import datetime
import io
import json
import math
import threading

import numpy as np
import pytest

from vibid.cli import main

pytestmark = pytest.mark.usefixtures("prefect_harness")

TAU_S = 2e-5
FREQUENCIES_HZ = (30.0,) + tuple(45.0 * k for k in range(1, 21))
OPTIONS = ["--candidates", "channel_delay", "--restarts", "1"]
FAULT_STEP = 3  # 0-based: the fourth frequency command of the first stand


def _write_inputs(folder, name, **simulated):
    import dataclasses

    from vibid.setup_model import example_setup

    s = example_setup()
    s = dataclasses.replace(
        s, excitation=dataclasses.replace(s.excitation, frequencies_hz=FREQUENCIES_HZ)
    )
    setup = folder / "setup.json"
    setup.write_text(s.to_json())
    stand = folder / "stand.json"
    stand.write_text(
        json.dumps(
            {
                "generator": {"url": f"vibidsim://{name}", "timeout_s": 0.2},
                "timing": {"min_record_s": 0.05, "min_cycles": 10, "max_settle_s": 40.0},
                "simulated": {
                    "seed": 3,
                    "noise": 0.003,
                    "effects": {"channel_delay": {"tau_s": TAU_S}},
                    **simulated,
                },
            }
        )
    )
    return setup, stand


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """The campaign through the CLI, with every run_campaign call recorded (its thread, its
    resume flag and how it ended)."""
    import vibid.acquisition.campaign as acquisition

    folder = tmp_path_factory.mktemp("campaign")
    setup, stand = _write_inputs(
        folder, "flow-campaign", faults=[{"kind": "no_reply", "at_step": FAULT_STEP, "count": 5}]
    )
    out, report_dir = folder / "strip.h5", folder / "report"
    calls = []
    real = acquisition.run_campaign

    def recorded(*args, **kwargs):
        result = real(*args, **kwargs)
        calls.append(
            {
                "main_thread": threading.current_thread() is threading.main_thread(),
                "resume": kwargs.get("resume"),
                "result": result,
            }
        )
        return result

    stdout = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(stdout):
        mp.setattr(acquisition, "run_campaign", recorded)
        rc = main(
            [
                "campaign",
                str(setup),
                "--stand",
                "simulated",
                "--stand-config",
                str(stand),
                "--out",
                str(out),
                "--report",
                str(report_dir),
                *OPTIONS,
            ]
        )
    return {
        "rc": rc,
        "stdout": stdout.getvalue(),
        "out": out,
        "report_dir": report_dir,
        "calls": calls,
        "report": json.loads((report_dir / "report.json").read_text()),
    }


def test_campaign_completes_validates_and_its_report_finds_the_delay(campaign):
    from vibid.session import file_problems, read_session

    assert campaign["rc"] == 0, campaign["stdout"]
    lines = campaign["stdout"].splitlines()
    assert lines[0] == f"session: {campaign['out']}"
    assert lines[1] == f"report: {campaign['report_dir'] / 'report.md'}"
    assert any(line.startswith("effects found: channel_delay") for line in lines), lines
    chi2 = next(line for line in lines if line.startswith("chi2/dof: "))
    before, after = (float(w) for w in chi2.split() if w[0].isdigit())
    report = campaign["report"]
    stages = report["loop"]["stages"]
    assert (before, after) == (
        float(f"{stages[0]['chi2_reduced']:.4g}"),
        float(f"{stages[-1]['chi2_reduced']:.4g}"),
    )
    # the delay explains nearly all of the residual (what is left, chi2/dof about 4 here, is
    # the virtual stand's records scattering more than the signal stage's stated std)
    assert before > 1000.0 and after < before / 1000.0
    assert file_problems(campaign["out"]) == []
    with read_session(campaign["out"]) as s:
        assert s.run_status == "complete"
    (effect,) = report["effects"]
    tau = effect["parameters"]["tau_s"]
    assert effect["name"] == "channel_delay" and abs(tau["value"] - TAU_S) < 4 * tau["std"], tau
    d = report["parameters"]["D"]
    assert abs(d["value"] - 17.97) < 4 * d["std"] + 2e-3 * 17.97, d
    md = (campaign["report_dir"] / "report.md").read_text()
    assert "channel_delay" in md and "](afc.png)" in md


def test_a_transient_generator_fault_is_retried_as_a_resume_and_no_step_is_written_twice(campaign):
    from vibid.hardware_mocks.virtual_stand import lookup_stand
    from vibid.session import read_session

    first, second = campaign["calls"]  # one retry
    assert first["result"].run_status == "aborted"
    assert first["result"].reason.startswith("stand fault: ")
    assert not first["resume"] and second["resume"]
    assert second["result"].run_status == "complete"
    assert 0 < first["result"].n_steps <= FAULT_STEP
    assert all(c["main_thread"] for c in campaign["calls"])  # where Ctrl-C and SIGTERM reach it
    assert lookup_stand("flow-campaign").instrument.sim_fired == {0}  # fired once, not again
    assert not lookup_stand("flow-campaign").instrument.output_on
    with read_session(campaign["out"]) as s:
        np.testing.assert_array_equal(s.frequencies_hz(), FREQUENCIES_HZ)  # each once, in order
        assert len(s) == len(FREQUENCIES_HZ)
        assert s.statuses() == ["ok"] * len(FREQUENCIES_HZ)


def test_replaying_the_campaigns_session_gives_its_report(campaign):
    from vibid.flows import replay_flow

    live = campaign["report"]
    replay = replay_flow(campaign["out"], candidates=["channel_delay"], restarts=1)
    assert replay["afc"] == live["afc"]  # floats from the same bits: equal exactly
    assert replay["session_id"] == live["session_id"]
    assert [e["name"] for e in replay["effects"]] == [e["name"] for e in live["effects"]]

    def values(r):
        out = {n: (p["value"], p["std"]) for n, p in r["parameters"].items()}
        out |= {n: (p["value"], p["std"]) for e in r["effects"] for n, p in e["parameters"].items()}
        return out

    a, b = values(live), values(replay)
    assert a.keys() == b.keys() and "tau_s" in a
    for name in a:
        for x, y in zip(a[name], b[name]):
            assert math.isclose(x, y, rel_tol=1e-12), (name, x, y)
    for sa, sb in zip(live["loop"]["stages"], replay["loop"]["stages"]):
        assert math.isclose(sa["chi2_reduced"], sb["chi2_reduced"], rel_tol=1e-12)


def test_an_aborted_campaign_is_not_retried_and_says_why_in_one_line(tmp_path, capsys):
    setup, stand = _write_inputs(tmp_path, "flow-abort")
    doc = json.loads(stand.read_text())
    doc["drive"] = {"abort_response_m_s2": 1.0}  # the first record exceeds it
    stand.write_text(json.dumps(doc))
    out = tmp_path / "s.h5"
    rc = main(
        [
            "campaign",
            str(setup),
            "--stand",
            "simulated",
            "--stand-config",
            str(stand),
            "--out",
            str(out),
            "--report",
            str(tmp_path / "report"),
        ]
    )
    captured = capsys.readouterr()
    assert rc == 1
    (line,) = [x for x in captured.err.splitlines() if x.startswith("vibid campaign: ")]
    assert line.startswith("vibid campaign: campaign aborted: response peak ")
    assert line.endswith(f"{out} keeps its 1 steps (resume to continue)")
    assert "Traceback" not in captured.err
    assert not (tmp_path / "report" / "report.json").exists()


def test_the_default_session_file_is_new_on_every_run(tmp_path, capsys):
    from vibid.cli.campaign import default_out

    t = datetime.datetime(2026, 11, 23, 7, 5, 9, tzinfo=datetime.UTC)
    assert default_out("examples/strip_setup.json", now=t) == "runs/strip_setup-20261123-070509.h5"
    setup, _ = _write_inputs(tmp_path, "flow-default")
    assert main(["campaign", str(setup), "--stand", "simulated", "--resume"]) == 1
    assert (
        capsys.readouterr().err
        == "vibid campaign: error: --resume needs --out: the session file to continue\n"
    )


def test_the_quick_starts_files_are_a_campaign_of_the_papers_strip(capsys):
    """README's first command: examples/ load, and its plan is 80 steps to 1500 Hz."""
    from pathlib import Path

    from vibid.acquisition.stand_config import load_stand_config
    from vibid.session import load_setup
    from vibid.setup_model import example_setup

    examples = Path(__file__).parent.parent / "examples"
    setup = load_setup(str(examples / "strip_setup.json"))
    paper = example_setup()
    assert (setup.specimen, setup.sensors, setup.identification) == (
        paper.specimen,
        paper.sensors,
        paper.identification,
    )
    assert setup.excitation.frequencies_hz == tuple(18.75 * k for k in range(1, 81))
    config = load_stand_config(str(examples / "simulated_stand.json"))
    assert config.simulated.effects == {"channel_delay": {"tau_s": 2e-5}}  # not in the setup
    assert (
        main(
            [
                "campaign",
                str(examples / "strip_setup.json"),
                "--stand",
                "simulated",
                "--stand-config",
                str(examples / "simulated_stand.json"),
                "--dry-run",
            ]
        )
        == 0
    )
    assert capsys.readouterr().out.splitlines()[-1].startswith("80 steps: ")


def test_a_resume_refused_inside_the_flow_fails_it_in_one_line_without_a_traceback(
    tmp_path, capsys, caplog
):
    """The CLI checks a resume before the flow starts; called from Python, the flow refuses
    it itself: its run Failed with the refusal's one line (the state's result is the
    error, calling the flow raises it), no traceback in its log (issue 62)."""
    from vibid.acquisition.campaign import CampaignError
    from vibid.flows import campaign_flow

    setup, stand = _write_inputs(tmp_path, "flow-refused")
    out = tmp_path / "s.h5"
    assert (
        main(
            [
                "campaign",
                str(setup),
                "--stand",
                "simulated",
                "--stand-config",
                str(stand),
                "--out",
                str(out),
                "--record-only",
            ]
        )
        == 0
    )
    capsys.readouterr()
    caplog.clear()
    state = campaign_flow(
        str(setup),
        stand="simulated",
        stand_config=str(stand),
        out=str(out),
        resume=True,
        return_state=True,
    )
    assert state.is_failed()
    error = state.result(raise_on_failure=False)
    assert isinstance(error, CampaignError) and state.message == str(error)
    assert str(error) == (
        f"{out}: the session is already complete (21 steps): nothing to "
        "resume (vibid replay identifies it)"
    )
    # its line in the run's log, and no record with a traceback (the console's text is the
    # harness's: a closed capture of an earlier test may add its own "Logging error")
    assert [r.getMessage() for r in caplog.records if r.levelname == "ERROR"] == [str(error)]
    assert not any(r.exc_info for r in caplog.records)
    with pytest.raises(CampaignError, match="already complete"):
        campaign_flow(
            str(setup), stand="simulated", stand_config=str(stand), out=str(out), resume=True
        )
