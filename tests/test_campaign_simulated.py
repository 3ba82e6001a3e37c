"""`vibid campaign --stand simulated`: the real drivers in front of the virtual stand.

The AFC of a simulated campaign against the virtual specimen's own H (z-scores in the signal
stage's stated uncertainty), at ±200 ppm generator clock offsets; the session validates;
bad paths are refused before the stand opens; a generator fault aborts with output off; a
campaign process killed with SIGKILL is continued by --resume.
"""

import json
import os
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vibid.cli import main
from vibid.session import file_problems, read_session
from vibid.setup_model import Excitation, example_setup
from vibid.signal import afc_from_session

FREQS = tuple(float(f) for f in np.linspace(20.0, 400.0, 10))


def _write_setup(tmp_path, freqs=FREQS, settle_s=0.5):
    s = example_setup()
    s = replace(s, excitation=Excitation(freqs, settle_s))
    path = tmp_path / "setup.json"
    path.write_text(s.to_json())
    return path


def _write_stand(tmp_path, name, timing=None, drive=None, **simulated):
    # settling is free in virtual time: up to 40 s lets the 75 Hz mode (decay 1.4 s) ring
    # out below the noise wherever the runner finds a record unsettled
    doc = {
        "generator": {"url": f"vibidsim://{name}"},
        "timing": {"min_record_s": 0.1, "min_cycles": 10, "max_settle_s": 40.0, **(timing or {})},
        "drive": drive or {},
        "simulated": {"seed": 5, **simulated},
    }
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("ppm", [200.0, -200.0])
def test_simulated_campaign_afc_equals_the_virtual_specimens_h(tmp_path, capsys, ppm):
    from vibid.hardware_mocks.virtual_stand import lookup_stand

    name = f"afc{int(ppm)}"
    setup, stand_json = _write_setup(tmp_path), _write_stand(tmp_path, name, clock_offset_ppm=ppm)
    out = tmp_path / "s.h5"
    code = main(
        [
            "campaign",
            str(setup),
            "--stand",
            "simulated",
            "--stand-config",
            str(stand_json),
            "--out",
            str(out),
            "--operator",
            "T. Est",
            "--temperature-c",
            "22.5",
            "--record-only",
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.out.strip().startswith(f"{out}: complete, 10 of 10 steps; stand time ")
    lines = captured.err.strip().splitlines()
    assert (
        len(lines) == 10
        and lines[0].startswith("step 1/10  20 Hz  |H| ")
        and "\r" not in captured.err
    )
    virtual = lookup_stand(name)
    assert not virtual.instrument.output_on
    with read_session(out) as s:
        table = afc_from_session(s)
        assert s.operator == "T. Est" and s.step(0).temperature_c == 22.5
        steps = [(s.step_attributes(i)["settle_s"], s.step(i)) for i in range(len(s))]
        stand_time_s = s.stand_time_s
    # stand time: every step's settle and record, summed; the virtual stand's clock, which
    # runs only while the specimen settles or is recorded, ran exactly that long
    assert stand_time_s == pytest.approx(
        sum(t + st.n_samples / st.sample_rate_hz for t, st in steps), rel=1e-12
    )
    assert all(t >= 0.5 for t, _ in steps)  # the setup's settle_s is a floor
    assert stand_time_s == pytest.approx(virtual.clock.now_s(), rel=1e-12)
    assert f"stand time {stand_time_s:.1f} s" in captured.out
    truth = virtual.specimen.h(np.array(FREQS) * (1 + 1e-6 * ppm))  # at the frequency played
    assert table.used.all(), table.flags
    z = np.concatenate(
        [(table.H.real - truth.real) / table.std_re, (table.H.imag - truth.imag) / table.std_im]
    )
    assert np.max(np.abs(z)) < 4.5 and np.mean(z**2) < 3.0, z
    np.testing.assert_allclose(table.frequency_hz / np.array(FREQS) - 1, ppm * 1e-6, atol=2e-6)
    assert main(["validate", str(out)]) == 0
    assert (
        "valid session, 10 steps (10 ok), 20-400 Hz, declared model isotropic, run complete"
        in capsys.readouterr().out
    )


def test_bad_output_paths_are_refused_before_the_stand_opens(tmp_path, capsys):
    setup = _write_setup(tmp_path)
    stand_json = _write_stand(tmp_path, "badpath")
    missing = tmp_path / "no" / "s.h5"
    assert (
        main(
            [
                "campaign",
                str(setup),
                "--stand",
                "simulated",
                "--stand-config",
                str(stand_json),
                "--out",
                str(missing),
            ]
        )
        == 1
    )
    err = capsys.readouterr().err
    assert (
        err.strip()
        == f"vibid campaign: error: --out {missing}: the directory {missing.parent} does not exist"
    )
    existing = tmp_path / "exists.h5"
    existing.write_bytes(b"x")
    assert main(["campaign", str(setup), "--stand", "simulated", "--out", str(existing)]) == 1
    assert "already exists" in capsys.readouterr().err
    assert (
        main(
            [
                "campaign",
                str(setup),
                "--stand",
                "simulated",
                "--out",
                str(tmp_path / "none.h5"),
                "--resume",
            ]
        )
        == 1
    )
    assert "no such session file to resume" in capsys.readouterr().err
    assert (
        main(
            ["campaign", str(setup), "--stand", "ni", "--realtime", "--out", str(tmp_path / "x.h5")]
        )
        == 1
    )
    assert "--realtime" in capsys.readouterr().err
    from vibid.hardware_mocks.virtual_stand import _STANDS

    assert "badpath" not in _STANDS  # nothing was opened


def test_generator_fault_aborts_the_campaign_with_output_off(tmp_path, capsys):
    from vibid.hardware_mocks.virtual_stand import lookup_stand

    setup = _write_setup(tmp_path)
    stand_json = _write_stand(
        tmp_path, "fault", faults=[{"kind": "no_reply", "at_step": 3, "count": 5}]
    )
    out = tmp_path / "s.h5"
    code = main(
        [
            "campaign",
            str(setup),
            "--stand",
            "simulated",
            "--stand-config",
            str(stand_json),
            "--out",
            str(out),
            "--record-only",
        ]
    )
    captured = capsys.readouterr()
    assert code == 1
    assert captured.out.startswith(f"{out}: aborted, 3 of 10 steps (stand fault: ")
    assert not lookup_stand("fault").instrument.output_on
    assert file_problems(out) == []
    with read_session(out) as s:
        assert (len(s), s.run_status) == (3, "aborted") and s.run_status_reason.startswith(
            "stand fault: "
        )


def _cli(*args):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(Path(__file__).parent.parent / "src"), env.get("PYTHONPATH", "")]
    )
    return subprocess.Popen(
        [sys.executable, "-m", "vibid", "campaign", "--record-only", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL (POSIX)")
def test_killed_campaign_process_is_continued_by_resume(tmp_path, capsys):
    # between the first two modes (75 and 497 Hz) and with a short settle rule, so that the
    # real-time run takes a few seconds
    n = 16
    setup = _write_setup(
        tmp_path, tuple(float(f) for f in np.linspace(200.0, 380.0, n)), settle_s=0.05
    )
    stand_json = _write_stand(
        tmp_path, "killed", timing={"expected_loss_factor": 0.05, "max_settle_s": 1.0}
    )
    out = tmp_path / "s.h5"
    child = _cli(setup, "--stand", "simulated", "--stand-config", stand_json, "--out", out)
    for line in child.stderr:  # kill it as soon as it reported its third step
        if line.startswith(f"step 3/{n}"):
            break
    os.kill(child.pid, signal.SIGKILL)
    child.communicate(timeout=60)
    assert child.returncode == -signal.SIGKILL
    assert main(["validate", str(out)]) == 0
    assert "run interrupted" in capsys.readouterr().out
    with read_session(out) as s:
        n_killed = len(s)
    assert 3 <= n_killed < n, "the campaign ended before the kill"
    resumed = _cli(
        setup, "--stand", "simulated", "--stand-config", stand_json, "--out", out, "--resume"
    )
    stdout, stderr = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, stderr
    assert stdout.strip().startswith(f"{out}: complete, {n} of {n} steps; stand time ")
    assert stderr.strip().splitlines()[0].startswith(f"step {n_killed + 1}/{n}")
    reference = tmp_path / "reference.h5"
    assert (
        main(
            [
                "campaign",
                str(setup),
                "--stand",
                "simulated",
                "--stand-config",
                str(stand_json),
                "--out",
                str(reference),
                "--record-only",
            ]
        )
        == 0
    )
    with read_session(out) as a, read_session(reference) as b:
        assert a.run_status == "complete" and len(a) == len(b) == n
        for i in range(n_killed):  # what was recorded before the kill is the uninterrupted run's
            np.testing.assert_array_equal(a.step(i).response, b.step(i).response)
        ta, tb = afc_from_session(a), afc_from_session(b)
    # after the resume: the same specimen within the uncertainty. Not the same samples: the
    # resumed process switches the output on again, and the virtual stand's 497 Hz mode rings
    # after it (decay 0.21 s) through the first few steps, as a real plate would
    both = ta.used & tb.used
    assert both.sum() >= n - 2, (ta.flags, tb.flags)
    z = np.abs(ta.H - tb.H)[both] / np.hypot(ta.std, tb.std)[both]
    assert np.max(z) < 5.0, z


def test_q333_resonance_with_a_short_settle_is_flagged_and_the_q_based_settle_avoids_it(
    tmp_path, capsys
):
    """The virtual plate's first mode (75 Hz, loss factor 0.003: Q 333, decay time 1.4 s),
    played with a 0.02 s settle: with the damping settle switched off the signal stage flags
    the transient; with the runner's rule (up to 40 s of virtual settle) no step is flagged."""
    from vibid.hardware_mocks.virtual_stand import lookup_stand

    setup = _write_setup(tmp_path, (72.0, 74.0, 75.0, 76.0, 78.0), settle_s=0.02)
    tables = {}
    for name, timing in (("q-short", {"max_settle_s": 0.0}), ("q-rule", {})):
        # |H| reaches 125: a 1 m/s² base keeps the response (125 m/s², 13 g) in the 50 g range
        stand_json = _write_stand(
            tmp_path, name, timing=timing, drive={"target_base_m_s2": 1.0, "initial_vpp": 0.04}
        )
        out = tmp_path / f"{name}.h5"
        assert (
            main(
                [
                    "campaign",
                    str(setup),
                    "--stand",
                    "simulated",
                    "--stand-config",
                    str(stand_json),
                    "--out",
                    str(out),
                    "--record-only",
                ]
            )
            == 0
        )
        with read_session(out) as s:
            tables[name] = afc_from_session(s)
    f_n, _ = lookup_stand("q-rule").specimen.nearest_mode(75.0)
    assert abs(f_n - 75.0) < 0.2  # the step at 75 Hz sits on the resonance
    assert "unsettled" in tables["q-short"].flags[2]
    assert not any("unsettled" in f for f in tables["q-rule"].flags), tables["q-rule"].flags
    assert tables["q-rule"].used.all(), tables["q-rule"].flags
    truth = lookup_stand("q-rule").specimen.h(
        np.array([72.0, 74.0, 75.0, 76.0, 78.0]) * (1 + 40e-6)
    )
    t = tables["q-rule"]
    z = np.concatenate([(t.H.real - truth.real) / t.std_re, (t.H.imag - truth.imag) / t.std_im])
    assert np.max(np.abs(z)) < 4.5, z


def test_dry_run_prints_the_plan_without_opening_the_stand(tmp_path, capsys):
    setup = _write_setup(tmp_path, (20.0, 100.0, 1000.0), settle_s=0.5)
    out = tmp_path / "s.h5"
    assert main(["campaign", str(setup), "--stand", "ni", "--out", str(out), "--dry-run"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    # default timing: 20 cycles or 0.25 s of whole cycles at 25.6 kHz
    assert lines[:3] == [
        "step 1/3  20 Hz  settle 0.5 s  record 25600 samples (1 s)",
        "step 2/3  100 Hz  settle 0.5 s  record 6400 samples (0.25 s)",
        "step 3/3  1000 Hz  settle 0.5 s  record 6400 samples (0.25 s)",
    ]
    assert lines[3].startswith("3 steps: settle 1.5 s + record 1.5 s = at least 3 s")
    assert not out.exists()


def test_each_steps_progress_carries_its_uncertainty_and_its_stand_time(tmp_path):
    """What a live view draws after each step: H's std, and the step's settle and record
    time, which add up to the session's stand time."""
    from vibid.acquisition.campaign import run_campaign
    from vibid.acquisition.stand import open_stand
    from vibid.acquisition.stand_config import load_stand_config
    from vibid.identify import configure
    from vibid.setup_model import parse_setup

    configure()
    setup = parse_setup(_write_setup(tmp_path, FREQS[:4]).read_text())
    config = load_stand_config(_write_stand(tmp_path, "progress"))
    seen = []
    with open_stand("simulated", setup, config) as stand:
        result = run_campaign(setup, stand, str(tmp_path / "s.h5"), config, progress=seen.append)
    assert [p.index for p in seen] == [0, 1, 2, 3]
    with read_session(tmp_path / "s.h5") as s:
        table = afc_from_session(s)
    np.testing.assert_allclose([p.h_std for p in seen], table.std, rtol=1e-9)
    assert result.stand_time_s == pytest.approx(
        sum(p.settle_s + p.record_s for p in seen), rel=1e-12
    )
