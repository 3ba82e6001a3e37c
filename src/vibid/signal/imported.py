"""An AFC measured by another system, read from CSV (``frequency_hz, re, im[, std]``) or
from a Universal File, dataset 58 (:mod:`vibid.signal.uff`); :func:`read_afc` tells the two
apart by content, not by extension.

The identification and the closed loop take it as they take a session's AFC. Without a
``std`` column (a UFF file: without vibid's std record) the fit falls back on the paper's
plain mean-square weighting (and the loop, which tests the residual against the noise,
cannot run). The report's ``session_id`` of an imported AFC is derived from the file's
bytes, so the same file gives the same id.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vibid.errors import VibidError

COLUMNS = ("frequency_hz", "re", "im")


@dataclass(frozen=True)
class ImportedAfc:
    """frequency_hz (n,) Hz; H (n,) complex; std (n,) per real and imaginary part, or None;
    session_id: derived from the file's content."""

    frequency_hz: np.ndarray
    H: np.ndarray
    std: np.ndarray | None
    session_id: str

    @property
    def used(self) -> np.ndarray:
        return np.ones(self.frequency_hz.size, bool)

    def to_report_block(self) -> dict[str, Any]:
        return {"frequency_hz": self.frequency_hz.tolist(), "re": self.H.real.tolist(),
                "im": self.H.imag.tolist(),
                "std": [None] * self.H.size if self.std is None else self.std.tolist()}


def read_afc(path) -> ImportedAfc:
    """Read an AFC file, UFF58 or CSV as its content says (a UFF file starts with a ``-1``
    line, :func:`vibid.signal.uff.is_uff`); a one-line :class:`VibidError` for anything
    wrong."""
    from vibid.signal.uff import is_uff, read_afc_uff

    return read_afc_uff(path) if is_uff(path) else read_afc_csv(path)


def content_session_id(raw: bytes) -> str:
    """The session id of an imported AFC: a UUID made of the SHA-256 of the file's bytes."""
    return str(uuid.UUID(hashlib.sha256(raw).hexdigest()[:32]))


def read_afc_csv(path) -> ImportedAfc:
    """Read an AFC CSV file; a clear one-line :class:`VibidError` for anything wrong."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise VibidError(f"{path}: cannot read ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise VibidError(f"{path}: not a text CSV file") from None
    rows = list(csv.reader(io.StringIO(text)))
    if not rows:
        raise VibidError(f"{path}: empty file")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise VibidError(f"{path}: the header lacks {', '.join(missing)} (expected columns "
                         "frequency_hz, re, im and optionally std)")
    cols = {name: header.index(name) for name in COLUMNS + ("std",) if name in header}
    values = {name: [] for name in cols}
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        for name, k in cols.items():
            try:
                v = float(row[k])
            except (IndexError, ValueError):
                raise VibidError(f"{path}: line {line}: {name} is not a number") from None
            if not math.isfinite(v):
                raise VibidError(f"{path}: line {line}: {name} is not finite")
            values[name].append(v)
    f = np.array(values["frequency_hz"])
    if f.size < 2:
        raise VibidError(f"{path}: fewer than two AFC points")
    if np.any(f <= 0):
        raise VibidError(f"{path}: frequencies must be positive")
    std = np.array(values["std"]) if "std" in values else None
    if std is not None and np.any(std < 0):
        raise VibidError(f"{path}: std must not be negative")
    return ImportedAfc(f, np.array(values["re"]) + 1j * np.array(values["im"]), std,
                       content_session_id(raw))
