"""Prefect's temporary server ends with the process that started it (vibid.flows.server).

A process that calls :func:`~vibid.flows.server.tie_temporary_server` and then starts a
child the way Prefect starts its server is killed with SIGKILL: the child must end too
(before the tie, a SIGKILLed campaign left its uvicorn server running for good)."""

import os
import signal
import subprocess
import sys
import time

import pytest

CHILD = """
import sys
from vibid.flows.server import tie_temporary_server
tied = tie_temporary_server()
from prefect.server.api import server
child = server.subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
print(tied, child.pid, flush=True)
time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="prctl(PR_SET_PDEATHSIG) is Linux's"
)
@pytest.mark.parametrize("tie", [True, False])
def test_a_server_started_after_the_tie_dies_with_its_killed_parent(tie):
    code = CHILD.replace(
        "tied = tie_temporary_server()", "tied = tie_temporary_server()" if tie else "tied = False"
    )
    parent = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        tied, pid = parent.stdout.readline().split()
        pid = int(pid)
        assert tied == str(tie) and _alive(pid)
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(timeout=10)
        deadline = time.monotonic() + 5
        while _alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _alive(pid) is (not tie)  # untied, the child stays: the leak the tie closes
    finally:
        try:
            os.killpg(parent.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
