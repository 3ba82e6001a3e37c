"""`vibid validate` against files written by an independent program (raw h5py, not vibid's
writer), and against 30+ corrupted variants of them: each refused with its own line."""

import json
import subprocess
import sys

import h5py
import numpy as np
import pytest

from vibid.cli import main
from vibid.setup_model import example_setup

SETUP = example_setup().to_dict()


def write_conformant(path, n_steps=4, n=2048, strings="bytes"):
    """A session as another program might write it: fixed-length byte strings, float32 data."""
    s = (lambda v: np.bytes_(v.encode())) if strings == "bytes" else (lambda v: v)
    rng = np.random.default_rng(0)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = s("vibid.session")
        f.attrs["format_version"] = np.int32(1)
        f.attrs["created_utc"] = s("2026-11-20T10:00:00Z")
        f.attrs["session_id"] = s("0f8fad5b-d9cb-469f-a165-70867728950e")
        f.attrs["software"] = s("labview-export 2.1")
        f.attrs["setup"] = s(json.dumps(SETUP))
        steps = f.create_group("steps")
        for k in range(n_steps):
            g = steps.create_group(f"{k:06d}")
            g.attrs["frequency_hz"] = 10.0 * (k + 1)
            g.attrs["sample_rate_hz"] = 25600.0
            g.attrs["t0_utc"] = s(f"2026-11-20T10:00:{k:02d}.000Z")
            g.attrs["status"] = s("ok")
            g.create_dataset("base", data=rng.standard_normal(n).astype(np.float32))
            g.create_dataset("response", data=rng.standard_normal(n).astype(np.float32))


def validate(capsys, path):
    code = main(["validate", str(path)])
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    return code, out.out.strip().splitlines()


@pytest.mark.parametrize("strings", ["bytes", "str"])
def test_conformant_file_from_independent_writer_is_accepted(tmp_path, capsys, strings):
    path = tmp_path / "good.h5"
    write_conformant(path, strings=strings)
    code, lines = validate(capsys, path)
    assert code == 0
    assert lines == [
        f"{path}: valid session, 4 steps (4 ok), 10-40 Hz, declared model isotropic, run interrupted "
        "(stopped before closing the session, 4 of 200 steps recorded)"
    ]


def _setup(mutate):
    doc = json.loads(json.dumps(SETUP))
    mutate(doc)
    return json.dumps(doc)


def _set_attr(path, name, value):
    def corrupt(f):
        f[path].attrs[name] = value

    return corrupt


def _del_attr(path, name):
    def corrupt(f):
        del f[path].attrs[name]

    return corrupt


def _replace_dataset(step, name, data):
    def corrupt(f):
        del f[f"steps/{step}/{name}"]
        f[f"steps/{step}"].create_dataset(name, data=data)

    return corrupt


def _setup_attr(mutate):
    return _set_attr("/", "setup", _setup(mutate))


def _rename(src, dst):
    def corrupt(f):
        f.move(src, dst)

    return corrupt


def _nan_at(step, name, value):
    def corrupt(f):
        d = f[f"steps/{step}/{name}"]
        a = d[()]
        a[17] = value
        d[...] = a

    return corrupt


def _set(d, keys, value):
    for k in keys[:-1]:
        d = d[k]
    d[keys[-1]] = value


def _del(d, keys):
    for k in keys[:-1]:
        d = d[k]
    del d[keys[-1]]


