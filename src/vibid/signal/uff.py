"""The AFC as a Universal File (dataset 58, through pyuff), for modal-analysis packages.

A file written here holds two binary type-58 records ("58b") at the same abscissa, the
frequencies in Hz:

1. the AFC ``H = response/base`` (dimensionless: acceleration over acceleration), complex
   double precision (ordinate data type 6), ID line 1 ``vibid AFC``;
2. its standard uncertainty per real and imaginary part, real double precision (ordinate
   data type 4), ID line 1 ``vibid AFC std`` (UFF58 has no slot for an uncertainty).

Binary, not ASCII: pyuff writes an ASCII record's uneven abscissa as ``E13.5`` (six
significant digits: the refined frequencies would move by up to 5 ppm) and its ordinates as
``E20.11``; the binary form stores every number as the IEEE double it was, so a round trip is
exact. No date in the ID lines: the same AFC gives the same bytes (and, read back, the same
content-derived session id, as :func:`vibid.signal.imported.read_afc_csv`).

Reading takes any UFF58 file, from other systems too: the first record with complex
ordinates is the AFC (even abscissa spacing is expanded from its minimum and increment; a
0 Hz line, an FFT analyser's DC line, is dropped), and the std is read only from a real
record marked as vibid's with the same abscissa (otherwise none, as a CSV without ``std``).
Its points are then checked, sorted and merged as a CSV's are
(:func:`vibid.signal.imported.checked_afc`: the order of the points does not matter, repeated
identical points count once, conflicting ones are refused naming both points).

A file is UFF when its first non-blank line is ``-1`` (:func:`is_uff`); one that then is no
readable UFF (a ``-1`` not right-justified in six columns, no dataset number, a last record
without its closing ``-1`` line: a truncated file) is refused in one line, not read as CSV.
Line ends may be LF or CRLF. A binary record's data must be exactly the bytes its points
take; a binary file whose every LF was made CRLF on the way (an FTP transfer in text mode, a
Windows checkout), which shifts the doubles that follow, is read as it was before that (the
conversion undone in the binary data, which then has its exact length again); any other
length is refused as truncated or damaged, never read shifted.
"""

from __future__ import annotations

import os
import tempfile
import uuid
from pathlib import Path

import numpy as np

from vibid.errors import VibidError
from vibid.signal.afc_file import ImportedAfc, checked_afc, content_session_id

AFC_ID = "vibid AFC"
STD_ID = "vibid AFC std"

# Function type 4 (frequency response function) with ordinate numerator and denominator both
# "acceleration" (specific data type 12): H is response over base acceleration, which the
# two data characteristics records say explicitly. Type 5 (transmissibility) would say it
# too, but pyuff 2.5.8 refuses to write it (its writer allows types 0-4, 6 and 9 only), and
# modal packages import acceleration/acceleration FRFs as such. The std record is type 0
# (general): it is no function a modal package should fit.
_AFC_FUNC_TYPE = 4
_STD_FUNC_TYPE = 0
_ACCELERATION = 12
_FREQUENCY = 18
_COMPLEX_DOUBLE = 6
_ID_WIDTH = 80


