"""Prefect's temporary server goes when the process that started it goes.

Where no ``PREFECT_API_URL`` names a server, Prefect 3 starts a temporary one as a child
process (uvicorn) and stops it at exit, from an ``atexit`` hook. A process killed with
SIGKILL runs no hook: its server stays, and a campaign resumed after every crash leaves one
more each time (seen in the soak: :mod:`vibid.soak`). On Linux the kernel
signals a child when the thread that started it ends (``prctl(PR_SET_PDEATHSIG)``):
:func:`tie_temporary_server` has Prefect start that server asking for SIGTERM then, where
it is started from the main thread (whose end is the process's); elsewhere nothing changes.
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import threading

__all__ = ["tie_temporary_server"]

#: prctl option: the signal the calling process gets when its parent thread ends
PR_SET_PDEATHSIG = 1


def _dies_with(parent_pid: int):
    """A ``preexec_fn`` (it runs in the child, before the server starts): SIGTERM when the
    parent goes; and exit now if it has gone already (it died between fork and here)."""

    def preexec() -> None:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        if os.getppid() != parent_pid:
            os._exit(1)

    return preexec


class _Subprocess:
    """The :mod:`subprocess` module as Prefect's server module sees it, but whose ``Popen``
    from the main thread starts a child that dies with this process."""

    def __getattr__(self, name):
        return getattr(subprocess, name)

    @staticmethod
    def Popen(*args, **kwargs):  # noqa: N802 - subprocess's own name
        if threading.current_thread() is threading.main_thread() and "preexec_fn" not in kwargs:
            kwargs["preexec_fn"] = _dies_with(os.getpid())
        return subprocess.Popen(*args, **kwargs)


def tie_temporary_server() -> bool:
    """Make Prefect's temporary server (``prefect.server.api.server.SubprocessASGIServer``,
    Prefect 3.8) end with this process. True where it now will (Linux), False elsewhere.
    Call it before the first flow runs; calling it again changes nothing."""
    if not sys.platform.startswith("linux"):
        return False
    from prefect.server.api import server

    if not isinstance(server.subprocess, _Subprocess):
        server.subprocess = _Subprocess()
    return True
