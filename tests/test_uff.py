"""The AFC as UFF58 (vibid.signal.uff): an exact round trip, files pyuff itself reads, files
of other systems, detection by content, one-line errors, and `vibid afc --uff` followed by
`vibid identify --afc` identifying exactly what the session identifies."""

import dataclasses
import json
import struct

import numpy as np
import pytest
import pyuff

from afc_files import write_afc_csv, write_pyuff_record
from vibid.cli import main
from vibid.errors import VibidError
from vibid.setup_model import example_setup
from vibid.signal.imported import read_afc
from vibid.signal.uff import is_uff, read_afc_uff, write_afc_uff

#: Refined frequencies as the signal stage gives them (ppm off the commanded ones, every
#: digit significant), an AFC through a resonance and its std.
F = np.array([22.500903217, 45.001806431, 67.50270965, 90.003612866, 497.13370021])
H = np.array(
    [
        1.0012 - 3.1e-4j,
        1.00481 - 0.00123j,
        1.011 + 2.5e-9j,
        -3.7 + 41.2345678901234j,
        0.123456789012345 - 1e-12j,
    ]
)
STD = np.array([1.1e-5, 1.2e-5, 1.3e-5, 4.1e-4, 9.9e-6])


def _write(tmp_path, name="afc.uff", **kw):
    p = tmp_path / name
    write_afc_uff(p, F, H, STD, session_id=kw.pop("session_id", "s-1"), **kw)
    return p


_pyuff_record = write_pyuff_record  # a type-58 record as another system would write it


def test_round_trip_is_exact_and_the_id_follows_the_bytes(tmp_path):
    """58b stores the doubles themselves: frequencies, H and std come back bit for bit (the
    ASCII form would keep six digits of the frequencies). The same AFC gives the same bytes
    (no date in the file), hence the same session id; another AFC another id."""
    p = _write(tmp_path)
    afc = read_afc_uff(p)
    assert np.array_equal(afc.frequency_hz, F)
    assert np.array_equal(afc.H, H) and afc.H.dtype == np.complex128
    assert np.array_equal(afc.std, STD)
    assert afc.used.all() and afc.used.size == F.size
    q = _write(tmp_path, "again.uff")
    assert q.read_bytes() == p.read_bytes()
    assert read_afc_uff(q).session_id == afc.session_id
    write_afc_uff(q, F, H * 1.001, STD, session_id="s-1")
    assert read_afc_uff(q).session_id != afc.session_id
    assert not list(tmp_path.glob(".*.tmp"))  # the temporary file is gone


def test_pyuff_reads_it_as_promised(tmp_path):
    """Record 1: a complex double FRF (type 4; acceleration over acceleration) at an uneven
    abscissa in Hz; record 2: its std, real double, marked as vibid's; the 58b byte count
    is the true one (pyuff 2.5.8 alone writes 8 bytes per point)."""
    p = _write(tmp_path, session_id="abc-123", description="plate 7, run 2")
    uff = pyuff.UFF(str(p))
    assert list(uff.get_set_types()) == [58, 58]
    afc, std = uff.read_sets()
    assert (afc["func_type"], afc["ord_data_type"], afc["abscissa_spacing"]) == (4, 6, 0)
    assert (afc["abscissa_spec_data_type"], afc["abscissa_axis_units_lab"]) == (18, "Hz")
    assert afc["ordinate_spec_data_type"] == afc["orddenom_spec_data_type"] == 12
    assert afc["id1"] == "vibid AFC" and afc["id2"] == "session abc-123"
    assert afc["id4"] == "plate 7, run 2"
    assert (std["ord_data_type"], std["id1"], std["id2"]) == (4, "vibid AFC std", "session abc-123")
    assert afc["n_bytes"] == 3 * 8 * F.size and std["n_bytes"] == 2 * 8 * F.size
    assert np.array_equal(afc["x"], F) and np.array_equal(afc["data"], H)
    assert np.array_equal(std["x"], F) and np.array_equal(std["data"], STD)