def is_uff(path) -> bool:
    """Whether ``path`` is a Universal File by content, whatever the extension: its first
    non-blank line (a UTF-8 byte-order mark skipped) is ``-1``. False for a file that cannot
    be read, and for one whose first 64 KiB are blank."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
    except OSError:
        return False
    line = _first_line(head)
    return line is not None and line.strip() == b"-1"


def _first_line(raw: bytes) -> bytes | None:
    """The first non-blank line of ``raw`` (a UTF-8 byte-order mark skipped), without its
    line end; None if there is none."""
    raw = raw.removeprefix(b"\xef\xbb\xbf")
    return next((line for line in raw.splitlines() if line.strip()), None)


def write_afc_uff(
    path,
    frequency_hz,
    H,
    std,
    *,
    session_id: str,
    description: str = "H = response/base acceleration, stepped sine",
) -> None:
    """Write the AFC and its std to ``path`` as two binary UFF58 records (module docstring).

    Parameters
    ----------
    frequency_hz : (n,) Hz, positive (the refined frequencies of the steps).
    H : (n,) complex, dimensionless (response/base acceleration).
    std : (n,) standard uncertainty per real and imaginary part, dimensionless.
    session_id : the session the AFC comes from (ID line 2 of both records).
    description : ID line 4 of both records (ASCII, at most 80 characters are kept).

    Atomic: written to a temporary file in the same folder, read back and compared, then
    moved over ``path``; a failure leaves no file behind. :class:`VibidError` on bad input.
    """
    f, h, s = _checked(path, frequency_hz, H, std)
    common = {"id2": _id_line(f"session {session_id}"), "id4": _id_line(description), "x": f}
    records = [
        dict(
            common,
            func_type=_AFC_FUNC_TYPE,
            id1=AFC_ID,
            data=h,
            id5="std per Re and Im part: record 2 (vibid AFC std)",
        ),
        dict(
            common,
            func_type=_STD_FUNC_TYPE,
            id1=STD_ID,
            data=s,
            id5="standard uncertainty per Re and Im part of record 1 (vibid AFC)",
        ),
    ]
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        for record in records:
            _append_record(tmp, record, shown=path)
        back = _records(tmp, shown=path)
        if not (
            len(back) == 2
            and all(np.array_equal(b["x"], f) for b in back)
            and np.array_equal(back[0]["data"], h)
            and np.array_equal(back[1]["data"], s)
        ):
            raise VibidError(f"{path}: the UFF file did not read back as written")
        os.replace(tmp, target)
    except OSError as exc:
        raise VibidError(f"{path}: cannot write ({exc.strerror or exc})") from None
    finally:
        if tmp.exists():
            tmp.unlink()


def read_afc_uff(path) -> ImportedAfc:
    """Read an AFC from a UFF58 file (module docstring): frequencies in Hz, H dimensionless,
    std per real and imaginary part or None; a one-line :class:`VibidError` for anything
    wrong."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise VibidError(f"{path}: cannot read ({exc.strerror or exc})") from None
    first = _first_line(raw)
    if first is None:
        raise VibidError(f"{path}: empty file")
    if first.strip() != b"-1":
        raise VibidError(f"{path}: not a UFF file (its first line is not -1)")
    if first.rstrip(b" ") != _DELIMITER:
        raise VibidError(
            f"{path}: not a readable UFF file (its -1 lines must be "
            "right-justified in six columns, '    -1')"
        )
    marks = _delimiters(raw)
    if not raw.rstrip().endswith(_DELIMITER) or len(marks) % 2:
        raise VibidError(
            f"{path}: truncated UFF file (its last record does not end with a -1 line)"
        )
    blocks = [raw[a:b] for a, b in zip(marks[::2], marks[1::2])]
    if not _dataset_number(blocks[0]):
        raise VibidError(
            f"{path}: not a readable UFF file (no dataset number after its first -1 line)"
        )
    records = _records_of(path, raw, marks, blocks)
    number, afc = next(((n, r) for n, r in records if np.iscomplexobj(r["data"])), (0, None))
    if afc is None:
        what = "only real type-58 records" if records else "no type-58 record"
        raise VibidError(f"{path}: {what}; the AFC must be a record with complex ordinates")
    mark = next(
        (
            r
            for _, r in records
            if r.get("id1") == STD_ID
            and not np.iscomplexobj(r["data"])
            and np.array_equal(r["x"], afc["x"])
        ),
        None,
    )
    if mark is None and afc.get("id1") == AFC_ID:
        raise VibidError(
            f"{path}: the std record ({STD_ID!r}) of this vibid AFC is missing "
            "or not at its frequencies"
        )
    f, h = afc["x"], afc["data"]
    std = None if mark is None else mark["data"]
    points = np.arange(1, f.size + 1)
    keep = f != 0.0  # an FFT analyser's DC line: no point of a stepped sine
    return checked_afc(
        path,
        f[keep],
        h[keep],
        None if std is None else std[keep],
        points[keep],
        (f"record {number}, point", f"record {number}, points"),
        content_session_id(raw),
    )


_DELIMITER = b"    -1"


