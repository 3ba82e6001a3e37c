"""An AFC measured elsewhere: vibid identify --afc AFC.csv --setup SETUP.json, its one-line
errors, and the report's engineering block against the closed-form constants."""

import json
import math
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from afc_files import csv_lines, write_afc_csv
from plate_helpers import PAPER_D
from vibid.cli import main
from vibid.errors import VibidError
from vibid.identify.assess.engineering import engineering_constants
from vibid.setup_model import example_setup
from vibid.signal.imported import read_afc


def _setup_without_excitation(tmp_path, **specimen):
    doc = example_setup().to_dict()
    del doc["excitation"]
    doc["specimen"].update(specimen)
    p = tmp_path / "setup.json"
    p.write_text(json.dumps(doc))
    return p


def test_engineering_constants_are_the_closed_forms():
    # the paper's strip: E 198 GPa, nu 0.286, h 1 mm -> D = 17.97 N m
    out = engineering_constants(
        "isotropic",
        ("D", "nu", "beta"),
        [PAPER_D, 0.286, 0.003],
        np.diag([0.01**2, 0.0, 0.0]),
        0.001,
        1e-5,
    )
    assert out["E_Pa"]["value"] == pytest.approx(198e9, rel=1e-12)
    assert out["G_Pa"]["value"] == pytest.approx(198e9 / (2 * 1.286), rel=1e-12)
    # std: D's (E proportional to D) and the thickness's (E ~ h^-3) in quadrature
    rel = math.hypot(0.01 / PAPER_D, 3 * 1e-5 / 0.001)
    assert out["E_Pa"]["std"] == pytest.approx(198e9 * rel, rel=1e-6)
    assert out["nu"]["std"] == 0.0
    ortho = engineering_constants(
        "orthotropic",
        ("D11", "D12", "D22", "D66", "beta"),
        [10.0, 3.0, 5.0, 2.0, 0.003],
        np.zeros((5, 5)),
        0.002,
    )
    assert ortho["nu12"]["value"] == pytest.approx(0.6)
    assert ortho["E1_Pa"]["value"] == pytest.approx(12 * (10 - 9 / 5) / 0.002**3)
    assert ortho["G12_Pa"]["value"] == pytest.approx(12 * 2 / 0.002**3)


def test_an_imported_afc_is_identified_and_reported(tmp_path):
    """The strip's reduced-model AFC (0.3 % noise) as a CSV, with a setup that has no
    excitation: the declared model fits it, nothing is added, the report is strict JSON
    with a content-derived session id and the engineering block."""
    from vibid.identify import build_forward_model, configure

    configure()
    setup = example_setup()
    f = np.linspace(20.0, 900.0, 45)
    fm = build_forward_model(setup, f, theta0={"D": 17.97, "nu": 0.286, "beta": 0.003})
    H = np.asarray(fm.afc(np.array([17.97, 0.286, 0.003])))
    std = 0.003 * np.abs(H) + 1e-3
    rng = np.random.default_rng(4)
    Hn = H + std * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    csv = write_afc_csv(tmp_path / "afc.csv", f, Hn, std)
    setup_path = _setup_without_excitation(tmp_path, thickness_std_m=1e-5)
    report = tmp_path / "report.json"
    args = [
        "identify",
        "--afc",
        str(csv),
        "--setup",
        str(setup_path),
        "--json",
        str(report),
        "--no-progress",
        "--restarts",
        "2",
    ]
    assert main(args) == 0
    text = report.read_text()
    doc = json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    assert doc["effects"] == [] and doc["loop"]["unexplained_residual"] is False
    assert abs(doc["parameters"]["D"]["value"] - 17.97) < 3 * doc["parameters"]["D"]["std"]
    e = doc["engineering"]["E_Pa"]
    assert abs(e["value"] - 198e9) < 3 * e["std"]
    # the thickness's 1 %: through the conversion (h^-3) and the fit (a heavier plate,
    # a larger D: h^+1 without the sensor, less with its 1 g that h does not scale), so
    # between 2 % and 3 % of E
    part = doc["engineering"]["budget"]["E_Pa"]["thickness_m"]
    assert 0.02 * 198e9 < part < 0.03 * 198e9
    assert e["std"] == pytest.approx(
        math.sqrt(sum(v**2 for v in doc["engineering"]["budget"]["E_Pa"].values())), rel=1e-9
    )
    first = doc["session_id"]
    assert main(args) == 0
    assert json.loads(report.read_text())["session_id"] == first  # derived from the bytes