def test_read_afc_goes_by_content_not_by_extension(tmp_path):
    uff_named_csv = _write(tmp_path, "really_uff.csv")
    csv_named_uff = write_afc_csv(tmp_path / "really_csv.uff", F, H, STD)
    assert is_uff(uff_named_csv) and not is_uff(csv_named_uff)
    for p in (uff_named_csv, csv_named_uff):
        afc = read_afc(p)
        assert np.array_equal(afc.frequency_hz, F) and np.array_equal(afc.H, H)
        assert np.array_equal(afc.std, STD)
    assert not is_uff(tmp_path / "missing.uff")


def test_an_even_spaced_ascii_file_of_another_system(tmp_path):
    """An FFT analyser's FRF: ASCII, even spacing from 0 Hz (its DC line is dropped), no std
    record (std None, as a CSV without a std column)."""
    x = np.arange(41) * 2.5
    data = 1.0 / (1.0 - (x / 60.0) ** 2 + 0.02j)
    p = tmp_path / "analyser.unv"
    _pyuff_record(p, x, data, spacing=1)
    afc = read_afc(p)
    np.testing.assert_allclose(afc.frequency_hz, x[1:], rtol=1e-12)
    np.testing.assert_allclose(afc.H, data[1:], rtol=1e-10)  # ASCII: E20.11
    assert afc.std is None


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "empty file"),
        (b"    -1\n    58\nNONE\nrubbish\n    -1\n", "UFF record 1 (dataset 58) cannot be read"),
        (b"    -1\n  2411\n         1\n    -1\n", "no type-58 record"),
        (b"frequency_hz,re,im\n1,2,3\n", "not a UFF file"),
    ],
)
def test_junk_is_one_line(tmp_path, content, message):
    p = tmp_path / "junk.uff"
    p.write_bytes(content)
    with pytest.raises(VibidError) as err:
        read_afc_uff(p)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert str(p) in str(err.value)


