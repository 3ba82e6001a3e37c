"""A guard against a hang, not a speed threshold: one whole `vibid identify` with the
closed loop, on a session whose model takes the reduced model's direct path (a lossy
elastic clamp: the complex LU solve that deadlocked jaxlib's two-thread pool, issue 62),
on two threads, in a fresh process, under a limit of minutes where it takes about one.
The many-run version is ``benchmarks/stress_hang.py``.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
LIMIT_S = 600  # about ten times the run; only a hang reaches it


@pytest.mark.slow
def test_a_loop_on_the_direct_path_ends(tmp_path):
    setup = json.loads((REPO / "examples/strip_setup.json").read_text())
    setup["excitation"]["frequencies_hz"] = setup["excitation"]["frequencies_hz"][::4]
    (tmp_path / "setup.json").write_text(json.dumps(setup))
    env = dict(os.environ, VIBID_THREADS="2")
    session = tmp_path / "s.h5"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "vibid",
            "simulate",
            str(tmp_path / "setup.json"),
            "--out",
            str(session),
            "--effect",
            "clamp_compliance:k_theta_N_per_rad=16000",
            "clamp_loss:beta_clamp=0.05",
            "--seed",
            "3",
        ],
        check=True,
        capture_output=True,
        env=env,
        timeout=LIMIT_S,
    )
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "vibid",
            "--stall-timeout",
            "300",
            "identify",
            str(session),
            "--json",
            str(tmp_path / "r.json"),
            "--candidates",
            "clamp_compliance,clamp_loss,channel_delay",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=LIMIT_S,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-1500:]
    report = json.loads((tmp_path / "r.json").read_text())
    assert len(report["loop"]["stages"]) >= 2  # the loop ran a round and added an effect
    assert "clamp_compliance" in [e["name"] for e in report["effects"]]