@pytest.mark.parametrize(
    "content, message",
    [
        ("frequency_hz,re\n1,2\n", "the header lacks im"),
        ("frequency_hz,re,im\n10,1,x\n20,1,0\n", "line 2: im 'x' is not a number"),
        ("frequency_hz,re,im\n10,1,0\n", "fewer than two AFC points"),
        ("frequency_hz,re,im,std\n10,1,0,-1\n20,1,0,1\n", "line 2: std -1.0 must be positive"),
    ],
)
def test_bad_csv_is_one_line(tmp_path, capsys, content, message):
    p = tmp_path / "afc.csv"
    p.write_text(content)
    setup_path = _setup_without_excitation(tmp_path)
    assert main(["identify", "--afc", str(p), "--setup", str(setup_path)]) == 1
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_afc_needs_its_setup(tmp_path, capsys):
    assert main(["identify", "--afc", str(tmp_path / "x.csv")]) == 1
    assert "--afc needs --setup" in capsys.readouterr().err


# --- issue 62: the CSV reader never hangs and is never silently wrong ----------------------

TITANIUM_SETUP = Path(__file__).parent / "data" / "titanium_setup.json"  # DAQ 25.6 kHz


def _strip_afc(n=80, seed=5):
    """An AFC of ``n`` distinct frequencies through a resonance, with its std."""
    rng = np.random.default_rng(seed)
    f = np.sort(rng.uniform(20.0, 1500.0, n))
    H = 1.0 / (1.0 - (f / 480.0) ** 2 + 0.01j) + 1e-3 * rng.standard_normal(n)
    return f, H, 1e-3 + 1e-3 * np.abs(H)


