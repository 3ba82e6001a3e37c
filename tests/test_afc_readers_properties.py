"""Property-based tests of the readers of an imported AFC (issue 62: never hang, never
silently wrong): CSV and UFF58 files generated with hypothesis — rows in any order, repeated
rows, blank lines, line ends, encodings, number formats, truncations, NaN/inf and absurd
magnitudes. The property: a file reads as the clean file of the same points reads, or it is
refused with a :class:`~vibid.errors.VibidError` of one line; never another exception, a
warning, or a silently different AFC. Then ``vibid identify`` on a few bad files, as a
process: rc 1, one line on stderr, no traceback, within a time limit.

Reproducible: ``derandomize=True`` and no example database; every test runs a few dozen
examples of small files (the whole file takes a few seconds on one core).
"""

from __future__ import annotations

import itertools
import struct
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vibid.errors import VibidError
from vibid.signal.imported import MAX_ABS_H, read_afc
from vibid.signal.uff import write_afc_uff

ROOT = Path(__file__).parent.parent
TITANIUM_SETUP = ROOT / "tests" / "data" / "titanium_setup.json"  # DAQ 25.6 kHz

SETTINGS = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
_names = itertools.count()


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("afc-properties")


def _file(folder, data: bytes, suffix=".csv") -> Path:
    p = folder / f"f{next(_names)}{suffix}"
    p.write_bytes(data)
    return p


