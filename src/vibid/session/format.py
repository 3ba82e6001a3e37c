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
#: Where vibid once wrote a step before moving it into /steps; a leftover is removed on resume.
PARTIAL_STEP = "_vibid_partial_step"
#: Optional root attributes saying how the session ended ("How a session ends" in the spec).
RUN_STATUS = "run_status"
RUN_STATUS_REASON = "run_status_reason"
RUN_STATUSES = ("complete", "interrupted", "aborted")
#: What vibid wrote before the spec named the run status: "running", "complete" or "aborted"
#: (read, never written).
LEGACY_RUN_STATUS = "vibid_run_status"
RUN_STATUS_ATTRS = (RUN_STATUS, RUN_STATUS_REASON, LEGACY_RUN_STATUS)
#: Optional root attribute: seconds the specimen was driven (every step's settle and record
#: time, re-records included, summed), written when the session is closed.
STAND_TIME_S = "stand_time_s"
#: Optional step attribute: seconds the drive ran at the step's frequency before its first
#: sample (re-records after an unsettled record included).
SETTLE_S = "settle_s"
#: Optional free-text root attributes of the spec.
OPTIONAL_TEXT_ATTRIBUTES = ("operator", "notes")
#: Optional root attribute: a JSON document (target, band, stand-time cap, batch size,
#: seed) marking a campaign that chooses its frequencies as it goes; the setup's
#: ``excitation.frequencies_hz`` then lists the steps recorded so far, and the step groups
#: are the truth where the two disagree.
ADAPTIVE = "adaptive"

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


def run_status_of(attrs, n_steps: int, n_frequencies: int) -> tuple[str, str]:
    """How a session ended, ``(status, reason)``, from its root attributes and step count.

    ``run_status`` when written; else vibid's earlier ``vibid_run_status`` ("running" read as
    ``interrupted``); else, as the spec says, ``interrupted`` when fewer steps than
    frequencies were recorded and ``complete`` otherwise (an adaptive campaign's setup
    lists only what it recorded: without ``run_status`` it stopped before it decided to).
    """
    if RUN_STATUS in attrs:
        reason = text(attrs[RUN_STATUS_REASON]) if RUN_STATUS_REASON in attrs else ""
        return text(attrs[RUN_STATUS]), reason
    if LEGACY_RUN_STATUS in attrs:
        legacy = text(attrs[LEGACY_RUN_STATUS])
        if legacy in ("complete", "aborted"):
            return legacy, ""
        return "interrupted", "stopped before closing the session"
    if ADAPTIVE in attrs:
        return "interrupted", f"stopped before closing the session, {n_steps} steps recorded"
    if n_steps < n_frequencies:
        return "interrupted", (
            f"stopped before closing the session, {n_steps} of {n_frequencies} steps recorded"
        )
    return "complete", ""


#: vibid's own root attribute: the SHA-256 of the ``setup`` text as written. HDF5 keeps
#: variable-length strings in its global heap, which has no checksum in any layout, so a
#: changed digit in the setup would otherwise read back as written.
SETUP_DIGEST = "vibid_setup_sha256"


def setup_digest(setup_text: str) -> str:
    """The SHA-256 (hex) of a setup's JSON text, as stored in :data:`SETUP_DIGEST`."""
    import hashlib

    return hashlib.sha256(setup_text.encode("utf-8")).hexdigest()


def setup_digest_problem(attrs) -> str | None:
    """Why the file's setup does not match its stored digest (damage), or None (no digest:
    a file written before vibid stored one, or by another program)."""
    if SETUP_DIGEST not in attrs or "setup" not in attrs:
        return None
    if text(attrs[SETUP_DIGEST]) != setup_digest(text(attrs["setup"])):
        return "the setup does not match its checksum (the file is damaged)"
    return None


def adaptive_document(attrs) -> dict | None:
    """The ``adaptive`` root attribute as a dict, or None for a campaign of fixed steps.
    Raises ValueError when it is not a JSON object."""
    import json

    if ADAPTIVE not in attrs:
        return None
    doc = json.loads(text(attrs[ADAPTIVE]))
    if not isinstance(doc, dict):
        raise ValueError("must be a JSON object")
    return doc


def stand_time_s(f) -> float | None:
    """Seconds the specimen was driven, of an open session file ``f`` (h5py), from its step
    groups (after a crash and a resume they are the truth): each step's ``settle_s``
    (re-records included) plus its record's duration. None when no step says how long it
    settled (a file written before the field)."""
    total, known = 0.0, False
    for name, g in f[STEPS_GROUP].items():
        if not is_step_name(name) or SETTLE_S not in g.attrs:
            continue
        known = True
        total += float(g.attrs[SETTLE_S]) + g["base"].shape[0] / float(g.attrs["sample_rate_hz"])
    return total if known else None
