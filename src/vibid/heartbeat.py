"""Progress beats, and a watchdog that ends a command whose computation has stopped moving.

A lab leaves vibid running on a measurement and comes back to an answer: a computation that
stops making progress (a native call that never returns, a loop that never ends) must end
the command with one line, not sit until somebody kills it. The numerical code says where
it is and that it moves; the command line decides what to do when it stops:

* :func:`stage` (a context manager) names what runs now, "local fits", "closed loop"
  (:func:`vibid.identify.engine.profile.section` opens one for every section it times), and
  :func:`beat` says "still moving" (every evaluation of a fit's model, every finished
  stage). Both cost a clock read and a dict update: the fits call them thousands of times.
* :class:`Watchdog` (a daemon thread, started by ``vibid``'s entry point,
  :func:`vibid.cli.main`) watches the beats while a stage is open. After ``limit_s`` seconds
  without one it writes every thread's Python stack to a file, prints one line naming the
  open stages and the file, and ends the process with exit code 1: the thread that hangs
  sits in native code and cannot be interrupted from Python, so the process is ended from
  the side (``os._exit``). Outside every stage (a campaign's acquisition, whose instruments
  have their own time-outs and whose generator must be switched off by its own code) the
  watchdog never fires.

The limit is ``vibid --stall-timeout S`` or ``$VIBID_STALL_TIMEOUT_S`` (default
:data:`DEFAULT_LIMIT_S`; 0 switches the watchdog off). This module imports the standard
library only, so any layer may beat.
"""

from __future__ import annotations

import contextlib
import faulthandler
import math
import os
import sys
import threading
import time
import traceback
from pathlib import Path

#: Seconds without progress after which a command is ended (issue 62: 10 minutes; the
#: longest single step vibid takes, a plate's wide reduced basis, is seconds).
DEFAULT_LIMIT_S = 600.0
#: The file the stacks go to, in the folder the command writes its report to.
STACKS_FILE = "vibid-stall-stacks.txt"

_lock = threading.Lock()
_last_beat = time.monotonic()
#: thread id -> its open stages ``(name, monotonic time entered)``, outermost first
_open: dict[int, list[tuple[str, float]]] = {}


def beat() -> None:
    """The computation moved: restart the watchdog's clock."""
    global _last_beat
    _last_beat = time.monotonic()


@contextlib.contextmanager
def stage(name: str):
    """``with stage("local fits"):`` names what runs inside, for the watchdog's message;
    entering and leaving a stage are beats."""
    ident = threading.get_ident()
    with _lock:
        _open.setdefault(ident, []).append((name, time.monotonic()))
    beat()
    try:
        yield
    finally:
        with _lock:
            names = _open.get(ident)
            if names:
                names.pop()
                if not names:
                    del _open[ident]
        beat()


def open_stages() -> list[list[str]]:
    """Each thread's open stages' names, outermost first; the deepest first (a thread that
    waits for others, the command's main thread, sits in an outer stage), then the one
    whose innermost stage has been open longest."""
    with _lock:
        held = [list(v) for v in _open.values() if v]
    held.sort(key=lambda v: (-len(v), v[-1][1]))
    return [[name for name, _ in v] for v in held]


def since_beat_s() -> float:
    return time.monotonic() - _last_beat


def limit_from(value=None) -> float:
    """The watchdog's limit, seconds: ``value`` (a command line's), else
    ``$VIBID_STALL_TIMEOUT_S``, else :data:`DEFAULT_LIMIT_S`; 0 means off. A one-line
    ValueError for anything that is not a non-negative finite number of seconds."""
    raw = value if value is not None else os.environ.get("VIBID_STALL_TIMEOUT_S")
    if raw is None or raw == "":
        return DEFAULT_LIMIT_S
    try:
        limit = float(raw)
    except (TypeError, ValueError):
        raise ValueError(f"the stall time-out must be a number of seconds, got {raw!r}") from None
    if not math.isfinite(limit) or limit < 0:
        raise ValueError(
            f"the stall time-out must be a finite number of seconds >= 0 (0: off), got {raw!r}"
        )
    return limit


def describe(stages: list[list[str]]) -> str:
    """The open stages for the watchdog's line, each thread's as ``'inner' (outer > inner)``:
    ``'problem.hessian' (local fits > problem.hessian); 'identify'``. Every thread's is
    named: which one stopped first cannot be told from the outside (a thread waiting for
    the one that hangs, for its result or for the right to run compiled code, looks the
    same); the stacks file shows where each one sits."""
    if not stages:
        return "no stage"
    parts = []
    for names in stages:
        part = f"'{names[-1]}'"
        if len(names) > 1:
            part += f" ({' > '.join(names)})"
        parts.append(part)
    return "; ".join(parts)


def write_stacks(path: Path) -> None:
    """Every thread's Python stack (and faulthandler's view of it) into ``path``."""
    frames = sys._current_frames()
    names = {t.ident: t.name for t in threading.enumerate()}
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"vibid: no progress for {since_beat_s():.0f} s; open stages: {open_stages()}\n\n")
        for ident, frame in frames.items():
            f.write(f"--- thread {names.get(ident, '?')} ({ident}) ---\n")
            f.write("".join(traceback.format_stack(frame)))
            f.write("\n")
        f.flush()
        f.write("--- faulthandler ---\n")
        f.flush()
        faulthandler.dump_traceback(file=f, all_threads=True)


class Watchdog:
    """A daemon thread that ends the process when an open stage sees no beat for
    ``limit_s`` seconds (module doc).

    ``folder()`` gives the folder for the stacks file when it fires (called then: the
    command's report folder may not exist when it starts); ``prefix`` starts the line
    (``"vibid identify"``); ``on_stall(line, path)`` replaces the exit (tests)."""

    def __init__(
        self,
        limit_s: float,
        folder,
        prefix: str = "vibid",
        on_stall=None,
        poll_s: float | None = None,
    ):
        self.limit_s = float(limit_s)
        self.folder = folder
        self.prefix = prefix
        self.on_stall = on_stall
        self.poll_s = poll_s if poll_s is not None else min(5.0, max(0.05, limit_s / 20))
        self._stop = threading.Event()
        self._thread = None

    def start(self) -> Watchdog:
        if self.limit_s > 0:
            beat()
            self._thread = threading.Thread(target=self._run, name="vibid-watchdog", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            stages = open_stages()
            if not stages:
                beat()  # outside every stage the clock does not run
                continue
            if since_beat_s() >= self.limit_s:
                self._fire(stages)
                return

    def _fire(self, stages) -> None:
        try:
            where = Path(self.folder() or ".")
            where.mkdir(parents=True, exist_ok=True)
            path = where / STACKS_FILE
            write_stacks(path)
        except Exception as exc:  # noqa: BLE001 - the line must come out whatever happens
            path = f"(not written: {exc})"
        line = (
            f"{self.prefix}: error: no progress for {self.limit_s:g} s in "
            f"{describe(stages)}; ended: the Python stacks are in {path} (set the "
            f"limit with --stall-timeout S)"
        )
        if self.on_stall is not None:
            self.on_stall(line, path)
            return
        print(f"\n{line}", file=sys.stderr, flush=True)  # after a progress bar's line
        sys.stdout.flush()
        os._exit(1)
