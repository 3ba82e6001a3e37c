"""Damaged session files: every variant is either read exactly as written or refused in one line.

A small valid session (four steps of 512 samples) is damaged in 240 seeded ways: a zeroed
block anywhere, a flipped bit anywhere, in a record's chunk, in a B-tree node or in the
superblock, and a truncation. For each, the validator and the reader (what ``vibid validate``,
``vibid afc``, ``vibid identify`` and ``--resume`` read through) must either give back the
written samples bit for bit, or refuse with one line that names the file — never an
exception of the HDF5 library, a hang or a crash. A flipped sample is refused by its checksum.
"""

from __future__ import annotations

import re

import h5py
import numpy as np
import pytest

from vibid.cli import main
from vibid.hardware_mocks.records import synthetic_step
from vibid.session import SessionFileError, SessionWriter, file_problems, read_session
from vibid.setup_model import example_setup
from vibid.signal import afc_from_session

FREQUENCIES_HZ = (100.0, 200.0, 300.0, 400.0)
N_VARIANTS = 240


def _write(path) -> None:
    with SessionWriter(
        path, example_setup(), session_id="damage-test", created_utc="2026-11-22T04:00:00+00:00"
    ) as w:
        for k, f in enumerate(FREQUENCIES_HZ):
            base, response = synthetic_step(
                f,
                0.5 + 0.2j,
                sample_rate_hz=25600.0,
                n_samples=512,
                noise_std_m_s2=(1e-3, 1e-3),
                rng=k,
            )
            w.append(
                frequency_hz=f,
                sample_rate_hz=25600.0,
                base=base,
                response=response,
                t0_utc="2026-11-22T04:00:00+00:00",
            )


def _contents(path):
    """Everything a reader gives back: the samples apart from the rest."""
    with read_session(path) as s:
        steps = list(s.steps())
        samples = [(st.base, st.response) for st in steps]
        rest = (
            s.setup,
            s.session_id,
            s.created_utc,
            s.software,
            s.run_status,
            [(st.frequency_hz, st.sample_rate_hz, st.t0_utc, st.status) for st in steps],
        )
    return samples, rest


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    path = tmp_path_factory.mktemp("damage") / "S.h5"
    _write(path)
    data = path.read_bytes()
    with h5py.File(path, "r") as f:
        chunks = {}
        for k in range(len(FREQUENCIES_HZ)):
            for name in ("base", "response"):
                info = f[f"steps/{k:06d}/{name}"].id.get_chunk_info(0)
                chunks[f"/steps/{k:06d}/{name}"] = (info.byte_offset, info.size)
    btree_nodes = [m.start() for m in re.finditer(b"TREE", data)]
    assert len(btree_nodes) >= 2 * len(FREQUENCIES_HZ)  # a chunk index per record at least
    return {
        "path": path,
        "data": data,
        "chunks": chunks,
        "btree_nodes": btree_nodes,
        "contents": _contents(path),
    }


def _variants(original, n, seed=20261122):
    """(description, damaged bytes, chunk path or None) for ``n`` seeded damages."""
    rng = np.random.default_rng(seed)
    data = original["data"]
    chunk_items = sorted(original["chunks"].items())
    kinds = ("zero", "flip", "chunk", "btree", "superblock", "truncate")
    for i in range(n):
        kind = kinds[i % len(kinds)]
        b = bytearray(data)
        hit = None
        if kind == "zero":
            at, length = int(rng.integers(len(b))), int(rng.integers(1, 8192))
            b[at : at + length] = bytes(len(b[at : at + length]))
            desc = f"zero {length} bytes at {at}"
        elif kind == "truncate":
            at = int(rng.integers(len(b)))
            del b[at:]
            desc = f"truncate at {at}"
        else:
            if kind == "chunk":
                hit, (start, size) = chunk_items[int(rng.integers(len(chunk_items)))]
                at = start + int(rng.integers(size))
            elif kind == "btree":
                at = original["btree_nodes"][int(rng.integers(len(original["btree_nodes"])))] + int(
                    rng.integers(48)
                )
            elif kind == "superblock":
                at = int(rng.integers(96))
            else:
                at = int(rng.integers(len(b)))
            bit = 1 << int(rng.integers(8))
            b[at] ^= bit
            desc = f"flip bit {bit} of byte {at} ({kind})"
        if hit is None:  # a zeroed block or a flip that lands in a chunk counts as one too
            for name, (start, size) in chunk_items:
                lo, hi = (at, at + length) if kind == "zero" else (at, at + 1)
                if (
                    kind != "truncate"
                    and lo < start + size
                    and start < hi
                    and bytes(b[start : start + size]) != data[start : start + size]
                ):
                    hit = name
        yield desc, bytes(b), hit


def _one_line_naming(path, text: str) -> None:
    assert "\n" not in text.strip(), text
    assert str(path) in text, text
    assert "internal error" not in text and "Traceback" not in text, text


