"""Session writer/reader: round trip, live reading, and survival of a SIGKILL."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from vibid.errors import VibidError
from vibid.session import SessionWriter, file_problems, read_session
from vibid.setup_model import example_setup


def _records(rng, n=4096):
    return rng.standard_normal(n), rng.standard_normal(n).astype(np.float32)


def test_round_trip_gives_equal_setup_and_samples(tmp_path):
    rng = np.random.default_rng(1)
    setup = example_setup()
    path = tmp_path / "s.h5"
    written = []
    with SessionWriter(path, setup, session_id="abc") as w:
        for k, f in enumerate([5.0, 7.5, 1200.0]):
            base, resp = _records(rng, 1000 + k)
            status = "overload" if k == 1 else "ok"
            w.append(
                frequency_hz=f,
                sample_rate_hz=25600.0,
                base=base,
                response=resp,
                status=status,
                t0_utc="2026-11-22T04:00:00+00:00",
            )
            written.append((f, status, base, resp))
    assert file_problems(path) == []
    with read_session(path) as s:
        assert s.setup == setup
        assert s.session_id == "abc"
        assert s.run_status == "complete"
        assert len(s) == 3
        for step, (f, status, base, resp) in zip(s.steps(), written):
            assert step.frequency_hz == f and step.status == status
            assert step.sample_rate_hz == 25600.0 and step.t0_utc == "2026-11-22T04:00:00+00:00"
            np.testing.assert_array_equal(step.base, base)
            np.testing.assert_array_equal(step.response, resp.astype(np.float64))


def test_reader_sees_completed_steps_while_writer_is_open(tmp_path):
    rng = np.random.default_rng(2)
    path = tmp_path / "live.h5"
    w = SessionWriter(path, example_setup())
    for k in range(3):
        w.append(
            frequency_hz=10.0 + k,
            sample_rate_hz=25600.0,
            base=rng.standard_normal(100),
            response=rng.standard_normal(100),
        )
        with read_session(path) as s:  # a reader between steps never blocks the writer
            assert len(s) == k + 1
            assert s.run_status == "interrupted"  # as the spec reads a file without run_status
    w.close()


def test_bad_step_is_refused_and_nothing_recorded_is_lost(tmp_path):
    path = tmp_path / "s.h5"
    w = SessionWriter(path, example_setup())
    w.append(frequency_hz=10.0, sample_rate_hz=25600.0, base=np.ones(10), response=np.ones(10))
    with pytest.raises(VibidError, match="equal length"):
        w.append(frequency_hz=11.0, sample_rate_hz=25600.0, base=np.ones(10), response=np.ones(9))
    with pytest.raises(VibidError, match="status"):
        w.append(
            frequency_hz=11.0,
            sample_rate_hz=25600.0,
            base=np.ones(10),
            response=np.ones(10),
            status="fine",
        )
    with pytest.raises(VibidError, match="already exists"):
        SessionWriter(path, example_setup())
    with read_session(path) as s:
        assert len(s) == 1


CHILD = textwrap.dedent(
    """
    import sys, numpy as np
    from vibid.session import SessionWriter
    from vibid.setup_model import example_setup
    w = SessionWriter(sys.argv[1], example_setup())
    k = 0
    while True:
        rng = np.random.default_rng(k)
        w.append(frequency_hz=5.0 + k, sample_rate_hz=25600.0,
                 base=rng.standard_normal(20000), response=rng.standard_normal(20000))
        print(k, flush=True)
        k += 1
    """
)


def test_sigkill_mid_session_leaves_every_completed_step_readable(tmp_path):
    path = tmp_path / "killed.h5"
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, text=True
    )
    try:
        completed = -1
        deadline = time.monotonic() + 120
        while completed < 8 and time.monotonic() < deadline:
            line = child.stdout.readline()
            if not line:
                break
            completed = int(line)
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
    assert completed >= 8, "the child never got going"
    # Steps 0..completed were reported done before the kill; the writer may have finished more.
    assert file_problems(path) == []
    with read_session(path) as s:
        assert len(s) >= completed + 1
        assert s.run_status == "interrupted"  # it never closed: a crashed run is recognisable
        for step in s.steps():
            rng = np.random.default_rng(step.index)
            np.testing.assert_array_equal(step.base, rng.standard_normal(20000))
            np.testing.assert_array_equal(step.response, rng.standard_normal(20000))
    # and the campaign can go on after the crash
    w = SessionWriter.resume(path)
    n = w.n_steps
    w.append(frequency_hz=99.0, sample_rate_hz=25600.0, base=np.ones(5), response=np.ones(5))
    w.close()
    with read_session(path) as s:
        assert len(s) == n + 1 and s.run_status == "complete"


def test_leftover_partial_step_is_not_a_step(tmp_path):
    """A crash inside a step leaves its partial group outside /steps; the reader ignores it."""
    path = tmp_path / "s.h5"
    w = SessionWriter(path, example_setup())
    w.append(frequency_hz=10.0, sample_rate_hz=25600.0, base=np.ones(10), response=np.ones(10))
    with h5py.File(path, "a") as f:
        g = f.create_group("_vibid_partial_step")
        g.create_dataset("base", data=np.ones(3))
    assert file_problems(path) == []
    with read_session(path) as s:
        assert len(s) == 1
    w2 = SessionWriter.resume(path)
    with h5py.File(path, "r") as f:
        assert "_vibid_partial_step" not in f
    assert w2.n_steps == 1
