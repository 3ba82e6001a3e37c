"""An AFC measured by another system, read from CSV (``frequency_hz, re, im[, std]``) or
from a Universal File, dataset 58 (:mod:`vibid.signal.uff`); :func:`read_afc` tells the two
apart by content, not by extension (a file whose first non-blank line is ``-1`` is UFF).

The identification and the closed loop take it as they take a session's AFC. Without a
``std`` column (a UFF file: without vibid's std record) the fit falls back on the paper's
plain mean-square weighting (and the loop, which tests the residual against the noise,
cannot run). The report's ``session_id`` of an imported AFC is derived from the file's
bytes, so the same file gives the same id.

What every reader (CSV and UFF58) does with what it reads, before any fit; anything it
refuses is one line (:class:`~vibid.errors.VibidError`) naming the file and the row (a CSV's
line, a UFF record's point):

* **order**: the points are sorted by frequency, so a file listed in any order (descending,
  as acquired) gives the same AFC, hence the same fit;
* **repeated frequencies**: rows at the same frequency that agree in every column (a file
  concatenated twice, a band edge exported twice) are one point, counted once; rows at the
  same frequency whose values differ are refused, naming both rows: which one is the
  measurement is the lab's call, not the reader's (average them, or keep one);
* **values**: frequency, re, im and std must be finite numbers, frequency and std positive;
  re, im and std at most :data:`MAX_ABS_H` in size (an AFC is a ratio of accelerations), std
  at least :data:`MIN_REL_STD` of the largest |H| (finer than any DAQ resolves);
* **signal**: an AFC whose largest |H| is below :data:`MIN_PEAK_H` (every H zero: the
  response channel not connected), or, with a std, none of whose points stands above its
  std (:data:`MIN_SNR`), holds no measurement to fit;
* **band** (where the AFC meets its setup, :func:`vibid.pipeline.afc_file`): every
  frequency must lie below the setup DAQ's Nyquist frequency (:func:`refuse_beyond_nyquist`).

A CSV file is UTF-8 (a byte-order mark is skipped), UTF-16 with its byte-order mark, or,
failing UTF-8, Latin-1 (numbers and the header are ASCII alike); line ends LF, CRLF or CR;
blank lines are skipped; columns are found by their exact header names (others are
ignored, but not one that is a known name in other case or with other characters, nor
one whose name holds ``std``: a ``Std`` or ``std_re`` column ignored would leave the fit
unweighted), a row holding more non-empty fields than the header is refused (a decimal
comma splits numbers into two fields). One truncation no reader can see: a cut inside the
last number of the file's last line (a shorter number is a number too).
"""

from __future__ import annotations

import codecs
import csv
import io
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from vibid.errors import VibidError
from vibid.signal.afc_file import (  # noqa: F401  (read beside the readers)
    MAX_ABS_H,
    MIN_PEAK_H,
    MIN_REL_STD,
    MIN_SNR,
    ImportedAfc,
    checked_afc,
    content_session_id,
    refuse_beyond_nyquist,
)
from vibid.signal.uff import is_uff, read_afc_uff

COLUMNS = ("frequency_hz", "re", "im")


def read_afc(path) -> ImportedAfc:
    """Read an AFC file, UFF58 or CSV as its content says (a UFF file's first non-blank
    line is ``-1``, :func:`vibid.signal.uff.is_uff`); a one-line :class:`VibidError` for
    anything wrong (module docstring)."""
    return read_afc_uff(path) if is_uff(path) else read_afc_csv(path)


def read_afc_csv(path) -> ImportedAfc:
    """Read an AFC CSV file (module docstring); a clear one-line :class:`VibidError` for
    anything wrong."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise VibidError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if raw.startswith(b"\x89HDF\r\n\x1a\n"):
        raise VibidError(
            f"{path}: an HDF5 file, not an AFC (a session file is identified without --afc)"
        )
    rows = _csv_rows(path, _decoded(raw))
    try:
        _, header = next(rows)
    except StopIteration:
        raise VibidError(f"{path}: empty file") from None
    cols = _columns(path, header)  # before the rest is parsed: junk is refused at once
    values = {name: [] for name in cols}
    lines = []
    for line, row in rows:
        if (filled := sum(1 for c in row if c.strip())) > len(header):
            raise VibidError(
                f"{path}: line {line}: {filled} fields, more than the header's "
                f"{len(header)} (a decimal comma?)"
            )
        for name, k in cols.items():
            values[name].append(_number(path, line, name, row[k] if k < len(row) else None))
        lines.append(line)
    H = np.empty(len(lines), complex)
    H.real, H.imag = values["re"], values["im"]  # not re + 1j * im: 1j * inf has a nan real part
    return checked_afc(
        path,
        np.array(values["frequency_hz"], float),
        H,
        np.array(values["std"], float) if "std" in values else None,
        lines,
        ("line", "lines"),
        content_session_id(raw),
    )


def _decoded(raw: bytes) -> str:
    """The text of a CSV file's bytes: UTF-16 by its byte-order mark, else UTF-8 (a mark
    skipped), else Latin-1 (module docstring)."""
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            pass
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _csv_rows(path, text: str) -> Iterator[tuple[int, list[str]]]:
    """The non-blank rows of a CSV text with the line each ends on (1-based), as they are
    parsed; any line end (LF, CRLF, CR)."""
    reader = csv.reader(io.StringIO(text, newline=None))
    try:
        for row in reader:
            if any(c.strip() for c in row):
                yield reader.line_num, row
    except csv.Error as exc:
        raise VibidError(f"{path}: line {reader.line_num}: not CSV ({exc})") from None


def _columns(path, header: list[str]) -> dict[str, int]:
    """The column of each of :data:`COLUMNS` and of ``std`` if there, by header name."""
    names = [h.strip() for h in header]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        hint = (
            " (is it separated by ';' or tabs? commas are expected)"
            if any(s in ",".join(names) for s in (";", "\t"))
            else ""
        )
        raise VibidError(
            f"{path}: the header lacks {', '.join(missing)} (expected columns "
            f"frequency_hz, re, im and optionally std){hint}"
        )
    wanted = COLUMNS + ("std",)
    twice = [c for c in wanted if names.count(c) > 1]
    if twice:
        raise VibidError(f"{path}: the header names {', '.join(twice)} more than once")
    for name in names:  # 'Std', 'std_re' or a damaged 'std' ignored: the fit unweighted
        plain = "".join(c for c in name.lower() if c.isalnum() or c == "_")
        if name not in wanted and (plain in wanted or "std" in plain):
            like = plain if plain in wanted else "std"
            raise VibidError(
                f"{path}: the header's column {name!r} is not {like!r} (the column names are exact)"
            )
    return {name: names.index(name) for name in wanted if name in names}


def _number(path, line: int, name: str, cell: str | None) -> float:
    """The number in ``cell`` (the column ``name`` of ``line``); finiteness is judged
    later (:func:`checked_afc`)."""
    if cell is None or not cell.strip():
        raise VibidError(f"{path}: line {line}: {name} is missing")
    try:
        if "_" in cell or not cell.strip().isascii():  # float() takes 1_000 and other
            raise ValueError  # scripts' digits; a CSV does not
        return float(cell)
    except ValueError:
        shown = cell.strip()
        shown = shown if len(shown) <= 30 else shown[:27] + "..."
        raise VibidError(f"{path}: line {line}: {name} {shown!r} is not a number") from None
