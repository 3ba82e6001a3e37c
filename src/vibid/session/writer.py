"""Write a session file one step at a time, so that every completed step survives a crash.

Why not write the file in place: HDF5 keeps its metadata (B-trees, heaps, the superblock) in
a cache that it flushes in several writes, so a process killed in the middle of a flush
(SIGKILL, a power cut) can leave a file that no longer opens. And SWMR, which is made for
live files, only lets a writer append to datasets that exist already, while the format stores
each step as a new group.

So the file at ``path`` is never modified in place. Each change (the header, a step, the
closing status) is made on a copy beside it, ``<path>.vibid-tmp``: the copy is written,
closed, fsynced, and atomically renamed over ``path`` (``os.replace``), then the directory is
fsynced. At every instant ``path`` is either the file before the change or the file after it,
complete and closed: a reader (opening without a lock) never sees a half-written step, a
process killed at any instant leaves a valid file holding every completed step, and old
readers keep the inode they opened. A leftover ``<path>.vibid-tmp`` is only ever an unfinished
copy and is deleted when the session is reopened.

Cost: one copy of the file per step (measured: 200 steps of 6 400 samples per channel, a
21 MB file in the end, 2.3 s of copying in all, 4.5 s with the fsyncs, on the project's
machine). On Windows ``os.replace`` fails while another program holds ``path`` open; the
writer retries for a few seconds and then says so in one line (nothing recorded is lost:
the step stays in memory of the caller, and the file holds every earlier step).

How the session ended is written when it is closed (``run_status``, ``run_status_reason``;
shared/spec/session-format.md, "How a session ends"); while it runs the file has no
``run_status``, which the format reads as ``interrupted`` if it stops there.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import time
import uuid
from collections.abc import Callable
from datetime import UTC, datetime

import h5py
import numpy as np

from vibid import __version__
from vibid.errors import VibidError
from vibid.session import format as fmt
from vibid.setup_model import Setup

#: Environment variable naming a write phase at which the process kills itself with SIGKILL
#: (crash-safety tests): ``step<index>:<phase>``, e.g. ``step3:after_fsync``; see
#: :data:`WRITE_PHASES`.
KILL_AT_ENV = "VIBID_KILL_AT"
#: The phases of one change of the file, in order.
WRITE_PHASES = ("before_copy", "after_copy", "after_write", "after_fsync", "after_replace")
_TMP_SUFFIX = ".vibid-tmp"


def utc_now() -> str:
    """The current UTC time in ISO 8601, microseconds included."""
    return datetime.now(UTC).isoformat()


class SessionWriter:
    """Create a session file and append steps to it.

    Parameters
    ----------
    path : the file to create (it must not exist).
    setup : the declared setup, stored as the ``setup`` JSON attribute.
    session_id : defaults to a new UUID4.
    created_utc : defaults to now.
    software : defaults to ``vibid <version>``.
    operator, notes : optional free-text root attributes of the format.
    adaptive : the ``adaptive`` root attribute (a dict: target, band, cap, batch size, seed)
        of a campaign that chooses its frequencies as it goes. The setup's excitation then
        lists the steps recorded so far (:func:`recorded_setup`), rewritten with each step
        in the same atomic change; the file is created with its first step (a setup lists
        at least one frequency), so an adaptive campaign stopped before it leaves no file.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        setup: Setup,
        *,
        session_id: str | None = None,
        created_utc: str | None = None,
        software: str | None = None,
        operator: str | None = None,
        notes: str | None = None,
        adaptive: dict | None = None,
    ):
        self.path = os.fspath(path)
        if os.path.exists(self.path):
            raise VibidError(f"{self.path}: already exists; a session file is never overwritten")
        if setup.excitation is None:
            raise VibidError(
                "a session needs the setup's excitation (the stepped sine it "
                "records); only an imported AFC's setup leaves it out"
            )
        self.setup = setup
        self.session_id = session_id or str(uuid.uuid4())
        self.n_steps = 0
        self.adaptive = None if adaptive is None else dict(adaptive)
        #: an adaptive session's steps so far, Hz (its setup's excitation)
        self.recorded_hz: list[float] = []
        _remove(self._tmp)

        def header(f: h5py.File) -> None:
            f.attrs["format"] = fmt.FORMAT
            f.attrs["format_version"] = np.int64(fmt.FORMAT_VERSION)
            f.attrs["created_utc"] = created_utc or utc_now()
            f.attrs["session_id"] = self.session_id
            f.attrs["software"] = software or f"vibid {__version__}"
            _write_setup(f, setup)
            for name, value in (("operator", operator), ("notes", notes)):
                if value is not None:
                    f.attrs[name] = str(value)
            if self.adaptive is not None:
                f.attrs[fmt.ADAPTIVE] = json.dumps(self.adaptive, sort_keys=True)
            f.create_group(fmt.STEPS_GROUP)

        #: the header not yet written (an adaptive session's, written with its first step)
        self._header: Callable[[h5py.File], None] | None = None
        if self.adaptive is None:
            self._commit(header, phase_tag="create", create=True)
        else:
            self._header = header

    @property
    def _tmp(self) -> str:
        return self.path + _TMP_SUFFIX

    @classmethod
    def resume(cls, path: str | os.PathLike) -> SessionWriter:
        """Reopen an existing session (e.g. after a crash) to append further steps.

        The file is running again: its ``run_status`` is removed until :meth:`close`.
        """
        self = cls.__new__(cls)
        self.path = os.fspath(path)
        _remove(self._tmp)
        from vibid.session.reader import read_session

        with read_session(self.path) as s:  # a damaged file: one line, nothing written
            self.setup, self.session_id, self.n_steps = s.setup, s.session_id, len(s)
            self.adaptive = s.adaptive
            self.recorded_hz = [float(v) for v in s.frequencies_hz()]  # the steps: the truth
        self._header = None
        with h5py.File(self.path, "r", locking=False) as f:
            stale = fmt.PARTIAL_STEP in f or any(a in f.attrs for a in fmt.RUN_STATUS_ATTRS)

        def reopen(f: h5py.File) -> None:
            if fmt.PARTIAL_STEP in f:  # left by vibid before the writes became atomic
                del f[fmt.PARTIAL_STEP]
            for name in fmt.RUN_STATUS_ATTRS:
                if name in f.attrs:
                    del f.attrs[name]

        if stale:
            self._commit(reopen, phase_tag="resume")
        return self

    @property
    def exists(self) -> bool:
        """Whether the file is there (an adaptive session's is created with its first step)."""
        return self._header is None

    def append(
        self,
        *,
        frequency_hz: float,
        sample_rate_hz: float,
        base: np.ndarray,
        response: np.ndarray,
        status: str = "ok",
        t0_utc: str | None = None,
        temperature_c: float | None = None,
        settle_s: float | None = None,
        extra_attrs: dict | None = None,
    ) -> int:
        """Write one complete step and return its index. Nothing is written if it is invalid.

        ``temperature_c`` (°C) and ``settle_s`` (s the drive ran at this frequency before the
        first sample) are the format's optional step attributes; ``extra_attrs`` are vibid's
        own step attributes (names starting with ``vibid_``).
        """
        base = np.asarray(base)
        response = np.asarray(response)
        if status not in fmt.STEP_STATUSES:
            raise VibidError(f"step status {status!r} is not one of {', '.join(fmt.STEP_STATUSES)}")
        if base.ndim != 1 or response.shape != base.shape or base.size == 0:
            raise VibidError(
                f"step records must be 1-D and of equal length, got {base.shape} and {response.shape}"
            )
        extra = dict(extra_attrs or {})
        if bad := [k for k in extra if not k.startswith("vibid_")]:
            raise VibidError(f"own step attributes must start with 'vibid_': {', '.join(bad)}")
        index = self.n_steps

        def add_step(f: h5py.File) -> None:
            g = f.create_group(f"{fmt.STEPS_GROUP}/{fmt.step_name(index)}")
            g.attrs["frequency_hz"] = float(frequency_hz)
            g.attrs["sample_rate_hz"] = float(sample_rate_hz)
            g.attrs["t0_utc"] = t0_utc or utc_now()
            g.attrs["status"] = status
            if temperature_c is not None:
                g.attrs["temperature_c"] = float(temperature_c)
            if settle_s is not None:
                g.attrs[fmt.SETTLE_S] = float(settle_s)
            for name, value in extra.items():
                g.attrs[name] = value
            # one chunk per record, with a checksum (a flipped sample is refused, not
            # fitted) and a NaN fill (a chunk whose address is lost reads as NaN, refused)
            for label, x in (("base", base), ("response", response)):
                g.create_dataset(
                    label, data=_float_samples(x), chunks=x.shape, fletcher32=True, fillvalue=np.nan
                )

        change, create = add_step, False
        if self.adaptive is not None:
            # the setup lists the steps recorded, this one too; the first step brings the header
            recorded, header = self.recorded_hz + [float(frequency_hz)], self._header

            def with_setup(f: h5py.File) -> None:
                if header is not None:
                    header(f)
                add_step(f)
                _write_setup(f, recorded_setup(self.setup, recorded))

            change, create = with_setup, header is not None
        self._commit(change, phase_tag=f"step{index}", create=create)
        self._header = None
        if self.adaptive is not None:
            self.recorded_hz = recorded
        self.n_steps += 1
        return index

    def close(self, run_status: str = "complete", reason: str | None = None) -> None:
        """Write how the session ended: ``complete``, ``interrupted`` or ``aborted``, with a
        one-line ``reason`` when it is not complete, and its stand time (:func:`vibid.session.format.stand_time_s`).
        The file stays valid either way."""
        if run_status not in fmt.RUN_STATUSES:
            raise VibidError(
                f"run status {run_status!r} is not one of {', '.join(fmt.RUN_STATUSES)}"
            )
        if not self.exists:
            self.stand_time_s = None
            return  # an adaptive session that recorded no step: there is no file to close

        def mark(f: h5py.File) -> None:
            f.attrs[fmt.RUN_STATUS] = run_status
            if reason:
                f.attrs[fmt.RUN_STATUS_REASON] = " ".join(str(reason).split())
            elif fmt.RUN_STATUS_REASON in f.attrs:
                del f.attrs[fmt.RUN_STATUS_REASON]
            if fmt.LEGACY_RUN_STATUS in f.attrs:
                del f.attrs[fmt.LEGACY_RUN_STATUS]
            self.stand_time_s = fmt.stand_time_s(f)
            if self.stand_time_s is not None:
                f.attrs[fmt.STAND_TIME_S] = self.stand_time_s

        self._commit(mark, phase_tag="close")

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close("complete")
        elif issubclass(exc_type, KeyboardInterrupt):
            self.close("interrupted", "interrupted by the operator")
        else:
            self.close("aborted", f"{exc_type.__name__}: {exc}")

    # -- the one way the file changes ------------------------------------------------------
    def _commit(
        self, change: Callable[[h5py.File], None], *, phase_tag: str, create: bool = False
    ) -> None:
        """Apply ``change`` to a copy of the file and put the copy in its place atomically."""
        tmp = self._tmp
        _kill_point(phase_tag, "before_copy")
        try:
            if create:
                _remove(tmp)
                f = h5py.File(tmp, "w")
            else:
                shutil.copyfile(self.path, tmp)
                _kill_point(phase_tag, "after_copy")
                f = h5py.File(tmp, "a", locking=False)
            try:
                change(f)
            finally:
                f.close()
            _kill_point(phase_tag, "after_write")
            _fsync_file(tmp)
            _kill_point(phase_tag, "after_fsync")
            _replace(tmp, self.path)
            _fsync_dir(os.path.dirname(os.path.abspath(self.path)))
        except OSError as exc:
            _remove(tmp)
            raise VibidError(
                f"{self.path}: cannot write the session file ({exc.strerror or exc})"
            ) from None
        except BaseException:
            _remove(tmp)
            raise
        _kill_point(phase_tag, "after_replace")


