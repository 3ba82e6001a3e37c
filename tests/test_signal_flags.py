"""Each quality flag fires on the record made to trigger it, and no flag fires on clean ones."""

import numpy as np
import pytest

from vibid.hardware_mocks.records import Transient, synthetic_step
from vibid.signal import StepRecord, afc_from_records
from vibid.signal.flags import flat_top_fraction, unsettled_chi2_limit

FS, N = 25_600.0, 25_600


def _h(f_hz):
    """A lightly damped resonance at 300 Hz: a plausible AFC."""
    r = f_hz / 300.0
    return 1.0 / (1.0 - r**2 + 0.02j * r)


def _step(f_hz=210.0, status="ok", n=N, **kw):
    """A realistic clean step (clock offset, DC, drift, -40 dB harmonics, noise) with changes ``kw``."""
    opts = dict(
        clock_offset_ppm=150.0,
        dc_m_s2=(0.05, -0.02),
        drift_m_s2_per_s=(0.01, 0.02),
        harmonics_db=(-40.0, -40.0),
        noise_std_m_s2=(2e-3, 2e-3),
        rng=int(f_hz),
    )
    opts.update(kw)
    base, response = synthetic_step(f_hz, _h(f_hz), sample_rate_hz=FS, n_samples=n, **opts)
    return StepRecord(f_hz, FS, base, response, status=status)


def _flags(step):
    (point,) = afc_from_records([step]).points
    return point


def test_no_flag_fires_on_clean_records_across_the_band():
    steps = [
        _step(f, rng=k, clock_offset_ppm=(-200.0 + 4 * k))
        for k, f in enumerate(np.geomspace(5.0, 4000.0, 100))
    ]
    table = afc_from_records(steps)
    assert table.flags == ((),) * 100
    assert table.used.all()


@pytest.mark.parametrize("channel", [0, 1])
def test_clipping_sets_overload(channel):
    clip = [None, None]
    clip[channel] = 0.97 * (1.0 if channel == 0 else abs(_h(210.0)))
    point = _flags(_step(clip_m_s2=tuple(clip)))
    assert point.flag_names[0] == "overload"  # a clipped record may look unsettled too
    assert ("base", "response")[channel] in point.flags[0].reason
    assert not point.used


def test_overload_status_sets_overload():
    point = _flags(_step(status="overload"))
    assert point.flag_names == ("overload",)
    assert "status" in point.flags[0].reason


def test_aborted_status_sets_aborted():
    assert _flags(_step(status="aborted")).flag_names == ("aborted",)


@pytest.mark.parametrize(
    "transient",
    [
        Transient(
            amplitude_m_s2=0.02, decay_s=0.3
        ),  # envelope still growing at the drive frequency
        # ringing at a natural frequency one bin from the drive: beats
        Transient(amplitude_m_s2=0.02, decay_s=0.3, frequency_hz=211.0),
    ],
)
def test_a_left_over_transient_sets_unsettled(transient):
    point = _flags(_step(transient=transient))
    assert "unsettled" in point.flag_names
    assert not point.used


def test_a_weak_response_sets_low_snr():
    point = _flags(_step(noise_std_m_s2=(2e-3, 30.0)))
    assert point.flag_names == ("low_snr",)
    assert "response" in point.flags[0].reason


def test_strong_harmonics_set_distortion():
    point = _flags(_step(harmonics_db=(-12.0, -30.0)))
    assert point.flag_names == ("distortion",)
    assert point.thd_db[0] == pytest.approx(
        20 * np.log10(np.hypot(10 ** (-12 / 20), 10 ** (-30 / 20))), abs=0.05
    )


def test_a_clock_beyond_its_tolerance_sets_clock():
    point = _flags(_step(clock_offset_ppm=450.0))
    assert point.flag_names == ("clock",)
    assert point.clock_offset_ppm == pytest.approx(450.0, abs=0.1)


def test_a_record_of_one_and_a_half_cycles_sets_few_cycles():
    point = _flags(_step(f_hz=3.0, n=12_800, harmonics_db=(), drift_m_s2_per_s=(0.0, 0.0)))
    assert point.flag_names == ("few_cycles",)


@pytest.mark.parametrize(
    "base, response, reason",
    [
        (np.ones(100), np.ones(99), "one length"),
        (np.r_[np.ones(99), np.nan], np.ones(100), "non-finite"),
        (np.ones(10), np.ones(10), "too short"),
    ],
)
def test_unusable_records_are_invalid(base, response, reason):
    point = _flags(StepRecord(50.0, 1000.0, base, response))
    assert point.flag_names == ("invalid",)
    assert reason in point.flags[0].reason
    assert np.isnan(point.h)


def test_ignored_flags_keep_the_step_but_status_never_does():
    steps = [_step(harmonics_db=(-12.0, -12.0)), _step(status="overload")]
    table = afc_from_records(steps, ignore_flags={"distortion", "overload"})
    assert table.flags == (("distortion",), ("overload",))
    assert table.used.tolist() == [True, False]


def test_flat_top_fraction_of_a_clean_sine_is_small_and_of_a_clipped_one_is_not():
    t = np.arange(25_600) / 25_600.0
    x = np.sin(2 * np.pi * 5.0 * t)  # 5120 samples per cycle: hits the peak exactly
    assert flat_top_fraction(x) < 0.001
    # clipped at 0.9: a fraction arccos(0.9)/π of the samples on each rail
    assert flat_top_fraction(np.clip(x, -0.9, 0.9)) == pytest.approx(
        np.arccos(0.9) / np.pi, rel=0.01
    )


def test_chi2_limits_are_the_gaussian_tails():
    assert unsettled_chi2_limit(5.0, 1) == 25.0
    # P(χ²₂ > L) = exp(-L/2) = erfc(5/√2) = 5.733e-7
    assert unsettled_chi2_limit(5.0, 2) == pytest.approx(-2 * np.log(5.733031e-7), rel=1e-6)
    # 4 dof: P(χ²₄ > L) = exp(-L/2) (1 + L/2)
    limit = unsettled_chi2_limit(5.0, 4)
    assert np.exp(-limit / 2) * (1 + limit / 2) == pytest.approx(5.733031e-7, rel=1e-6)