# (id, corruption, expected line fragment: location and message)
CASES = [
    ("no-format", _del_attr("/", "format"), "/@format: missing root attribute"),
    (
        "wrong-format",
        _set_attr("/", "format", "vibid.report"),
        "/@format: is 'vibid.report', expected 'vibid.session'",
    ),
    ("format-not-str", _set_attr("/", "format", 7), "/@format: must be a string"),
    ("no-version", _del_attr("/", "format_version"), "/@format_version: missing root attribute"),
    (
        "version-2",
        _set_attr("/", "format_version", 2),
        "/@format_version: version 2 is not supported; this vibid reads version 1",
    ),
    (
        "version-str",
        _set_attr("/", "format_version", "1"),
        "/@format_version: must be an integer, got the string '1'",
    ),
    (
        "version-float",
        _set_attr("/", "format_version", 1.0),
        "/@format_version: must be an integer",
    ),
    ("no-created", _del_attr("/", "created_utc"), "/@created_utc: missing root attribute"),
    (
        "bad-created",
        _set_attr("/", "created_utc", "yesterday"),
        "/@created_utc: 'yesterday' is not an ISO 8601 time",
    ),
    ("no-session-id", _del_attr("/", "session_id"), "/@session_id: missing root attribute"),
    ("empty-session-id", _set_attr("/", "session_id", ""), "/@session_id: is empty"),
    ("no-software", _del_attr("/", "software"), "/@software: missing root attribute"),
    ("no-setup", _del_attr("/", "setup"), "/@setup: missing root attribute"),
    ("setup-not-json", _set_attr("/", "setup", "{specimen: 1"), "/@setup: not valid JSON"),
    ("setup-array", _set_attr("/", "setup", np.arange(3)), "/@setup: must be a JSON string"),
    (
        "setup-no-specimen",
        _setup_attr(lambda d: _del(d, ["specimen"])),
        "/@setup.specimen: missing",
    ),
    (
        "setup-length-str",
        _setup_attr(lambda d: _set(d, ["specimen", "length_m"], "100 mm")),
        "/@setup.specimen.length_m: expected a number, got a string",
    ),
    (
        "setup-negative-length",
        _setup_attr(lambda d: _set(d, ["specimen", "length_m"], -0.1)),
        "/@setup.specimen.length_m: must be a positive number, got -0.1",
    ),
    (
        "setup-zero-density",
        _setup_attr(lambda d: _set(d, ["specimen", "density_kg_m3"], 0)),
        "/@setup.specimen.density_kg_m3: must be a positive number, got 0.0",
    ),
    (
        "setup-sensor-outside",
        _setup_attr(lambda d: _set(d, ["sensors", "response", "x_m"], 0.0995)),
        "/@setup.sensors.response: the sensor disc",
    ),
    (
        "setup-negative-mass",
        _setup_attr(lambda d: _set(d, ["sensors", "response", "mass_kg"], -0.001)),
        "/@setup.sensors.response.mass_kg: must be zero or positive",
    ),
    (
        "setup-bounds-reversed",
        _setup_attr(lambda d: _set(d, ["identification", "bounds", "D"], [100.0, 1.0])),
        "/@setup.identification.bounds.D: low 100.0 must be below high 1.0",
    ),
    (
        "setup-unknown-model",
        _setup_attr(lambda d: _set(d, ["identification", "model"], "anisotropic")),
        "/@setup.identification.model: unknown model 'anisotropic'",
    ),
    (
        "setup-wrong-params",
        _setup_attr(lambda d: _set(d, ["identification", "model"], "orthotropic")),
        "/@setup.identification.bounds: model 'orthotropic' needs bounds for D11, D12, D22, D66",
    ),
    (
        "setup-extra-param",
        _setup_attr(lambda d: _set(d, ["identification", "bounds", "E"], [1.0, 2.0])),
        "/@setup.identification.bounds: E is not a parameter of model 'isotropic'",
    ),
    (
        "setup-negative-frequency",
        _setup_attr(lambda d: _set(d, ["excitation", "frequencies_hz"], [5.0, -10.0])),
        "/@setup.excitation.frequencies_hz[1]: must be a positive number, got -10.0",
    ),
    (
        "setup-bounds-shape",
        _setup_attr(lambda d: _set(d, ["identification", "bounds", "nu"], [0.1])),
        "/@setup.identification.bounds.nu: expected [low, high], got [0.1]",
    ),
    ("no-steps-group", lambda f: f.move("steps", "records"), "/steps: missing group"),
    (
        "step-out-of-sequence",
        _rename("steps/000002", "steps/000005"),
        "/steps/000003: step out of sequence: 000002 is missing before it",
    ),
    (
        "step-name-not-digits",
        _rename("steps/000003", "steps/step3"),
        "/steps/step3: step group name is not six digits",
    ),
    (
        "step-no-frequency",
        _del_attr("steps/000001", "frequency_hz"),
        "/steps/000001@frequency_hz: missing step attribute",
    ),
    (
        "step-frequency-str",
        _set_attr("steps/000001", "frequency_hz", "10 Hz"),
        "/steps/000001@frequency_hz: must be a number, got the string '10 Hz'",
    ),
    (
        "step-negative-rate",
        _set_attr("steps/000001", "sample_rate_hz", -25600.0),
        "/steps/000001@sample_rate_hz: must be a positive finite number, got -25600.0",
    ),
    (
        "step-above-nyquist",
        _set_attr("steps/000001", "frequency_hz", 13000.0),
        "/steps/000001@frequency_hz: 13000.0 Hz is not below the Nyquist frequency 12800.0 Hz",
    ),
    (
        "step-no-t0",
        _del_attr("steps/000002", "t0_utc"),
        "/steps/000002@t0_utc: missing step attribute",
    ),
    (
        "step-no-status",
        _del_attr("steps/000002", "status"),
        "/steps/000002@status: missing step attribute",
    ),
    (
        "step-unknown-status",
        _set_attr("steps/000002", "status", "clipped"),
        "/steps/000002@status: unknown status 'clipped', expected one of ok, overload, aborted",
    ),
    (
        "step-no-response",
        lambda f: f["steps/000003"].__delitem__("response"),
        "/steps/000003/response: missing dataset",
    ),
    (
        "step-lengths-differ",
        _replace_dataset("000003", "response", np.zeros(2047, np.float32)),
        "/steps/000003/response: length 2047 differs from base 2048",
    ),
    (
        "step-int-samples",
        _replace_dataset("000003", "base", np.zeros(2048, np.int16)),
        "/steps/000003/base: must be float32 or float64, is int16",
    ),
    (
        "step-2d-samples",
        _replace_dataset("000003", "base", np.zeros((2, 1024))),
        "/steps/000003/base: must be 1-D, has shape (2, 1024)",
    ),
    (
        "step-nan",
        _nan_at("000000", "response", np.nan),
        "/steps/000000/response: 1 sample is NaN or infinite",
    ),
    (
        "step-inf",
        _nan_at("000001", "base", np.inf),
        "/steps/000001/base: 1 sample is NaN or infinite",
    ),
    ("step-empty", _replace_dataset("000002", "base", np.zeros(0)), "/steps/000002/base: is empty"),
]