def recorded_setup(setup: Setup, frequencies_hz) -> Setup:
    """An adaptive session's setup: the declared one with the steps recorded so far as its
    excitation (each step's own settle and record time are in its group), the declared
    settle time (the floor) and minimum record length kept where they are one number."""
    from dataclasses import replace

    from vibid.setup_model import Excitation

    exc = setup.excitation
    settle = exc.settle_s if not isinstance(exc.settle_s, tuple) else min(exc.settle_s)
    record = exc.record_s if not isinstance(exc.record_s, tuple) else None
    return replace(
        setup, excitation=Excitation(tuple(float(f) for f in frequencies_hz), float(settle), record)
    )


def _write_setup(f: h5py.File, setup: Setup) -> None:
    text = setup.to_json(indent=None)
    f.attrs["setup"] = text
    f.attrs[fmt.SETUP_DIGEST] = fmt.setup_digest(text)


def _float_samples(a: np.ndarray) -> np.ndarray:
    return a if a.dtype in (np.float32, np.float64) else a.astype(np.float64)


def _remove(path: str) -> None:
    try:
        os.remove(path)
    except FileNotFoundError:
        pass


def _fsync_file(path: str) -> None:
    fd = os.open(
        path, os.O_RDWR | getattr(os, "O_BINARY", 0)
    )  # Windows commits only writable handles
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: str) -> None:
    """Make the rename durable (POSIX); Windows cannot open a directory and needs no such step."""
    if sys.platform.startswith("win"):
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems refuse fsync on a directory; the rename itself is atomic
    finally:
        os.close(fd)


def _replace(src: str, dst: str, attempts: int = 50) -> None:
    """``os.replace``, retried for ~5 s where Windows refuses while a reader holds ``dst`` open."""
    for i in range(attempts):
        try:
            os.replace(src, dst)
            return
        except PermissionError:
            if i == attempts - 1 or not sys.platform.startswith("win"):
                raise
            time.sleep(0.1)


def _kill_point(tag: str, phase: str) -> None:
    """Kill this process with SIGKILL if ``VIBID_KILL_AT`` names this write phase (tests)."""
    target = os.environ.get(KILL_AT_ENV)
    if target and target == f"{tag}:{phase}":
        kill = getattr(signal, "SIGKILL", None)
        if kill is not None:
            os.kill(os.getpid(), kill)
        os._exit(137)
