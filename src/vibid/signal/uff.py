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
"""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import numpy as np

from vibid.errors import VibidError
from vibid.signal.imported import ImportedAfc, content_session_id

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
    """Whether ``path`` starts as a Universal File: a line holding ``-1`` right-justified in
    six columns (blanks may follow), then a line whose first six columns hold a dataset
    number. By content, whatever the extension; False for a file that cannot be read."""
    try:
        with open(path, "rb") as fh:
            return _starts_as_uff(fh.read(256))
    except OSError:
        return False


def _starts_as_uff(head: bytes) -> bool:
    lines = head.split(b"\n")
    if len(lines) < 2 or lines[0].rstrip(b"\r").rstrip(b" ") != b"    -1":
        return False
    return lines[1][:6].strip().isdigit()


def write_afc_uff(path, frequency_hz, H, std, *, session_id: str,
                  description: str = "H = response/base acceleration, stepped sine") -> None:
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
        dict(common, func_type=_AFC_FUNC_TYPE, id1=AFC_ID, data=h,
             id5="std per Re and Im part: record 2 (vibid AFC std)"),
        dict(common, func_type=_STD_FUNC_TYPE, id1=STD_ID, data=s,
             id5="standard uncertainty per Re and Im part of record 1 (vibid AFC)"),
    ]
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        for record in records:
            _append_record(tmp, record, shown=path)
        back = _records(tmp, shown=path)
        if not (len(back) == 2 and all(np.array_equal(b["x"], f) for b in back)
                and np.array_equal(back[0]["data"], h) and np.array_equal(back[1]["data"], s)):
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
    if not raw.strip():
        raise VibidError(f"{path}: empty file")
    if not _starts_as_uff(raw[:256]):
        raise VibidError(f"{path}: not a UFF file (it does not start with a -1 line and a "
                         "dataset number)")
    if not raw.rstrip().endswith(b"    -1"):
        raise VibidError(f"{path}: truncated UFF file (it does not end with a -1 line)")
    records = _records(path)
    afc = next((r for r in records if np.iscomplexobj(r["data"])), None)
    if afc is None:
        what = "only real type-58 records" if records else "no type-58 record"
        raise VibidError(f"{path}: {what}; the AFC must be a record with complex ordinates")
    mark = next((r for r in records if r.get("id1") == STD_ID and not np.iscomplexobj(r["data"])
                 and np.array_equal(r["x"], afc["x"])), None)
    if mark is None and afc.get("id1") == AFC_ID:
        raise VibidError(f"{path}: the std record ({STD_ID!r}) of this vibid AFC is missing "
                         "or not at its frequencies")
    f, h = afc["x"], afc["data"]
    std = None if mark is None else mark["data"]
    if not (np.all(np.isfinite(f)) and np.all(np.isfinite(h))):
        raise VibidError(f"{path}: the AFC record holds values that are not finite")
    keep = f != 0.0  # an FFT analyser's DC line: no point of a stepped sine
    f, h, std = f[keep], h[keep], None if std is None else std[keep]
    if np.any(f < 0):
        raise VibidError(f"{path}: frequencies must be positive")
    if f.size < 2:
        raise VibidError(f"{path}: fewer than two AFC points")
    if std is not None and not (np.all(np.isfinite(std)) and np.all(std >= 0)):
        raise VibidError(f"{path}: std must be finite and not negative")
    return ImportedAfc(f, h, std, content_session_id(raw))


def _checked(path, frequency_hz, H, std) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three arrays as float64/complex128, or a VibidError naming ``path``."""
    f = np.asarray(frequency_hz, float).ravel()
    h = np.asarray(H, complex).ravel()
    s = np.asarray(std, float).ravel()
    if not f.size == h.size == s.size:
        raise VibidError(f"{path}: frequency_hz, H and std differ in length "
                         f"({f.size}, {h.size}, {s.size})")
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
    dset = {"type": 58, "binary": 1, "abscissa_spacing": 0,
            "rsp_ent_name": "RESPONSE", "rsp_node": 1, "rsp_dir": 3,  # +Z: out of plane
            "ref_ent_name": "BASE", "ref_node": 2, "ref_dir": 3,
            "abscissa_spec_data_type": _FREQUENCY, "abscissa_axis_lab": "Frequency",
            "abscissa_axis_units_lab": "Hz",
            "ordinate_spec_data_type": _ACCELERATION, "ordinate_axis_lab": "Response accel",
            "ordinate_axis_units_lab": "m/s^2",
            "orddenom_spec_data_type": _ACCELERATION, "orddenom_axis_lab": "Base accel",
            "orddenom_axis_units_lab": "m/s^2", "z_axis_spec_data_type": 0, **record}
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
        if head[:6] != b"    -1" or head[second:second + 7] != b"    58b":
            raise VibidError(f"{shown}: unexpected UFF58b header from pyuff")
        fh.seek(start + second + 31)
        fh.write(b"%12d" % n_bytes)


def _records(path, *, shown=None) -> list[dict]:
    """Every type-58 record of a UFF file, as pyuff reads it (``x`` Hz, ``data``, the
    header fields); other dataset types are skipped unread. One-line VibidError on junk,
    naming ``shown`` (default ``path``)."""
    import pyuff

    path, shown = os.fspath(path), path if shown is None else shown
    try:
        uff = pyuff.UFF(path)
        types = list(uff.get_set_types())
    except Exception:  # pyuff raises bare Exceptions (and others) on junk
        raise VibidError(f"{shown}: not a readable UFF file") from None
    out = []
    for k, kind in enumerate(types):
        if kind != 58:
            continue
        try:
            record = uff.read_sets(k)
            x, data = np.asarray(record["x"], float), np.asarray(record["data"])
        except Exception:
            raise VibidError(f"{shown}: UFF record {k + 1} (dataset 58) cannot be read") from None
        if x.size != data.size or data.size != record.get("num_pts", data.size):
            raise VibidError(f"{shown}: UFF record {k + 1} holds {data.size} values for "
                             f"{record.get('num_pts')} points (truncated or damaged)")
        out.append(record | {"x": x, "data": data})
    return out