def _delimiters(raw: bytes) -> list[int]:
    """The offsets of the ``    -1`` delimiters of a Universal File, found as pyuff 2.5.8
    finds them (followed by a line end, the end of the file or blanks to column 80)."""
    out, k, n = [], -1, len(raw)
    while (k := raw.find(_DELIMITER, k + 1)) != -1:
        end = k + len(_DELIMITER)
        if end == n or raw[end] in b"\r\n" or (end + 74 < n and raw[end : k + 80] == b" " * 74):
            out.append(k)
    return out


def _dataset_number(block: bytes) -> int | None:
    """The dataset number of a block (columns 1-6 of the line after its ``-1``), or None."""
    lines = block.splitlines()
    head = lines[1][:6].strip() if len(lines) > 1 else b""
    return int(head) if head.isdigit() else None


def _records_of(path, raw: bytes, marks: list[int], blocks: list[bytes]) -> list[tuple[int, dict]]:
    """``[(record number, record)]``: the type-58 records of the file (:func:`_records`),
    each binary one's data checked for its exact length first (:func:`_binary_body`) and
    read from a repaired copy of the file where a line-end conversion had to be undone."""
    fixed, pieces, at = False, [], 0
    for k, (start, block) in enumerate(zip(marks[::2], blocks)):
        if _dataset_number(block) != 58 or block.splitlines()[1][6:7].lower() != b"b":
            continue
        head = b"".join(block.splitlines(True)[:13])
        body = _binary_body(path, k + 1, block)
        if head + body != block:
            fixed = True
            pieces += [raw[at:start], head, body]
            at = start + len(block)
    if not fixed:
        return _records(path, numbered=True)
    with tempfile.TemporaryDirectory() as folder:
        copy = Path(folder) / "repaired.uff"
        copy.write_bytes(b"".join(pieces) + raw[at:])
        return _records(copy, shown=path, numbered=True)


def _binary_body(path, number: int, block: bytes) -> bytes:
    """The binary data of a 58b block (``    -1`` line, 12 header lines, data), exactly the
    bytes its points take: as it is, less a line end after it, or with a CRLF conversion
    undone (module docstring). A VibidError for any other length (a truncated or damaged
    record)."""
    lines = block.splitlines(True)
    try:
        if len(lines) < 14:
            raise ValueError
        form = lines[8]
        kind, n_points, spacing = int(form[0:10]), int(form[10:20]), int(form[20:30])
        size = {2: 4, 4: 8, 5: 4, 6: 8}[kind]
        order = int(lines[1][7:13])
    except (ValueError, KeyError):
        raise VibidError(f"{path}: UFF record {number} (dataset 58) cannot be read") from None
    if order not in (1, 2):  # pyuff would read any other as big-endian
        raise VibidError(
            f"{path}: UFF record {number} (dataset 58b): byte ordering {order} is "
            "neither 1 (little-endian) nor 2 (big-endian)"
        )
    per_point = (2 if kind in (5, 6) else 1) + (1 if spacing == 0 else 0)
    expected = n_points * per_point * size
    body = b"".join(lines[13:])
    for data in (body, body.replace(b"\r\n", b"\n")):
        for end in (b"", b"\r\n", b"\n", b"\r"):
            if data.endswith(end) and len(data) - len(end) == expected:
                return data[:expected]
    raise VibidError(
        f"{path}: UFF record {number} (dataset 58b) holds {len(body)} bytes of "
        f"binary data where its {n_points} points take {expected} (truncated, or "
        "damaged in a copy: copy binary UFF files as binary)"
    )


