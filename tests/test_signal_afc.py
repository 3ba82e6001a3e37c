"""Session → AFC table: phase convention, report block, grouping, the `vibid afc` command."""

import json

import numpy as np
import pytest

from vibid.cli import main
from vibid.hardware_mocks.records import synthetic_step, true_frequency_hz
from vibid.session import SessionWriter, read_session
from vibid.setup_model import example_setup
from vibid.signal import StepRecord, afc_from_records, afc_from_session

FS = 25_600.0


def _record(f_hz, h, n=12_800, ppm=0.0, seed=0, noise=(1e-3, 1e-3), **kw):
    base, response = synthetic_step(
        f_hz,
        h,
        sample_rate_hz=FS,
        n_samples=n,
        clock_offset_ppm=ppm,
        noise_std_m_s2=noise,
        rng=seed,
        **kw,
    )
    return base, response


def test_phase_is_positive_when_the_response_leads():
    """Direct construction, not the generator: response = cos(ωt + 30°), base = cos(ωt)."""
    t = np.arange(10_000) / 10_000.0
    w = 2 * np.pi * 123.0
    table = afc_from_records(
        [StepRecord(123.0, 10_000.0, np.cos(w * t), 2.0 * np.cos(w * t + np.radians(30.0)))]
    )
    assert np.angle(table.H[0], deg=True) == pytest.approx(30.0, abs=1e-9)
    assert abs(table.H[0]) == pytest.approx(2.0, rel=1e-12)


def test_generator_phasors_follow_the_convention():
    """The mock's response at t = 0 is Re(H A e^{iφ}): independent of any fit."""
    h = 0.5 * np.exp(1j * 0.7)
    base, response = synthetic_step(
        10.0, h, sample_rate_hz=1000.0, n_samples=10, base_phase_rad=0.2
    )
    assert base[0] == pytest.approx(np.cos(0.2))
    assert response[0] == pytest.approx(0.5 * np.cos(0.9))
    again = synthetic_step(10.0, h, sample_rate_hz=1000.0, n_samples=10, base_phase_rad=0.2)
    assert np.array_equal(base, again[0])


def test_table_holds_every_step_in_order_with_mixed_lengths():
    steps = []
    truth = []
    for k, (f, n) in enumerate([(20.0, 12_800), (40.0, 6_400), (60.0, 12_800), (9_000.0, 12_800)]):
        h = (1 + k) * np.exp(1j * k)
        b, r = _record(f, h, n=n, ppm=100.0 - 50 * k, seed=k)
        steps.append(StepRecord(f, FS, b, r, index=k))
        truth.append(h)
    table = afc_from_records(steps)
    assert len(table) == 4
    assert [p.index for p in table.points] == [0, 1, 2, 3]
    assert [p.n_samples for p in table.points] == [12_800, 6_400, 12_800, 12_800]
    # 9 kHz at fs 25.6 kHz: 2f and 3f are above Nyquist, fitted with the fundamental only
    z = np.abs(table.H - np.array(truth)) / table.std
    assert np.all(z < 5.0)
    f_true = [
        true_frequency_hz(f, 100.0 - 50 * k) for k, f in enumerate([20.0, 40.0, 60.0, 9_000.0])
    ]
    f_std = np.array([p.frequency_std_hz for p in table.points])
    assert np.all(np.abs(table.frequency_hz - f_true) < 5.0 * f_std)
    assert np.isnan(table.points[3].thd_db[0])


def test_report_block_lists_used_steps_and_diagnoses_all():
    b, r = _record(50.0, 1.5j)
    steps = [
        StepRecord(50.0, FS, b, r),
        StepRecord(50.0, FS, b, r, status="overload"),
        StepRecord(70.0, FS, np.ones(5), np.ones(5)),
    ]
    block = afc_from_records(steps).to_report_block()
    assert block["frequency_hz"] == [pytest.approx(50.0)]
    assert block["re"][0] == pytest.approx(0.0, abs=1e-4)
    assert block["im"][0] == pytest.approx(1.5, abs=1e-4)
    assert len(block["std"]) == 1
    assert [d["used"] for d in block["diagnostics"]] == [True, False, False]
    assert block["diagnostics"][2]["re"] is None  # NaN as null: strict JSON
    json.dumps(block, allow_nan=False)


def test_std_is_the_rms_of_the_real_and_imaginary_uncertainties():
    b, r = _record(50.0, 0.3 + 2.0j, noise=(0.05, 0.01))
    (p,) = afc_from_records([StepRecord(50.0, FS, b, r)]).points
    assert p.std == pytest.approx(np.sqrt((p.std_re**2 + p.std_im**2) / 2))
    # white noise: the delta-method ellipse is nearly circular (std_re ≈ std_im)
    assert p.std_re == pytest.approx(p.std_im, rel=0.05)


def _write_session(path, statuses=("ok", "ok", "overload")):
    setup = example_setup()
    truth = []
    with SessionWriter(path, setup, session_id="sig-test") as w:
        for k, status in enumerate(statuses):
            f = 100.0 + 50.0 * k
            h = 1.0 / (1.0 - (f / 180.0) ** 2 + 0.01j)
            b, r = _record(
                f, h, ppm=80.0, seed=k, dc_m_s2=(0.01, 0.02), harmonics_db=(-40.0, -45.0)
            )
            w.append(
                frequency_hz=f,
                sample_rate_hz=FS,
                base=b.astype(np.float32),
                response=r.astype(np.float32),
                status=status,
            )
            truth.append(h)
    return truth


def test_afc_from_session_reads_every_step(tmp_path):
    path = tmp_path / "s.h5"
    truth = _write_session(path)
    with read_session(path) as s:
        table = afc_from_session(s)
    assert table.used.tolist() == [True, True, False]
    assert table.flags[2] == ("overload",)
    assert np.all(np.abs(table.H[:2] - truth[:2]) / table.std[:2] < 5.0)


def test_cli_prints_a_table_and_writes_the_afc_block(tmp_path, capsys):
    path = tmp_path / "s.h5"
    _write_session(path)
    out_json = tmp_path / "afc.json"
    assert main(["afc", str(path), "--json", str(out_json)]) == 0
    text = capsys.readouterr().out
    lines = text.strip().splitlines()
    assert lines[0].split()[:6] == ["step", "f_Hz", "|H|", "phase_deg", "std", "SNR_dB"]
    assert len(lines) == 5
    assert lines[3].rstrip().endswith("overload")
    assert "2 of 3 steps used" in lines[4]
    doc = json.loads(out_json.read_text())
    assert doc["session_id"] == "sig-test"
    assert len(doc["afc"]["frequency_hz"]) == 2
    assert set(doc["afc"]) >= {"frequency_hz", "re", "im", "std", "diagnostics"}


def test_cli_refuses_a_missing_file_in_one_line(tmp_path, capsys):
    assert main(["afc", str(tmp_path / "nope.h5")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("vibid afc: error:") and "no such file" in err and "\n" not in err
