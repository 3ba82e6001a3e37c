"""The synthetic-record generator the signal tests (and the simulated stand) rely on."""

import numpy as np
import pytest

from vibid.hardware_mocks.records import Transient, synthetic_step, true_frequency_hz


def _bin(x, k):
    """Amplitude of DFT bin k of a record holding whole cycles (independent of the fit)."""
    return 2 * abs(np.fft.rfft(x)[k]) / x.size


def test_amplitudes_harmonics_dc_and_drift_are_as_asked():
    # 20 Hz at 1 kHz over 1 s: 20 whole cycles, so every component sits on one bin
    base, response = synthetic_step(
        20.0,
        0.5j,
        sample_rate_hz=1000.0,
        n_samples=1000,
        base_amplitude_m_s2=2.0,
        harmonics_db=(-20.0, -40.0),
        dc_m_s2=(0.3, -0.1),
        rng=4,
    )
    assert _bin(base, 20) == pytest.approx(2.0)
    assert _bin(response, 20) == pytest.approx(1.0)
    assert _bin(base, 40) == pytest.approx(0.2)
    assert _bin(response, 60) == pytest.approx(0.01)
    assert base.mean() == pytest.approx(0.3)
    _, steady = synthetic_step(20.0, 1.0, sample_rate_hz=1000.0, n_samples=1000)
    _, drifting = synthetic_step(
        20.0, 1.0, sample_rate_hz=1000.0, n_samples=1000, drift_m_s2_per_s=(0.0, 0.5)
    )
    assert drifting - steady == pytest.approx(0.5 * np.arange(1000) / 1000.0, abs=1e-12)


def test_clock_offset_moves_the_frequency():
    assert true_frequency_hz(1000.0, 200.0) == pytest.approx(1000.2)
    base, _ = synthetic_step(
        100.0, 1.0, sample_rate_hz=1000.0, n_samples=1000, clock_offset_ppm=1e4
    )
    # 101 Hz over 1 s: 101 cycles exactly
    assert _bin(base, 101) == pytest.approx(1.0)


def test_noise_clipping_dtype_and_seed():
    kw = dict(
        sample_rate_hz=1000.0,
        n_samples=100_000,
        noise_std_m_s2=(0.0, 0.1),
        clip_m_s2=(0.9, None),
        dtype=np.float32,
    )
    base, response = synthetic_step(7.0, 1.0, rng=1, **kw)
    assert (
        base.dtype == np.float32
        and base.max() == pytest.approx(0.9)
        and base.min() == pytest.approx(-0.9)
    )
    clean = synthetic_step(7.0, 1.0, **{**kw, "noise_std_m_s2": (0.0, 0.0)})[1]
    assert np.std(response - clean) == pytest.approx(0.1, rel=0.01)
    assert np.array_equal(response, synthetic_step(7.0, 1.0, rng=1, **kw)[1])
    assert not np.array_equal(response, synthetic_step(7.0, 1.0, rng=2, **kw)[1])


def test_transient_decays_on_the_response_only():
    kw = dict(sample_rate_hz=1000.0, n_samples=2000)
    b0, r0 = synthetic_step(10.0, 1.0, **kw)
    b1, r1 = synthetic_step(
        10.0, 1.0, transient=Transient(0.5, decay_s=0.2, frequency_hz=33.0), **kw
    )
    assert np.array_equal(b0, b1)
    extra = r1 - r0
    t = np.arange(2000) / 1000.0
    assert extra == pytest.approx(0.5 * np.exp(-t / 0.2) * np.cos(2 * np.pi * 33.0 * t), abs=1e-12)