def test_truncated_files_are_refused(tmp_path):
    raw = _write(tmp_path).read_bytes()
    end_of_first = raw.index(b"    -1\n    -1\n") + 7
    for cut, message in (
        (len(raw) // 2, "truncated"),
        (len(raw) - 30, "truncated"),
        (end_of_first, "std record ('vibid AFC std') of this vibid AFC"),
    ):
        p = tmp_path / "cut.uff"
        p.write_bytes(raw[:cut])
        with pytest.raises(VibidError, match="cut.uff: ") as err:
            read_afc_uff(p)
        assert message in str(err.value) and "\n" not in str(err.value)


def test_only_real_records_and_bad_frequencies(tmp_path):
    real = tmp_path / "real.uff"
    _pyuff_record(real, F, STD, spacing=0, binary=1)
    with pytest.raises(VibidError, match="only real type-58 records"):
        read_afc_uff(real)
    negative = tmp_path / "negative.uff"
    _pyuff_record(negative, -F[::-1], H, spacing=0, binary=1)
    with pytest.raises(
        VibidError, match="record 1, point 1: frequency_hz -497.13370021 Hz is not positive"
    ):
        read_afc_uff(negative)
    with pytest.raises(VibidError, match="not finite"):
        write_afc_uff(tmp_path / "nan.uff", F, H * np.nan, STD, session_id="x")
    assert not (tmp_path / "nan.uff").exists()


def test_identify_refuses_a_bad_uff_in_one_line(tmp_path, capsys):
    p = tmp_path / "afc.csv"  # a UFF by content, whatever its name
    p.write_bytes(b"    -1\n    58\nNONE\n")
    setup = tmp_path / "setup.json"
    setup.write_text(json.dumps(example_setup().to_dict()))
    assert main(["identify", "--afc", str(p), "--setup", str(setup)]) == 1
    err = capsys.readouterr().err
    assert "afc.csv: truncated UFF file" in err and err.count("\n") == 1


#: 20 steps of 45 Hz to 900 Hz: the strip's first three modes (75, 497, 790 Hz) in the band,
#: a small search. The virtual specimen on the identification's own mesh ("default"): only
#: the exchange is under test here, not the model.
STEPS_HZ = tuple(45.0 * k for k in range(1, 21))
OVERLOADED = 3


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A simulated strip session whose step 3 is marked overloaded (left out of the fit):
    (folder, session path, setup JSON path)."""
    from vibid.hardware_mocks.simulated_session import simulate_session
    from vibid.session import SessionWriter, read_session

    folder = tmp_path_factory.mktemp("uff-cli")
    s = example_setup()
    s = dataclasses.replace(
        s, excitation=dataclasses.replace(s.excitation, frequencies_hz=STEPS_HZ)
    )
    simulate_session(
        folder / "sim.h5", s, {"D": 17.97, "nu": 0.286, "beta": 0.003}, seed=1, accuracy="default"
    )
    path = folder / "session.h5"
    with (
        read_session(folder / "sim.h5") as r,
        SessionWriter(path, r.setup, session_id="uff-test") as w,
    ):
        for step in r.steps():
            w.append(
                frequency_hz=step.frequency_hz,
                sample_rate_hz=step.sample_rate_hz,
                base=step.base,
                response=step.response,
                status="overload" if step.index == OVERLOADED else "ok",
            )
        setup = folder / "setup.json"
        setup.write_text(json.dumps(r.setup.to_dict()))
    return folder, path, setup


def test_afc_uff_refuses_a_missing_folder_before_fitting(session, tmp_path, capsys):
    _, path, _ = session
    target = tmp_path / "nope" / "afc.uff"
    assert main(["afc", str(path), "--uff", str(target)]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and "does not exist" in captured.err
    assert captured.err.count("\n") == 1


@pytest.mark.slow
def test_afc_uff_then_identify_gives_the_session_s_parameters(session, capsys):
    """`vibid afc --uff` writes the used steps at their refined frequencies with the report's
    std; `vibid identify --afc` of that file identifies what the session identifies (equal
    to relative 1e-6; in fact bit for bit: the fit sees the same doubles)."""
    folder, path, setup = session
    uff, afc_json = folder / "afc.uff", folder / "afc.json"
    assert main(["afc", str(path), "--uff", str(uff), "--json", str(afc_json)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    n_used = len(STEPS_HZ) - 1
    assert out[-1] == f"{n_used} used steps written to {uff} (UFF58: the AFC, then its std)"
    block = json.loads(afc_json.read_text())["afc"]
    afc = read_afc(uff)
    assert afc.frequency_hz.size == n_used
    assert np.array_equal(afc.frequency_hz, block["frequency_hz"])  # refined, not commanded
    assert not np.array_equal(afc.frequency_hz, np.delete(STEPS_HZ, OVERLOADED))
    assert np.array_equal(afc.H, np.array(block["re"]) + 1j * np.array(block["im"]))
    assert np.array_equal(afc.std, block["std"])
    # a CSV of the same numbers reads as the same AFC
    csv = write_afc_csv(folder / "afc.csv", afc.frequency_hz, afc.H, afc.std)
    same = read_afc(csv)
    assert np.array_equal(same.H, afc.H) and np.array_equal(same.std, afc.std)

    common = ["--no-loop", "--restarts", "1", "--seed", "0", "--no-progress"]
    assert main(["identify", str(path), "--json", str(folder / "a.json"), *common]) == 0
    assert (
        main(
            [
                "identify",
                "--afc",
                str(uff),
                "--setup",
                str(setup),
                "--json",
                str(folder / "b.json"),
                *common,
            ]
        )
        == 0
    )
    a = json.loads((folder / "a.json").read_text())
    b = json.loads((folder / "b.json").read_text())
    assert set(a["parameters"]) == set(b["parameters"]) == {"D", "nu", "beta"}
    for name, p in a["parameters"].items():
        assert b["parameters"][name]["value"] == pytest.approx(p["value"], rel=1e-6), name
        assert b["parameters"][name]["std"] == pytest.approx(p["std"], rel=1e-6), name
    assert b["afc"]["frequency_hz"] == a["afc"]["frequency_hz"]
    assert b["session_id"] == read_afc(uff).session_id != a["session_id"]


# --- issue 62: the UFF58 reader never hangs and is never silently wrong --------------------


def _many(n=80, seed=1):
    """``n`` refined frequencies, an AFC and its std whose doubles hold LF bytes (0x0A) in
    their binary form, as real ones do."""
    rng = np.random.default_rng(seed)
    f = np.sort(rng.uniform(20.0, 1500.0, n))
    return f, rng.normal(size=n) + 1j * rng.normal(size=n), rng.uniform(1e-3, 2e-3, n)


def _same(a, b):
    assert np.array_equal(a.frequency_hz, b.frequency_hz) and np.array_equal(a.H, b.H)
    assert (a.std is None and b.std is None) or np.array_equal(a.std, b.std)


def test_a_shuffled_uff_reads_as_the_sorted_one(tmp_path):
    """vibid's own binary records, another system's ASCII and binary ones, an even abscissa
    counting down: the points come back sorted by frequency, as the sorted file's; the rows
    named are the record's points."""
    f, h, s = _many()
    write_afc_uff(tmp_path / "sorted.uff", f, h, s, session_id="s")
    clean = read_afc(tmp_path / "sorted.uff")
    shuffled = np.random.default_rng(2).permutation(f.size)
    for k, order in enumerate((shuffled, np.arange(f.size)[::-1])):
        write_afc_uff(tmp_path / f"v{k}.uff", f[order], h[order], s[order], session_id="s")
        back = read_afc(tmp_path / f"v{k}.uff")
        _same(back, clean)
        assert back.where(0) == f"record 1, point {list(order).index(0) + 1}"
        for binary in (0, 1):
            p = write_pyuff_record(
                tmp_path / f"o{k}{binary}.uff", f[order], h[order], spacing=0, binary=binary
            )
            q = write_pyuff_record(tmp_path / f"c{k}{binary}.uff", f, h, spacing=0, binary=binary)
            _same(read_afc(p), read_afc(q))
    x = np.arange(1, 41) * 2.5
    data = 1.0 / (1.0 - (x / 60.0) ** 2 + 0.02j)
    down = read_afc(write_pyuff_record(tmp_path / "down.uff", x[::-1], data[::-1], spacing=1))
    up = read_afc(write_pyuff_record(tmp_path / "up.uff", x, data, spacing=1))
    _same(down, up)


def test_repeated_uff_points_count_once_and_conflicting_ones_are_refused(tmp_path):
    p = tmp_path / "afc.uff"
    write_afc_uff(p, F, H, STD, session_id="s")
    clean = read_afc(p)
    again = np.r_[np.arange(F.size), 1, 3]
    write_afc_uff(p, F[again], H[again], STD[again], session_id="s")
    _same(read_afc(p), clean)
    write_afc_uff(p, np.r_[F, F[1]], np.r_[H, H[1] * 1.5], np.r_[STD, STD[1]], session_id="s")
    with pytest.raises(VibidError) as err:
        read_afc(p)
    assert str(err.value) == (
        f"{p}: record 1, points 2 and 6 both give {float(F[1])!r} Hz, with "
        "different values: keep one of them, or average them"
    )


def test_a_crlf_uff_file_reads_as_written(tmp_path):
    """Every LF made CRLF (a text-mode copy): the ASCII header lines read as they are, and a
    binary record's doubles, shifted by the inserted CRs, are read as they were written —
    before, vibid's own file lost its std record ("missing or not at its frequencies") and
    another system's binary record read as other numbers."""
    f, h, s = _many()
    p = tmp_path / "afc.uff"
    write_afc_uff(p, f, h, s, session_id="s")
    clean = read_afc(p)
    raw = p.read_bytes()
    assert raw.count(b"\n") > 28  # LF bytes inside the doubles, not only line ends
    crlf = tmp_path / "crlf.uff"
    crlf.write_bytes(raw.replace(b"\n", b"\r\n"))
    _same(read_afc(crlf), clean)
    assert read_afc(crlf).session_id != clean.session_id  # the id is the file's bytes'
    for binary in (0, 1):
        other = write_pyuff_record(tmp_path / f"other{binary}.uff", f, h, spacing=0, binary=binary)
        crlf.write_bytes(other.read_bytes().replace(b"\n", b"\r\n"))
        _same(read_afc(crlf), read_afc(other))


def test_a_damaged_binary_record_is_refused_not_read_shifted(tmp_path):
    """Bytes lost inside a binary record that still ends with its -1 line: refused with the
    record's sizes, never read as shifted numbers."""
    raw = _write(tmp_path).read_bytes()
    start = raw.index(b"NONE                \n", raw.index(b"Base accel")) + 21  # record 1's data
    p = tmp_path / "damaged.uff"
    p.write_bytes(raw[: start + 10] + raw[start + 13 :])
    with pytest.raises(VibidError) as err:
        read_afc(p)
    assert str(err.value) == (
        f"{p}: UFF record 1 (dataset 58b) holds 117 bytes of binary data "
        "where its 5 points take 120 (truncated, or damaged in a copy: "
        "copy binary UFF files as binary)"
    )


@pytest.mark.parametrize(
    "content, message",
    [
        (
            b"    -1\n  garbage\n    -1\n",
            "not a readable UFF file (no dataset number after its first -1 line)",
        ),
        (b"-1\n58\n-1\n", "not a readable UFF file (its -1 lines must be right-justified"),
        (b"\n  \n\t-1\n    58\n", "not a readable UFF file (its -1 lines must be right-justified"),
        (b"    -1\n  2411\n         1\n    -1\n    -1\n    58\n", "truncated UFF file"),
        (b"    -1\n", "truncated UFF file"),
    ],
)
def test_a_file_starting_with_minus_1_is_judged_as_uff(tmp_path, content, message):
    """A file whose first non-blank line is -1 is UFF, whatever follows: its faults are
    UFF faults in one line (before, such files were read as CSV: "the header lacks ...")."""
    p = tmp_path / "junk.csv"
    p.write_bytes(content)
    assert is_uff(p)
    with pytest.raises(VibidError) as err:
        read_afc(p)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_leading_blank_lines_and_a_truncated_end_of_a_uff_file(tmp_path):
    raw = _write(tmp_path).read_bytes()
    clean = read_afc(tmp_path / "afc.uff")
    p = tmp_path / "blank.uff"
    p.write_bytes(b"\n   \n" + raw)
    _same(read_afc(p), clean)
    end_of_first = raw.index(b"    -1\n    -1\n") + 7
    p.write_bytes(raw[: end_of_first + 6])  # record 2's -1 line and nothing after it
    with pytest.raises(VibidError, match="truncated UFF file"):
        read_afc(p)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda h, s: (h * 0.0, s), "every H is 0: no response measured"),
        (
            lambda h, s: (np.where(np.arange(h.size) == 2, 1e300, h), s),
            "record 1, point 3: re 1e+300 is beyond ±1e+06",
        ),
        (
            lambda h, s: (h, np.where(np.arange(s.size) == 4, 0.0, s)),
            "record 1, point 5: std 0.0 must be positive",
        ),
    ],
)
def test_absurd_uff_values_are_refused_naming_the_point(tmp_path, change, message):
    h, s = change(H.copy(), STD.copy())
    p = tmp_path / "afc.uff"
    write_afc_uff(p, F, h, s, session_id="s")
    with pytest.raises(VibidError) as err:
        read_afc(p)
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "value, message",
    [
        (np.nan, "record 1, point 3: re is nan, not a finite number"),
        (np.inf, "record 1, point 3: re is inf, not a finite number"),
        (1e308, "record 1, point 3: re 1e+308 is beyond ±1e+06"),
    ],
)
def test_non_finite_binary_doubles_are_refused_naming_the_point(tmp_path, value, message):
    """Point 3's real part replaced in the file's bytes (pyuff's writer would write 0 for a
    NaN)."""
    raw = bytearray(_write(tmp_path).read_bytes())
    start = raw.index(b"NONE                \n", raw.index(b"Base accel")) + 21  # record 1's data
    raw[start + 56 : start + 64] = struct.pack("<d", value)  # (x, re, im) per point
    p = tmp_path / "bad.uff"
    p.write_bytes(bytes(raw))
    with pytest.raises(VibidError) as err:
        read_afc(p)
    assert f"bad.uff: {message}" in str(err.value) and "\n" not in str(err.value)


def test_a_uff_frequency_above_the_daq_s_nyquist_is_refused(tmp_path):
    from vibid.pipeline import afc_file

    setup = tmp_path / "setup.json"
    setup.write_text(json.dumps(example_setup().to_dict()))  # DAQ 25.6 kHz
    p = tmp_path / "afc.uff"
    write_afc_uff(p, np.r_[F, 20000.0], np.r_[H, 0.1], np.r_[STD, 1e-3], session_id="s")
    with pytest.raises(VibidError) as err:
        afc_file(p, setup)
    assert str(err.value) == (
        f"{p}: record 1, point 6: 20000.0 Hz is not below the Nyquist "
        "frequency 12800.0 Hz of the setup's DAQ (daq.sample_rate_hz "
        "25600.0)"
    )
