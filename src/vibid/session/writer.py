"""Write a session file one step at a time, so that every completed step survives a crash.

Why reopen-per-step rather than HDF5 SWMR: SWMR only lets a writer append to datasets that
already exist, but the format stores each step as a new group, which SWMR forbids. So the
writer opens the file, writes one step, flushes and closes it. Between steps the file is
closed and consistent on disk: a reader (opening without a lock) sees every completed step
while the test runs, and a process killed with SIGKILL between steps leaves a valid file.

A step is all or nothing: it is written under ``/_vibid_partial_step`` and moved to its
six-digit name only when complete, so a crash in the middle of a step leaves no half step
in ``/steps`` (the leftover is removed when the file is reopened for writing).
"""

from __future__ import annotations

import os
import uuid
from datetime import datetime, timezone

import h5py
import numpy as np

from vibid import __version__
from vibid.errors import VibidError
from vibid.session import format as fmt
from vibid.setup_model import Setup, parse_setup


def utc_now() -> str:
    """The current UTC time in ISO 8601, microseconds included."""
    return datetime.now(timezone.utc).isoformat()


class SessionWriter:
    """Create a session file and append steps to it.

    Parameters
    ----------
    path : the file to create (it must not exist).
    setup : the declared setup, stored as the ``setup`` JSON attribute.
    session_id : defaults to a new UUID4.
    created_utc : defaults to now.
    """

    def __init__(self, path: str | os.PathLike, setup: Setup, *, session_id: str | None = None,
                 created_utc: str | None = None, software: str | None = None):
        self.path = os.fspath(path)
        if os.path.exists(self.path):
            raise VibidError(f"{self.path}: already exists; a session file is never overwritten")
        if setup.excitation is None:
            raise VibidError("a session needs the setup's excitation (the stepped sine it "
                             "records); only an imported AFC's setup leaves it out")
        self.setup = setup
        self.session_id = session_id or str(uuid.uuid4())
        self.n_steps = 0
        with h5py.File(self.path, "w-") as f:
            f.attrs["format"] = fmt.FORMAT
            f.attrs["format_version"] = np.int64(fmt.FORMAT_VERSION)
            f.attrs["created_utc"] = created_utc or utc_now()
            f.attrs["session_id"] = self.session_id
            f.attrs["software"] = software or f"vibid {__version__}"
            f.attrs["setup"] = setup.to_json(indent=None)
            f.attrs[fmt.RUN_STATUS_ATTR] = "running"
            f.create_group(fmt.STEPS_GROUP)

    @classmethod
    def resume(cls, path: str | os.PathLike) -> "SessionWriter":
        """Reopen an existing session (e.g. after a crash) to append further steps."""
        self = cls.__new__(cls)
        self.path = os.fspath(path)
        with h5py.File(self.path, "a") as f:
            if fmt.PARTIAL_STEP in f:
                del f[fmt.PARTIAL_STEP]
            self.setup = parse_setup(fmt.text(f.attrs["setup"]))
            self.session_id = fmt.text(f.attrs["session_id"])
            self.n_steps = sum(fmt.is_step_name(k) for k in f[fmt.STEPS_GROUP])
            f.attrs[fmt.RUN_STATUS_ATTR] = "running"
        return self

    def append(self, *, frequency_hz: float, sample_rate_hz: float, base: np.ndarray,
               response: np.ndarray, status: str = "ok", t0_utc: str | None = None) -> int:
        """Write one complete step and return its index. Nothing is written if it is invalid."""
        base = np.asarray(base)
        response = np.asarray(response)
        if status not in fmt.STEP_STATUSES:
            raise VibidError(f"step status {status!r} is not one of {', '.join(fmt.STEP_STATUSES)}")
        if base.ndim != 1 or response.shape != base.shape or base.size == 0:
            raise VibidError(f"step records must be 1-D and of equal length, got {base.shape} and {response.shape}")
        index = self.n_steps
        with h5py.File(self.path, "a") as f:
            if fmt.PARTIAL_STEP in f:
                del f[fmt.PARTIAL_STEP]
            g = f.create_group(fmt.PARTIAL_STEP)
            g.attrs["frequency_hz"] = float(frequency_hz)
            g.attrs["sample_rate_hz"] = float(sample_rate_hz)
            g.attrs["t0_utc"] = t0_utc or utc_now()
            g.attrs["status"] = status
            g.create_dataset("base", data=_float_samples(base), chunks=base.shape, fletcher32=True, fillvalue=np.nan)
            g.create_dataset("response", data=_float_samples(response), chunks=response.shape, fletcher32=True, fillvalue=np.nan)
            f.move(fmt.PARTIAL_STEP, f"{fmt.STEPS_GROUP}/{fmt.step_name(index)}")
            f.flush()
        self.n_steps += 1
        return index

    def close(self, run_status: str = "complete") -> None:
        """Mark the run ``complete`` (or ``aborted``); the file stays valid either way."""
        with h5py.File(self.path, "a") as f:
            f.attrs[fmt.RUN_STATUS_ATTR] = run_status

    def __enter__(self) -> "SessionWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close("complete" if exc_type is None else "aborted")


def _float_samples(a: np.ndarray) -> np.ndarray:
    return a if a.dtype in (np.float32, np.float64) else a.astype(np.float64)

