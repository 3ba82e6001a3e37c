"""The AFC as UFF58 (vibid.signal.uff): an exact round trip, files pyuff itself reads, files
of other systems, detection by content, one-line errors, and `vibid afc --uff` followed by
`vibid identify --afc` identifying exactly what the session identifies."""

import dataclasses
import json

import numpy as np
import pyuff
import pytest
from afc_files import write_afc_csv

from vibid.cli import main
from vibid.errors import VibidError
from vibid.setup_model import example_setup
from vibid.signal.imported import read_afc
from vibid.signal.uff import is_uff, read_afc_uff, write_afc_uff

#: Refined frequencies as the signal stage gives them (ppm off the commanded ones, every
#: digit significant), an AFC through a resonance and its std.
F = np.array([22.500903217, 45.001806431, 67.50270965, 90.003612866, 497.13370021])
H = np.array([1.0012 - 3.1e-4j, 1.00481 - 0.00123j, 1.011 + 2.5e-9j, -3.7 + 41.2345678901234j,
              0.123456789012345 - 1e-12j])
STD = np.array([1.1e-5, 1.2e-5, 1.3e-5, 4.1e-4, 9.9e-6])


def _write(tmp_path, name="afc.uff", **kw):
    p = tmp_path / name
    write_afc_uff(p, F, H, STD, session_id=kw.pop("session_id", "s-1"), **kw)
    return p


def _pyuff_record(path, x, data, *, spacing, binary=0, id1="other system"):
    """A type-58 record as another system would write it (pyuff directly)."""
    pyuff.UFF(str(path)).write_sets({
        "type": 58, "binary": binary, "func_type": 4, "id1": id1, "rsp_node": 1, "rsp_dir": 3,
        "ref_node": 1, "ref_dir": 3, "abscissa_spacing": spacing, "abscissa_spec_data_type": 18,
        "ordinate_spec_data_type": 12, "orddenom_spec_data_type": 13,
        "z_axis_spec_data_type": 0, "x": x, "data": data}, mode="add")


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


@pytest.mark.parametrize("content, message", [
    (b"", "empty file"),
    (b"    -1\n    58\nNONE\nrubbish\n    -1\n", "UFF record 1 (dataset 58) cannot be read"),
    (b"    -1\n  2411\n         1\n    -1\n", "no type-58 record"),
    (b"frequency_hz,re,im\n1,2,3\n", "not a UFF file"),
])
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
    for cut, message in ((len(raw) // 2, "truncated"), (len(raw) - 30, "truncated"),
                         (end_of_first, "std record ('vibid AFC std') of this vibid AFC")):
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
    with pytest.raises(VibidError, match="record 1, point 1: frequency_hz -497.13370021 Hz is not positive"):
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
    s = dataclasses.replace(s, excitation=dataclasses.replace(s.excitation,
                                                              frequencies_hz=STEPS_HZ))
    simulate_session(folder / "sim.h5", s, {"D": 17.97, "nu": 0.286, "beta": 0.003}, seed=1,
                     accuracy="default")
    path = folder / "session.h5"
    with (read_session(folder / "sim.h5") as r,
          SessionWriter(path, r.setup, session_id="uff-test") as w):
        for step in r.steps():
            w.append(frequency_hz=step.frequency_hz, sample_rate_hz=step.sample_rate_hz,
                     base=step.base, response=step.response,
                     status="overload" if step.index == OVERLOADED else "ok")
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
    assert main(["identify", "--afc", str(uff), "--setup", str(setup),
                 "--json", str(folder / "b.json"), *common]) == 0
    a = json.loads((folder / "a.json").read_text())
    b = json.loads((folder / "b.json").read_text())
    assert set(a["parameters"]) == set(b["parameters"]) == {"D", "nu", "beta"}
    for name, p in a["parameters"].items():
        assert b["parameters"][name]["value"] == pytest.approx(p["value"], rel=1e-6), name
        assert b["parameters"][name]["std"] == pytest.approx(p["std"], rel=1e-6), name
    assert b["afc"]["frequency_hz"] == a["afc"]["frequency_hz"]
    assert b["session_id"] == read_afc(uff).session_id != a["session_id"]
