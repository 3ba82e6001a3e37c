"""The watchdog: a computation that stops moving ends the command with one line.

Injected stalls, not timings: a stage that never beats again (a thread parked on an event,
where issue 62's deadlock parked the fit's Hessian in native code), one that beats, and
the process outside every stage. The last test runs ``vibid identify`` in a child process
whose Hessian blocks forever, the deadlock's own Python frame, and reads its one line,
exit code and stacks file.
"""

import json
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from vibid import heartbeat
from vibid.setup_model import example_setup

REPO = Path(__file__).resolve().parents[1]


def _watch(limit_s, folder):
    fired = []
    dog = heartbeat.Watchdog(
        limit_s,
        lambda: folder,
        "vibid test",
        on_stall=lambda line, path: fired.append((line, path)),
        poll_s=0.02,
    )
    return dog, fired


def _parked_forever(release: threading.Event):
    release.wait(30)  # the stall: no beat while parked


def test_a_stage_without_beats_ends_with_its_name_and_the_stacks(tmp_path):
    dog, fired = _watch(0.3, tmp_path)
    release = threading.Event()
    with dog, heartbeat.stage("closed loop"), heartbeat.stage("local fits"):
        t = threading.Thread(target=_parked_forever, args=(release,))
        t.start()
        deadline = time.monotonic() + 20
        while not fired and time.monotonic() < deadline:
            time.sleep(0.05)
        release.set()
        t.join()
    assert len(fired) == 1
    line, path = fired[0]
    assert "\n" not in line
    assert "in 'local fits' (closed loop > local fits); ended" in line
    assert str(tmp_path / heartbeat.STACKS_FILE) in line
    stacks = Path(path).read_text()
    assert "_parked_forever" in stacks  # the parked thread's frame
    assert "test_a_stage_without_beats" in stacks  # the main thread's


def test_beats_keep_it_quiet():
    dog, fired = _watch(0.3, ".")
    with dog, heartbeat.stage("local fits"):
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.0:  # three limits long, a beat every 50 ms
            heartbeat.beat()
            time.sleep(0.05)
    assert fired == []


def test_outside_every_stage_it_never_fires():
    dog, fired = _watch(0.2, ".")
    with dog:
        time.sleep(0.8)
        with heartbeat.stage("identify"):  # a stage opened after a long idle starts fresh
            time.sleep(0.05)
    assert fired == []


@pytest.mark.parametrize(
    "raw, expected", [(None, heartbeat.DEFAULT_LIMIT_S), ("0", 0.0), ("2.5", 2.5)]
)
def test_the_limit(raw, expected, monkeypatch):
    monkeypatch.delenv("VIBID_STALL_TIMEOUT_S", raising=False)
    assert heartbeat.limit_from(raw) == expected
    monkeypatch.setenv("VIBID_STALL_TIMEOUT_S", "7")
    assert heartbeat.limit_from(raw) == (7.0 if raw is None else expected)


@pytest.mark.parametrize("raw", ["nan", "-1", "inf", "soon"])
def test_a_bad_limit_is_one_line(raw):
    with pytest.raises(ValueError) as err:
        heartbeat.limit_from(raw)
    assert "\n" not in str(err.value)


CHILD = textwrap.dedent("""
    import sys, threading
    from vibid.identify.engine import persist

    call = persist.Persisted._call

    def parked(self, *args):  # the deadlock's frame: the compiled Hessian never returns
        if self.name == "problem.hessian":
            threading.Event().wait()
        return call(self, *args)

    persist.Persisted._call = parked
    from vibid.cli import main
    sys.exit(main(sys.argv[1:]))
""")


def test_identify_whose_hessian_never_returns_ends_in_one_line(tmp_path):
    setup = tmp_path / "setup.json"
    setup.write_text(example_setup().to_json())
    report = tmp_path / "report"
    cmd = [
        sys.executable,
        "-c",
        CHILD,
        "--stall-timeout",
        "5",
        "identify",
        "--afc",
        str(REPO / "tests/data/adaptive_strip_afc.csv"),
        "--setup",
        str(setup),
        "--json",
        str(tmp_path / "r.json"),
        "--report",
        str(report),
        "--no-loop",
    ]
    done = subprocess.run(
        cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False
    )
    # the progress bars (tqdm, on stderr) then the one line
    lines = [
        x
        for x in done.stderr.replace("\r", "\n").splitlines()
        if x.strip() and not x.startswith("global search:")
    ]
    assert done.returncode == 1, done.stderr[-2000:]
    assert len(lines) == 1, lines
    assert lines[0].startswith("vibid identify: error: no progress for 5 s in ")
    assert "'problem.hessian' (local fits > problem.hessian)" in lines[0]
    assert lines[0].endswith(
        "'identify'; ended: the Python stacks are in "
        f"{report / heartbeat.STACKS_FILE} (set the limit with "
        "--stall-timeout S)"
    )
    assert "Traceback" not in done.stderr
    stacks = (report / heartbeat.STACKS_FILE).read_text()
    assert "in parked" in stacks and "hessian" in stacks
    assert not (tmp_path / "r.json").exists() or json.loads((tmp_path / "r.json").read_text())
