"""Names and constants of the session file format, version 1 (shared/spec/session-format.md)."""

from __future__ import annotations

import re
from datetime import datetime

FORMAT = "vibid.session"
FORMAT_VERSION = 1
#: Versions this vibid reads.
READABLE_VERSIONS = (1,)

ROOT_ATTRIBUTES = ("format", "format_version", "created_utc", "session_id", "software", "setup")
STEP_ATTRIBUTES = ("frequency_hz", "sample_rate_hz", "t0_utc", "status")
STEP_DATASETS = ("base", "response")
STEP_STATUSES = ("ok", "overload", "aborted")

STEPS_GROUP = "steps"
#: A step being written lives here until it is complete, then moves into /steps (vibid's own).
PARTIAL_STEP = "_vibid_partial_step"
#: vibid's own root attribute: "running", "complete" or "aborted" (extension of the format).
RUN_STATUS_ATTR = "vibid_run_status"

_STEP_NAME = re.compile(r"^[0-9]{6}$")


def step_name(index: int) -> str:
    """The group name of step ``index``: six digits, ``000000`` first."""
    return f"{index:06d}"


def is_step_name(name: str) -> bool:
    return bool(_STEP_NAME.match(name))


def parse_utc(text: str) -> datetime:
    """Parse an ISO 8601 time (``Z`` accepted); raise ValueError if it is not one."""
    return datetime.fromisoformat(text.replace("Z", "+00:00").replace("z", "+00:00"))


def text(value) -> str:
    """An HDF5 string attribute as str, whether stored variable-length (str) or fixed (bytes)."""
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)