def _read_csv_lines(tmp_path, lines, name="afc.csv"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return read_afc(p)


def _same(a, b):
    assert np.array_equal(a.frequency_hz, b.frequency_hz)
    assert np.array_equal(a.H, b.H)
    assert (a.std is None) == (b.std is None)
    assert a.std is None or np.array_equal(a.std, b.std)


def test_a_descending_or_shuffled_csv_reads_as_the_sorted_one(tmp_path):
    """The same 80 rows reversed or shuffled: the same AFC, sorted by frequency, the rows
    it came from kept (line 2 is the file's first data line); the compressed problem's
    data (Gauss nodes, weights and pseudo-data of every band) alike, bit for bit."""
    from vibid.identify.fit.compress import NODES, project, quadratures

    f, H, std = _strip_afc()
    header, *rows = csv_lines(f, H, std)
    sorted_ = _read_csv_lines(tmp_path, [header, *rows])
    assert np.array_equal(sorted_.frequency_hz, f) and list(sorted_.rows) == list(range(2, 82))
    rng = np.random.default_rng(0)
    for order in (np.arange(80)[::-1], rng.permutation(80), rng.permutation(80)):
        other = _read_csv_lines(tmp_path, [header, *(rows[k] for k in order)])
        _same(other, sorted_)
        assert np.all(np.diff(other.frequency_hz) > 0)
        assert sorted_.where(0) == "line 2" and other.where(0) == f"line {2 + list(order).index(0)}"
        for a, b in ((0, 30), (30, 80)):
            qa = quadratures(sorted_.frequency_hz, sorted_.std**-2.0, NODES)(a, b)
            qb = quadratures(other.frequency_hz, other.std**-2.0, NODES)(a, b)
            assert all(np.array_equal(x, y) for x, y in zip(qa, qb))
            ca = project(sorted_.frequency_hz[a:b], sorted_.std[a:b] ** -2.0, sorted_.H[a:b], *qa)
            cb = project(other.frequency_hz[a:b], other.std[a:b] ** -2.0, other.H[a:b], *qb)
            assert np.array_equal(ca[0], cb[0]) and ca[1] == cb[1]


def test_repeated_rows_count_once_and_conflicting_ones_are_refused(tmp_path):
    """A row repeated as it is (a file concatenated twice) is one point; two rows at one
    frequency with different values are refused, naming both lines."""
    f, H, std = _strip_afc(20)
    header, *rows = csv_lines(f, H, std)
    clean = _read_csv_lines(tmp_path, [header, *rows])
    _same(_read_csv_lines(tmp_path, [header, *rows, *rows[::-1]]), clean)
    _same(_read_csv_lines(tmp_path, [header, rows[3], *rows]), clean)
    other = csv_lines(f[3:4], H[3:4] * 1.01, std[3:4])[1]
    with pytest.raises(VibidError) as err:
        _read_csv_lines(tmp_path, [header, *rows, other])
    assert str(err.value).endswith(
        f"afc.csv: lines 5 and 22 both give {float(f[3])!r} Hz, with "
        "different values: keep one of them, or average them"
    )
    with pytest.raises(VibidError, match="fewer than two AFC points"):
        _read_csv_lines(tmp_path, [header, rows[0], rows[0]])


@pytest.mark.parametrize(
    "rows, message",
    [
        (["10,0,0,1", "20,0,0,1"], "every H is 0: no response measured"),
        (["10,0,0", "20,0,0", "30,-0.0,0"], "every H is 0: no response measured"),
        (["10,1e-300,0,1", "20,0,1e-300,1"], "the largest |H| is 1e-300, below 1e-06"),
        (["10,1e-9,0", "20,2e-9,0"], "the largest |H| is 2e-09, below 1e-06"),
        (
            ["10,1e-3,0,1", "20,0,2e-3,1"],
            ("no point of the AFC stands above its std (the largest |H|/std is 0.002)"),
        ),
    ],
)
def test_an_afc_without_signal_is_refused_when_read(tmp_path, rows, message):
    """Every |H| zero (a response channel not connected), tiny, or under its own std: no
    measurement, refused before any fit, one line, without a numpy warning."""
    header = "frequency_hz,re,im" + (",std" if rows[0].count(",") == 3 else "")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(VibidError) as err:
            _read_csv_lines(tmp_path, [header, *rows])
    assert message in str(err.value) and "\n" not in str(err.value)


def test_an_afc_without_signal_is_rc_1_before_any_fit(tmp_path, capsys):
    p = tmp_path / "zero.csv"
    p.write_text(
        "frequency_hz,re,im,std\n" + "".join(f"{10 * k},0,0,0.001\n" for k in range(1, 80))
    )
    start = time.perf_counter()
    assert (
        main(
            [
                "identify",
                "--afc",
                str(p),
                "--setup",
                str(TITANIUM_SETUP),
                "--json",
                str(tmp_path / "x.json"),
            ]
        )
        == 1
    )
    assert time.perf_counter() - start < 2.0  # read and refused, no model built
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "zero.csv: every H is 0: no response measured" in err
    assert not (tmp_path / "x.json").exists()


@pytest.mark.parametrize(
    "row, message",
    [
        ("30,nan,0,1", "line 4: re is nan, not a finite number"),
        ("30,1,-inf,1", "line 4: im is -inf, not a finite number"),
        ("30,1e308,0,1", "line 4: re 1e+308 is beyond ±1e+06: an AFC is a ratio of accelerations"),
        ("30,1,-2e6,1", "line 4: im -2000000.0 is beyond ±1e+06"),
        ("30,1,0,1e300", "line 4: std 1e+300 is beyond ±1e+06"),
        ("30,1,0,0", "line 4: std 0.0 must be positive"),
        ("30,1,0,-1e-3", "line 4: std -0.001 must be positive"),
        ("30,1,0,nan", "line 4: std is nan, not a finite number"),
        ("30,1,0,1e-300", "line 4: std 1e-300 is below 1e-12 of the largest |H| (1.11803)"),
        ("0,1,0,1", "line 4: frequency_hz 0.0 Hz is not positive"),
        ("-30,1,0,1", "line 4: frequency_hz -30.0 Hz is not positive"),
        ("inf,1,0,1", "line 4: frequency_hz is inf, not a finite number"),
        ("1e999,1,0,1", "line 4: frequency_hz is inf, not a finite number"),
        ("30,1_0,0,1", "line 4: re '1_0' is not a number"),
        ("30,1,0", "line 4: std is missing"),
        ("30,1,5,0,1,1", "line 4: 6 fields, more than the header's 4 (a decimal comma?)"),
    ],
)
def test_absurd_or_non_finite_values_are_refused_naming_the_row(tmp_path, row, message):
    lines = ["frequency_hz,re,im,std", "10,1,0,1", "20,1,0.5,1", row, "40,1,0,1"]
    with pytest.raises(VibidError) as err:
        _read_csv_lines(tmp_path, lines)
    assert f"afc.csv: {message}" in str(err.value) and "\n" not in str(err.value)


def test_a_huge_file_with_one_absurd_value_is_refused_in_well_under_a_second(tmp_path):
    """20 000 good rows (an FFT analyser's grid), then re = 1e308 on the last line: about
    0.1 s here (0.4 s for 100 000 rows)."""
    p = tmp_path / "big.csv"
    p.write_text(
        "frequency_hz,re,im\n"
        + "".join(f"{10 + k * 0.01!r},1,0\n" for k in range(20_000))
        + "2000.5,1e308,0\n"
    )
    start = time.perf_counter()
    with pytest.raises(VibidError, match="big.csv: line 20002: re 1e\\+308 is beyond"):
        read_afc(p)
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize(
    "raw",
    [
        "frequency_hz,re,im\r10,1,0.5\r20,2,0\r",  # old Mac line ends: a csv.Error before
        "frequency_hz,re,im\r\n10,1,0.5\r\n\r\n20,2,0\r\n",
        "\n\nfrequency_hz,re,im\n10,1,0.5\n  \n,,\n20,2,0",
        "\ufefffrequency_hz,re,im\n10,1,0.5\n20,2,0\n",
        " frequency_hz , re , im ,note\n 10 , 1 , 0.5 ,x\n20,2,0,\n",
    ],
)
def test_line_ends_blank_lines_and_byte_order_marks_read_as_the_clean_file(tmp_path, raw):
    clean = _read_csv_lines(tmp_path, ["frequency_hz,re,im", "10,1,0.5", "20,2,0"], "clean.csv")
    p = tmp_path / "afc.csv"
    p.write_bytes(raw.encode())
    _same(read_afc(p), clean)


@pytest.mark.parametrize(
    "raw",
    [
        "frequency_hz,re,im,note\n10,1,0.5,caf\xe9\n20,2,0,25 \xb0C\n".encode("latin-1"),
        "frequency_hz,re,im\n10,1,0.5\n20,2,0\n".encode("utf-16"),
    ],
)
def test_latin_1_and_utf_16_files_read_as_the_clean_file(tmp_path, raw):
    clean = _read_csv_lines(tmp_path, ["frequency_hz,re,im", "10,1,0.5", "20,2,0"], "clean.csv")
    p = tmp_path / "afc.csv"
    p.write_bytes(raw)
    _same(read_afc(p), clean)


@pytest.mark.parametrize(
    "raw, message",
    [
        (
            "frequency_hz;re;im\n10;1;0\n20;1;0\n",
            "(is it separated by ';' or tabs? commas are expected)",
        ),
        ("frequency_hz,re,im,re\n10,1,0,2\n20,1,0,2\n", "the header names re more than once"),
        (
            "frequency_hz,re,im,Std\n10,1,0,2\n20,1,0,2\n",
            "the header's column 'Std' is not 'std' (the column names are exact)",
        ),
        (
            "frequency_hz,re,im,\x00std\n10,1,0,2\n20,1,0,2\n",
            "the header's column '\\x00std' is not 'std'",
        ),
        (
            "frequency_hz,re,im,std_re\n10,1,0,2\n20,1,0,2\n",
            "the header's column 'std_re' is not 'std'",
        ),
        ('frequency_hz,re,im\n10,1,"' + "9" * 200_000 + '"\n', "line 2: not CSV (field larger"),
    ],
)
def test_csv_that_cannot_be_read_is_one_line(tmp_path, raw, message):
    p = tmp_path / "afc.csv"
    p.write_text(raw)
    with pytest.raises(VibidError) as err:
        read_afc(p)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_frequency_at_or_above_the_daq_s_nyquist_is_refused_where_afc_and_setup_meet(
    tmp_path, capsys
):
    """The titanium setup's DAQ samples at 25.6 kHz: 12.8 kHz and above are in no record.
    The row is the file's (the AFC is sorted when read: line 3 is the first one listed)."""
    from vibid.pipeline import afc_file

    p = tmp_path / "afc.csv"
    p.write_text("frequency_hz,re,im,std\n100,1,0,0.01\n13000,0.1,0,0.01\n12800,0.2,0,0.01\n")
    with pytest.raises(VibidError) as err:
        afc_file(p, TITANIUM_SETUP)
    assert str(err.value) == (
        f"{p}: line 3: 13000.0 Hz is not below the Nyquist frequency "
        "12800.0 Hz of the setup's DAQ (daq.sample_rate_hz 25600.0) "
        "(and 1 more points)"
    )
    p.write_text("frequency_hz,re,im,std\n100,1,0,0.01\n12799.99,0.1,0,0.01\n")
    assert afc_file(p, TITANIUM_SETUP).afc.frequency_hz[-1] == 12799.99
    p.write_text("frequency_hz,re,im,std\n100,1,0,0.01\n12800,0.1,0,0.01\n")
    assert main(["identify", "--afc", str(p), "--setup", str(TITANIUM_SETUP)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "line 3: 12800.0 Hz is not below the Nyquist" in err


def test_a_session_file_given_as_afc_is_named_for_what_it_is(tmp_path):
    p = tmp_path / "s.h5"
    p.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(256)) * 40)
    with pytest.raises(VibidError, match="s.h5: an HDF5 file, not an AFC"):
        read_afc(p)