def test_every_damaged_variant_is_read_exactly_or_refused_in_one_line(original, tmp_path, capsys):
    samples0, rest0 = original["contents"]
    assert main(["afc", str(original["path"])]) == 0
    table0 = capsys.readouterr().out
    path = tmp_path / "D.h5"
    outcomes = {"same": 0, "refused": 0, "metadata changed": 0}
    for i, (desc, damaged, hit) in enumerate(_variants(original, N_VARIANTS)):
        path.write_bytes(damaged)
        if i % 16 == 0:  # a subset through the command line too: the same table, or one line
            rc = main(["afc", str(path)])
            out, err = capsys.readouterr()
            if rc == 0:
                assert out == table0 and err == "", desc
            else:
                _one_line_naming(path, err)
                assert err.startswith(f"vibid afc: error: {path}: ") and out == "", (desc, err)
        problems = file_problems(path)  # vibid validate
        for p in problems:
            _one_line_naming(path, f"{path}: {p}")
        try:
            samples, rest = _contents(path)  # vibid afc / identify / --resume read through this
        except SessionFileError as exc:
            _one_line_naming(path, str(exc))
            outcomes["refused"] += 1
            continue
        assert problems == [], f"{desc}: the reader took what validate refused: {problems[0]}"
        assert hit is None, f"{desc}: record {hit} was damaged and read anyway"
        for (b0, r0), (b1, r1) in zip(samples0, samples, strict=True):
            np.testing.assert_array_equal(b1, b0, err_msg=desc)
            np.testing.assert_array_equal(r1, r0, err_msg=desc)
        if rest == rest0:
            outcomes["same"] += 1
        else:  # the old HDF5 layout keeps attributes without checksums: see the xfail below
            outcomes["metadata changed"] += 1
    assert outcomes["refused"] > N_VARIANTS // 3 and outcomes["same"] > N_VARIANTS // 10, outcomes
    assert outcomes["metadata changed"] <= N_VARIANTS // 20, outcomes


def test_a_flipped_sample_is_refused_by_its_checksum_not_fitted(original, tmp_path):
    start, size = original["chunks"]["/steps/000002/response"]
    damaged = bytearray(original["data"])
    damaged[start + 8 * 100 + 3] ^= 0x10  # sample 100, a mantissa bit: a plausible value
    path = tmp_path / "S.h5"
    path.write_bytes(bytes(damaged))
    expected = f"{path}: /steps/000002/response: checksum mismatch (the file is damaged)"
    assert [str(p) for p in file_problems(path)] == [expected.split(": ", 1)[1]]
    with read_session(path) as s:
        assert len(s) == 4 and s.step(1).response.size == 512  # the steps around it still read
        with pytest.raises(SessionFileError) as exc:
            afc_from_session(s)  # lazy: found in the middle of the pass
    assert str(exc.value) == expected


def test_the_commands_say_one_line_on_a_damaged_file(original, tmp_path, capsys):
    """validate, afc and identify through the command line, on damage found at open and in the middle."""
    start, _ = original["chunks"]["/steps/000002/response"]
    middle = bytearray(original["data"])
    middle[start + 400] ^= 0x01
    heap = bytearray(
        original["data"]
    )  # a zeroed block over the root's global heap: hangs HDF5 2.0 if read
    at = original["data"].find(b"GCOL")
    heap[at + 1100 : at + 1100 + 3000] = bytes(3000)
    cases = {
        "middle.h5": (bytes(middle), "/steps/000002/response: checksum mismatch"),
        "heap.h5": (bytes(heap), "/: global heap collection"),
        "short.h5": (original["data"][: len(original["data"]) // 2], "/: HDF5 file is truncated"),
    }
    for name, (data, says) in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        for argv, first in (
            (["validate", str(path)], "validate"),
            (["afc", str(path)], "afc"),
            (["identify", str(path), "--no-loop", "--no-progress"], "identify"),
        ):
            assert main(argv) == 1
            out, err = capsys.readouterr()
            text = out if first == "validate" else err
            _one_line_naming(path, text)
            assert says in text, (argv, text)
            if first != "validate":
                assert text.startswith(f"vibid {first}: error: {path}: "), text


def test_a_crash_or_a_hang_of_the_library_is_one_line(tmp_path):
    """Where the library would crash or hang reading the structure, the child process takes it."""
    import ctypes
    import time

    from vibid.session.hdf5io import survives

    assert survives(len, "a file") is None
    crash = survives(ctypes.string_at, 0)  # reads address 0: a segmentation fault
    assert str(crash) == (
        "/: the HDF5 library crashed reading the file's structure (signal 11; the file is damaged)"
    )
    hang = survives(time.sleep, 30, timeout_s=0.5)
    assert (
        str(hang)
        == "/: the HDF5 library did not finish reading the file's structure in 0.5 s (the file is damaged)"
    )


def test_a_flipped_digit_in_the_setup_is_refused(original, tmp_path):
    data = bytearray(original["data"])
    at = data.find(b"862.5")
    data[at + 2] ^= 0x01  # 862.5 -> 863.5: still a valid setup
    path = tmp_path / "S.h5"
    path.write_bytes(bytes(data))
    # the setup is a variable-length string in HDF5's global heap, which has no checksum in
    # any layout: the writer stores its SHA-256 beside it
    assert [str(p) for p in file_problems(path)] == [
        "/@setup: the setup does not match its checksum (the file is damaged)"
    ]
    with pytest.raises(SessionFileError, match="does not match its checksum"):
        read_session(path)
