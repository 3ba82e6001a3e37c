"""Crash safety of a campaign (issue #12, part 5): a campaign process killed with SIGKILL at
every write phase of the session file, and at random instants, leaves a file that validates
(``interrupted``), holds every completed step, and that ``resume`` completes into the very
steps of an uninterrupted run (samples and attributes, ``t0_utc`` aside).

The child is ``tests/campaign_fakes.py`` run as a script: the campaign on the fake stand,
seeded, 10 steps of short records (about a second per process, most of it imports).
"""

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
from campaign_fakes import fake_stand, fast_config, short_setup  # noqa: E402
from test_campaign import assert_same_steps  # noqa: E402
from vibid.acquisition.campaign import run_campaign  # noqa: E402
from vibid.cli import main  # noqa: E402
from vibid.session import file_problems, read_session  # noqa: E402
from vibid.session.writer import KILL_AT_ENV, WRITE_PHASES  # noqa: E402

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL (POSIX)")

N_STEPS = 10


def _env(kill_at=None):
    env = dict(os.environ)
    src = str(HERE.parent / "src")
    env["PYTHONPATH"] = os.pathsep.join([src, str(HERE), env.get("PYTHONPATH", "")])
    env.pop(KILL_AT_ENV, None)
    if kill_at:
        env[KILL_AT_ENV] = kill_at
    return env


def _child(out, *args, kill_at=None):
    return subprocess.Popen(
        [sys.executable, str(HERE / "campaign_fakes.py"), str(out), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(kill_at),
    )


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted run, in this process (the child's arithmetic is the same)."""
    path = tmp_path_factory.mktemp("ref") / "reference.h5"
    run_campaign(short_setup(), fake_stand(seed=7), path, fast_config())
    return path


def _check_killed_file_and_resume(path, reference, capsys):
    """The file validates as interrupted (or complete), resume completes it, steps equal."""
    assert file_problems(path) == []
    assert main(["validate", str(path)]) == 0
    line = capsys.readouterr().out
    with read_session(path) as s:
        n, status = len(s), s.run_status
    assert status in ("interrupted", "complete") and (status == "complete") == (n == N_STEPS), line
    if not (status == "complete" and n == N_STEPS and _closed(path)):
        result = run_campaign(short_setup(), fake_stand(seed=7), path, fast_config(), resume=True)
        assert (result.run_status, result.n_steps) == ("complete", N_STEPS)
    assert not os.path.exists(str(path) + ".vibid-tmp")
    assert_same_steps(path, reference)
    with read_session(path) as s:
        assert s.run_status == "complete" and s.run_status_written
    return n


def _closed(path):
    with read_session(path) as s:
        return s.run_status_written


KILL_POINTS = [
    f"{tag}:{phase}"
    for tag in ("create", "step0", "step5", "step9", "close")
    for phase in WRITE_PHASES
    if not (tag == "create" and phase == "after_copy")
]


@pytest.mark.parametrize("kill_at", KILL_POINTS)
def test_kill_at_every_write_phase_leaves_a_valid_file_that_resume_completes(
    tmp_path, reference, capsys, kill_at
):
    out = tmp_path / "s.h5"
    child = _child(out, kill_at=kill_at)
    stdout, stderr = child.communicate(timeout=120)
    assert child.returncode == -signal.SIGKILL, stderr
    tag, phase = kill_at.split(":")
    if tag == "create" and phase != "after_replace":
        assert not out.exists()  # killed before the file existed: nothing was recorded
        run_campaign(short_setup(), fake_stand(seed=7), out, fast_config())
        assert_same_steps(out, reference)
        return
    completed = [int(x) for x in stdout.split() if x.isdigit()]
    n = _check_killed_file_and_resume(out, reference, capsys)
    expected = {"create": 0, "step0": 0, "step5": 5, "step9": 9, "close": N_STEPS}[tag]
    assert n == expected + (phase == "after_replace" and tag.startswith("step"))
    # every step reported done was in the file; the step being committed may be in it too
    assert completed == list(range(expected))


def test_kill_in_a_resumed_campaign_then_resume_again(tmp_path, reference, capsys):
    out = tmp_path / "s.h5"
    child = _child(out, kill_at="step3:after_replace")
    child.communicate(timeout=120)
    assert child.returncode == -signal.SIGKILL
    # an interrupted close leaves run_status written: the resume's own write is a phase too
    result = run_campaign(
        short_setup(),
        fake_stand(seed=7, fail_at=(5, KeyboardInterrupt())),
        out,
        fast_config(),
        resume=True,
    )
    assert (result.run_status, result.n_steps) == ("interrupted", 5)
    for kill_at in ("resume:after_write", "step7:after_fsync"):
        child = _child(out, "--resume", kill_at=kill_at)
        child.communicate(timeout=120)
        assert child.returncode == -signal.SIGKILL
        assert file_problems(out) == []
    with read_session(out) as s:
        assert len(s) == 7 and s.run_status == "interrupted"
    _check_killed_file_and_resume(out, reference, capsys)


@pytest.fixture(scope="module")
def campaign_seconds(tmp_path_factory):
    """How long the child's campaign takes, uninterrupted (after its imports)."""
    out = tmp_path_factory.mktemp("timing") / "s.h5"
    child = _child(out)
    stdout, stderr = child.communicate(timeout=120)
    assert child.returncode == 0, stderr
    done = stdout.split("done")[1].split()
    assert done[:2] == ["complete", str(N_STEPS)]
    return float(done[2])


@pytest.mark.parametrize("draw", range(20))
def test_sigkill_at_a_random_instant_leaves_a_valid_file_that_resume_completes(
    tmp_path, reference, capsys, campaign_seconds, draw
):
    rng = np.random.default_rng(1000 + draw)
    out = tmp_path / "s.h5"
    delay_s = float(rng.uniform(0.0, 0.95 * campaign_seconds))
    for _ in range(6):  # a busy machine may run faster or slower than timed: halve until it hits
        child = _child(out)
        assert child.stdout.readline().strip() == "ready"
        try:
            child.wait(timeout=delay_s)
        except subprocess.TimeoutExpired:
            os.kill(child.pid, signal.SIGKILL)
        child.communicate(timeout=120)
        if child.returncode != 0:
            break
        out.unlink()
        delay_s /= 2
    assert child.returncode == -signal.SIGKILL
    if not out.exists():  # killed before the header was in place
        return
    _check_killed_file_and_resume(out, reference, capsys)


def test_sigterm_ends_the_campaign_like_ctrl_c(tmp_path, reference, capsys):
    out = tmp_path / "s.h5"
    child = _child(out, "--slow")  # a second in all: the signal comes while it runs
    assert child.stdout.readline().strip() == "ready"
    assert child.stdout.readline().strip() == "0"  # the first step is written
    os.kill(child.pid, signal.SIGTERM)
    stdout, stderr = child.communicate(timeout=120)
    assert child.returncode == 0, stderr  # the campaign returned: the file was closed
    assert "done interrupted" in stdout
    with read_session(out) as s:
        assert s.run_status == "interrupted" and s.run_status_reason == "stopped by SIGTERM"
        assert 1 <= len(s) < N_STEPS
    _check_killed_file_and_resume(out, reference, capsys)