@pytest.mark.parametrize("case_id, corrupt, expected", CASES, ids=[c[0] for c in CASES])
def test_each_corruption_is_refused_with_its_own_line(tmp_path, capsys, case_id, corrupt, expected):
    path = tmp_path / f"{case_id}.h5"
    write_conformant(path)
    with h5py.File(path, "a") as f:
        corrupt(f)
    code, lines = validate(capsys, path)
    assert code == 1
    assert any(line.startswith(f"{path}: {expected}") for line in lines), lines


def test_messages_are_all_different():
    assert len({c[2] for c in CASES}) == len(CASES) >= 30


@pytest.mark.parametrize(
    "content, expected",
    [
        (b"", "/: empty file (0 bytes), not an HDF5 session"),
        (b"frequency,base,response\n5,0.1,0.2\n", "/: not an HDF5 file (no HDF5 signature)"),
    ],
    ids=["empty", "text"],
)
def test_non_hdf5_files(tmp_path, capsys, content, expected):
    path = tmp_path / "x.h5"
    path.write_bytes(content)
    code, lines = validate(capsys, path)
    assert (code, lines) == (1, [f"{path}: {expected}"])


def test_truncated_file(tmp_path, capsys):
    good = tmp_path / "good.h5"
    write_conformant(good)
    data = good.read_bytes()
    path = tmp_path / "truncated.h5"
    path.write_bytes(data[: len(data) // 3])
    code, lines = validate(capsys, path)
    assert code == 1 and len(lines) == 1
    assert lines[0].startswith(f"{path}: /: HDF5 file is truncated or corrupted")


def test_installed_command_exit_codes(tmp_path):
    """Through the real entry point: 0 valid, 1 invalid, 2 usage; never a traceback."""
    good, bad = tmp_path / "good.h5", tmp_path / "bad.h5"
    write_conformant(good)
    bad.write_text("not hdf5")
    run = lambda *a: subprocess.run(
        [sys.executable, "-m", "vibid", *a], capture_output=True, text=True
    )
    ok, fail, usage = run("validate", str(good)), run("validate", str(bad)), run("validate")
    assert (ok.returncode, fail.returncode, usage.returncode) == (0, 1, 2)
    assert all("Traceback" not in r.stdout + r.stderr for r in (ok, fail, usage))
    assert fail.stdout.strip() == f"{bad}: /: not an HDF5 file (no HDF5 signature)"