def _checked(path, frequency_hz, H, std) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three arrays as float64/complex128, or a VibidError naming ``path``."""
    f = np.asarray(frequency_hz, float).ravel()
    h = np.asarray(H, complex).ravel()
    s = np.asarray(std, float).ravel()
    if not f.size == h.size == s.size:
        raise VibidError(
            f"{path}: frequency_hz, H and std differ in length ({f.size}, {h.size}, {s.size})"
        )
    if f.size < 2:
        raise VibidError(f"{path}: fewer than two AFC points to write")
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(h)) and np.all(np.isfinite(s))):
        raise VibidError(f"{path}: the AFC to write holds values that are not finite")
    if np.any(f <= 0) or np.any(s < 0):
        raise VibidError(f"{path}: frequencies must be positive and std not negative")
    return f, h, s


def _id_line(text: str) -> str:
    """One UFF ID line: printable ASCII, at most 80 characters, never blank."""
    line = "".join(c if " " <= c <= "~" else " " for c in str(text)).strip()[:_ID_WIDTH]
    return line or "NONE"


def _append_record(path: Path, record: dict, *, shown) -> None:
    """Append one binary type-58 record (uneven abscissa in Hz, acceleration/acceleration,
    double precision) to ``path`` with pyuff, then correct its byte count (see below);
    errors name ``shown`` (the file the user asked for)."""
    import pyuff

    start = path.stat().st_size if path.exists() else 0
    dset = {
        "type": 58,
        "binary": 1,
        "abscissa_spacing": 0,
        "rsp_ent_name": "RESPONSE",
        "rsp_node": 1,
        "rsp_dir": 3,  # +Z: out of plane
        "ref_ent_name": "BASE",
        "ref_node": 2,
        "ref_dir": 3,
        "abscissa_spec_data_type": _FREQUENCY,
        "abscissa_axis_lab": "Frequency",
        "abscissa_axis_units_lab": "Hz",
        "ordinate_spec_data_type": _ACCELERATION,
        "ordinate_axis_lab": "Response accel",
        "ordinate_axis_units_lab": "m/s^2",
        "orddenom_spec_data_type": _ACCELERATION,
        "orddenom_axis_lab": "Base accel",
        "orddenom_axis_units_lab": "m/s^2",
        "z_axis_spec_data_type": 0,
        **record,
    }
    try:
        # 'add' on a new file: pyuff's 'overwrite' of a binary record truncates its own header
        pyuff.UFF(os.fspath(path)).write_sets(dset, mode="add", force_double=True)
    except Exception as exc:  # pyuff raises bare Exceptions
        raise VibidError(f"{shown}: pyuff could not write the record ({exc})") from None
    values_per_point = 3 if np.iscomplexobj(record["data"]) else 2  # x, (Re, Im) or y
    _set_byte_count(path, start, 8 * values_per_point * len(record["x"]), shown=shown)


def _set_byte_count(path: Path, start: int, n_bytes: int, *, shown) -> None:
    """Field 6 of a 58b header (columns 32-43 of its second line: the bytes of binary data
    that follow the 11 ASCII lines). pyuff 2.5.8 writes 8 bytes per point there, though an
    uneven record holds the abscissa too (and a complex one two ordinates); a reader that
    trusts the field would stop short."""
    with open(path, "r+b") as fh:
        fh.seek(start)
        head = fh.read(100)
        second = head.find(b"\n") + 1
        if head[:6] != b"    -1" or head[second : second + 7] != b"    58b":
            raise VibidError(f"{shown}: unexpected UFF58b header from pyuff")
        fh.seek(start + second + 31)
        fh.write(b"%12d" % n_bytes)


def _records(path, *, shown=None, numbered: bool = False) -> list:
    """Every type-58 record of a UFF file, as pyuff reads it (``x`` Hz, ``data``, the
    header fields); other dataset types are skipped unread; with ``numbered``, as
    ``(record number, record)``. One-line VibidError on junk, naming ``shown`` (default
    ``path``)."""
    import pyuff

    path, shown = os.fspath(path), path if shown is None else shown
    try:
        with np.errstate(all="ignore"):
            uff = pyuff.UFF(path)
            types = list(uff.get_set_types())
    except Exception:  # pyuff raises bare Exceptions (and others) on junk
        raise VibidError(f"{shown}: not a readable UFF file") from None
    out = []
    for k, kind in enumerate(types):
        if kind != 58:
            continue
        try:
            with np.errstate(all="ignore"):
                record = uff.read_sets(k)
                x, data = np.asarray(record["x"], float), np.asarray(record["data"])
        except Exception:
            raise VibidError(f"{shown}: UFF record {k + 1} (dataset 58) cannot be read") from None
        if x.size != data.size or data.size != record.get("num_pts", data.size):
            raise VibidError(
                f"{shown}: UFF record {k + 1} holds {data.size} values for "
                f"{record.get('num_pts')} points (truncated or damaged)"
            )
        record = record | {"x": x, "data": data}
        out.append((k + 1, record) if numbered else record)
    return out