def _read(path):
    """``read_afc(path)`` with every warning an error (a numpy warning is a fault too)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return read_afc(path)


def _outcome(path):
    """("ok", afc) or ("refused", message); any other exception fails the test."""
    try:
        return "ok", _read(path)
    except VibidError as exc:
        message = str(exc)
        assert message and "\n" not in message and "\r" not in message, message
        assert str(path) in message, message
        return "refused", message


def _same(a, b):
    assert np.array_equal(a.frequency_hz, b.frequency_hz)
    assert np.array_equal(a.H, b.H)
    assert (a.std is None) == (b.std is None)
    assert a.std is None or np.array_equal(a.std, b.std)


# --- the AFCs ---------------------------------------------------------------------------

_component = st.floats(-1e3, 1e3, allow_nan=False, allow_subnormal=False)


@st.composite
def afcs(draw, with_std=None, min_size=2, max_size=25):
    """(f Hz distinct, H, std or None): an AFC a reader must take (finite, in range, with a
    point of |H| >= 1 above its std)."""
    n = draw(st.integers(min_size, max_size))
    f = np.array(
        draw(
            st.lists(
                st.floats(0.01, 12_000.0, allow_subnormal=False),
                min_size=n,
                max_size=n,
                unique=True,
            )
        )
    )
    re = np.array(draw(st.lists(_component, min_size=n, max_size=n)))
    im = np.array(draw(st.lists(_component, min_size=n, max_size=n)))
    re[draw(st.integers(0, n - 1))] = draw(st.sampled_from([1.0, -3.5, 250.0]))
    H = np.empty(n, complex)
    H.real, H.imag = re, im
    if with_std is None:
        with_std = draw(st.booleans())
    std = (
        np.array(draw(st.lists(st.floats(1e-4, 0.5), min_size=n, max_size=n))) if with_std else None
    )
    return f, H, std


_FORMATS = (repr, lambda v: f"{v:.17g}", lambda v: f"{v:.17e}", lambda v: f"{v:+.16E}")


def _cells(f, H, std, k, fmt=repr):
    cells = [fmt(float(f[k])), fmt(float(H[k].real)), fmt(float(H[k].imag))]
    return cells + ([fmt(float(std[k]))] if std is not None else [])


def _header(std):
    return ["frequency_hz", "re", "im"] + (["std"] if std is not None else [])


def _clean_csv(f, H, std) -> bytes:
    rows = [",".join(_header(std))] + [",".join(_cells(f, H, std, k)) for k in range(len(f))]
    return ("\n".join(rows) + "\n").encode()


# --- CSV: the same points, written otherwise ----------------------------------------------


@st.composite
def csv_variants(draw):
    """(clean bytes, variant bytes) of one AFC: the rows permuted and some repeated as they
    are, blank lines, spaces around fields, another line end, number format, column order,
    an extra column, a byte-order mark or another encoding."""
    f, H, std = draw(afcs())
    n = len(f)
    order = draw(st.permutations(range(n)))
    order += draw(st.lists(st.integers(0, n - 1), max_size=4))  # repeated rows, identical
    order = draw(st.permutations(order))
    fmt = draw(st.sampled_from(_FORMATS))
    names = _header(std)
    columns = draw(st.permutations(range(len(names))))
    note = draw(st.sampled_from([None, "note", "remarque"]))
    pad = draw(st.sampled_from(["", " ", "  "]))
    rows = [[names[c] for c in columns] + ([note] if note else [])]
    for k in order:
        cells = _cells(f, H, std, k, fmt)
        rows.append(
            [pad + cells[c] + pad for c in columns] + (["25 \u00b0C caf\u00e9"] if note else [])
        )
    lines = [",".join(r) for r in rows]
    for _ in range(draw(st.integers(0, 3))):  # blank lines anywhere (also before the header)
        lines.insert(draw(st.integers(0, len(lines))), draw(st.sampled_from(["", "  ", ",,"])))
    end = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    text = end.join(lines) + draw(st.sampled_from([end, ""]))
    encoding = draw(st.sampled_from(["utf-8", "utf-8-sig", "latin-1", "cp1252", "utf-16"]))
    return _clean_csv(f, H, std), text.encode(encoding)


@SETTINGS
@given(csv_variants())
def test_a_csv_written_otherwise_reads_as_its_clean_file(folder, files):
    clean, variant = files
    _same(_read(_file(folder, variant)), _read(_file(folder, clean)))


# --- CSV: damaged files ---------------------------------------------------------------------

_BAD_NUMBERS = [
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e300",
    "1e999",
    "2e6",
    "",
    "x",
    "1,5",
    "0x10",
    "1_0",
    "--1",
    "\u00b11",
]


#: Bytes spliced into a CSV as junk: none that can continue a number (a digit spliced into
#: one makes another number, which no reader can tell).
_JUNK = st.binary(min_size=1, max_size=12).map(
    lambda b: bytes(c for c in b if chr(c) not in "0123456789.eE+-_") or b"\x00"
)


@st.composite
def csv_damaged(draw):
    """(f, H, std, clean bytes, damaged bytes, kind) of one AFC."""
    f, H, std = draw(afcs())
    clean = _clean_csv(f, H, std)
    lines = clean.decode().splitlines()
    kind = draw(st.sampled_from(["cell", "conflict", "cut", "bytes", "frequency", "std"]))
    if kind == "cell":  # a bad number in one cell of re, im or std
        row = draw(st.integers(1, len(lines) - 1))
        cells = lines[row].split(",")
        cells[draw(st.integers(1, len(cells) - 1))] = draw(st.sampled_from(_BAD_NUMBERS))
        lines[row] = ",".join(cells)
    elif kind == "frequency":  # a frequency that is not a positive finite number
        row = draw(st.integers(1, len(lines) - 1))
        cells = lines[row].split(",")
        cells[0] = draw(st.sampled_from(["0", "-0.0", "-12.5", "inf", "nan", "1e400"]))
        lines[row] = ",".join(cells)
    elif kind == "std":  # a std that is no uncertainty, or a row without it
        if std is None:
            lines[0] += ",std"
        row = draw(st.integers(1, len(lines) - 1))
        cells = lines[row].split(",")[:3]
        cells.append(draw(st.sampled_from(["0", "-1e-3", "nan", "inf", "1e-300", "1e7", ""])))
        lines[row] = ",".join(cells)
    elif kind == "conflict":  # a second row at one frequency, another value
        k = draw(st.integers(0, len(f) - 1))
        lines.insert(draw(st.integers(1, len(lines))), ",".join(_cells(f, H * 1.5 + 1.0, std, k)))
    data = ("\n".join(lines) + "\n").encode()
    if kind == "cut":
        data = clean[: draw(st.integers(0, len(clean) - 1))]
    elif kind == "bytes":  # in the rows: junk that makes a header name another name makes
        at = draw(st.integers(clean.index(b"\n"), len(clean)))  # another column
        data = clean[:at] + draw(_JUNK) + clean[at:]
    return f, H, std, clean, data, kind


def _points(f, H, std) -> set:
    return {
        (float(f[k]), complex(H[k]), None if std is None else float(std[k])) for k in range(len(f))
    }


@SETTINGS
@given(csv_damaged())
def test_a_damaged_csv_is_refused_in_one_line_or_reads_as_what_it_holds(folder, case):
    """A bad number, frequency or std, a conflicting row: always refused. Junk spliced in:
    refused, or the same AFC (it fell on a blank, a line end, a column not read). A cut:
    refused, or every row the cut left complete (ended by its line end) and, at most, the
    cut row as it now reads (a cut inside the last number of a line cannot be told from a
    shorter number: the one truncation no CSV reader can see)."""
    f, H, std, clean, data, kind = case
    outcome, value = _outcome(_file(folder, data))
    if kind in ("cell", "frequency", "std", "conflict"):
        assert outcome == "refused", kind
        return
    if outcome == "refused":
        return
    read = _points(value.frequency_hz, value.H, value.std)
    if kind == "bytes":
        _same(value, _read(_file(folder, clean)))
        return
    complete = max(data.count(b"\n") - 1, 0)  # data rows ended by their line end
    kept = _points(f[:complete], H[:complete], None if std is None else std[:complete])
    assert kept <= read and len(read - kept) <= 1


# --- UFF58: the same points, written otherwise ----------------------------------------------


@st.composite
def uff_variants(draw):
    """(f, H, std, order): an AFC and the order its points are written in, some repeated as
    they are."""
    f, H, std = draw(afcs(with_std=True))
    n = len(f)
    order = list(draw(st.permutations(range(n))))
    order += draw(st.lists(st.integers(0, n - 1), max_size=3))
    return f, H, std, list(draw(st.permutations(order)))


@SETTINGS
@given(uff_variants(), st.sampled_from(["as written", "crlf", "blank lines", "bom"]))
def test_a_uff_written_otherwise_reads_as_its_clean_file(folder, afc, form):
    f, H, std, order = afc
    clean = folder / f"u{next(_names)}.uff"
    write_afc_uff(clean, f, H, std, session_id="s")
    p = folder / f"u{next(_names)}.uff"
    write_afc_uff(p, f[order], H[order], std[order], session_id="s")
    raw = p.read_bytes()
    raw = {
        "as written": raw,
        "crlf": raw.replace(b"\n", b"\r\n"),
        "blank lines": b"\n \n" + raw,
        "bom": b"\xef\xbb\xbf" + raw,
    }[form]
    _same(_read(_file(folder, raw, ".uff")), _read(clean))


@st.composite
def other_system_files(draw):
    """An AFC as another system writes it (pyuff: ASCII or binary, even or uneven abscissa),
    its points in another order, LF or CRLF line ends: (f, H, binary, even, order, crlf)."""
    f, H, _ = draw(afcs(with_std=False, min_size=3))
    binary, even = draw(st.integers(0, 1)), draw(st.booleans())
    if even:  # an analyser's grid (exact in E13.5), counting up or down
        f = draw(st.sampled_from([0.5, 1.25, 2.5, 10.0])) * np.arange(1, len(f) + 1)
        order = np.arange(len(f))[::-1] if draw(st.booleans()) else np.arange(len(f))
    else:
        order = np.array(draw(st.permutations(range(len(f)))))
    return f, H, binary, int(even), order, draw(st.booleans())


@SETTINGS
@given(other_system_files())
def test_another_system_s_uff_reads_as_its_clean_file(folder, case):
    """Read as the file of the same points in order is read (both refused alike where an
    ASCII abscissa's six digits make two frequencies one)."""
    from afc_files import write_pyuff_record as write

    f, H, binary, even, order, crlf = case
    clean = write(folder / f"o{next(_names)}.uff", f, H, spacing=even, binary=binary)
    p = write(folder / f"o{next(_names)}.uff", f[order], H[order], spacing=even, binary=binary)
    raw = p.read_bytes()
    if crlf:
        raw = raw.replace(b"\n", b"\r\n")
    got, want = _outcome(_file(folder, raw, ".uff")), _outcome(clean)
    assert got[0] == want[0], (got, want)
    if got[0] == "ok":
        _same(got[1], want[1])


# --- UFF58: damaged files ---------------------------------------------------------------------


@SETTINGS
@given(afcs(with_std=True), st.data())
def test_a_truncated_or_padded_uff_is_refused_in_one_line(folder, afc, data):
    """vibid's file cut anywhere: refused (a cut at the end of record 1 leaves the AFC
    without its std record: refused too), or, cut in the blanks after its last -1 line, as
    written. Junk appended after it or spliced in: refused, or as written."""
    f, H, std = afc
    clean = folder / f"t{next(_names)}.uff"
    write_afc_uff(clean, f, H, std, session_id="s")
    raw = clean.read_bytes()
    how = data.draw(st.sampled_from(["cut", "append", "splice"]))
    if how == "cut":
        damaged = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif how == "append":
        damaged = raw + data.draw(
            st.sampled_from([b"x", b"\n    -1\n", b"    -1\n    58\n", b"\x00\xff", b"1,2,3\n"])
        )
    else:
        at = data.draw(st.integers(0, len(raw)))
        damaged = raw[:at] + data.draw(st.binary(min_size=1, max_size=9)) + raw[at:]
    outcome, value = _outcome(_file(folder, damaged, ".uff"))
    if outcome == "ok":
        _same(value, _read(clean))


@SETTINGS
@given(afcs(with_std=True), st.data())
def test_a_bad_double_in_a_uff_is_refused_naming_its_point(folder, afc, data):
    """One number of the binary AFC record replaced in the file's bytes by NaN, inf or an
    absurd magnitude: refused, naming the point as the file lists it."""
    f, H, std = afc
    p = folder / f"d{next(_names)}.uff"
    write_afc_uff(p, f, H, std, session_id="s")
    raw = bytearray(p.read_bytes())
    start = raw.index(b"NONE                \n", raw.index(b"Base accel")) + 21
    k = data.draw(st.integers(0, len(f) - 1))
    part = data.draw(st.sampled_from([1, 2]))  # re or im (0: the frequency)
    value = data.draw(st.sampled_from([np.nan, np.inf, -np.inf, 1e308, -1e300, 2 * MAX_ABS_H]))
    raw[start + 8 * (3 * k + part) : start + 8 * (3 * k + part + 1)] = struct.pack("<d", value)
    q = _file(folder, bytes(raw), ".uff")
    outcome, message = _outcome(q)
    assert outcome == "refused"
    if np.isfinite(value) or part == 1:  # 1j * inf has a NaN real part: pyuff's own doing
        assert f"record 1, point {k + 1}: " in message, message


# --- the command line --------------------------------------------------------------------


def _uff_without_end(folder):
    p = folder / "cut.uff"
    write_afc_uff(
        p,
        np.array([100.0, 200.0]),
        np.array([1 + 0j, 2 + 0j]),
        np.array([0.01, 0.01]),
        session_id="s",
    )
    p.write_bytes(p.read_bytes()[:-40])
    return p


@pytest.mark.parametrize(
    "name, make, message",
    [
        (
            "zero.csv",
            lambda d: (
                "frequency_hz,re,im,std\n" + "".join(f"{10 * k},0,0,0.001\n" for k in range(1, 60))
            ),
            "every H is 0",
        ),
        (
            "huge.csv",
            lambda d: "frequency_hz,re,im\n10,1e308,0\n20,1e300,1e300\n",
            "line 2: re 1e+308",
        ),
        (
            "nyquist.csv",
            lambda d: "frequency_hz,re,im\n100,1,0\n12800,1,0\n",
            "line 3: 12800.0 Hz is not below the Nyquist frequency 12800.0 Hz",
        ),
        (
            "cr.csv",
            lambda d: "frequency_hz,re,im\r10,1,0\r20,1,x\r",
            "line 3: im 'x' is not a number",
        ),
        ("cut.uff", _uff_without_end, "truncated UFF file"),
    ],
)
def test_vibid_identify_refuses_a_bad_afc_in_one_line(tmp_path, name, make, message):
    """As a process: rc 1, exactly one line on stderr, no traceback, in a few seconds."""
    made = make(tmp_path)
    p = made if isinstance(made, Path) else tmp_path / name
    if not isinstance(made, Path):
        p.write_text(made, newline="")
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "vibid",
            "identify",
            "--afc",
            str(p),
            "--setup",
            str(TITANIUM_SETUP),
            "--json",
            str(tmp_path / "x.json"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        check=False,
    )
    assert run.returncode == 1, run.stderr
    assert run.stderr.count("\n") == 1 and "Traceback" not in run.stderr, run.stderr
    assert message in run.stderr and f"{p}: " in run.stderr
    assert not (tmp_path / "x.json").exists()
