"""Resonance peaks of an AFC and the peak-matching score, on an analytic two-mode AFC; and
identify's search on the peaks alone, on the strip's AFC of the loop tests."""

import numpy as np
import pytest

from vibid.identify.fit.peaks import grid_heights, measured_peaks, peak_score, peaks_matched

F_MODES = np.array([123.4, 456.7])
BETA = 0.01


def two_mode_afc(f_hz):
    """Base-excited two-mode system: H = 1 + sum_j a_j w^2 / (w_j^2 (1 + i beta) - w^2)."""
    w2 = (2 * np.pi * f_hz) ** 2
    wj2 = (2 * np.pi * F_MODES) ** 2
    a = np.array([0.8, 0.3])
    return 1 + (a[None, :] * w2[:, None] / (wj2[None, :] * (1 + 1j * BETA) - w2[:, None])).sum(1)


def test_peaks_found_at_the_natural_frequencies():
    f = np.linspace(5, 600, 300)  # 2 Hz grid: the parabola must refine between points
    p = measured_peaks(f, two_mode_afc(f))
    assert p.count == 2
    # |H| peaks at w_j (1 + O(beta^2)); the 3-point parabola on ln|H| is good to ~0.1 Hz here
    np.testing.assert_allclose(p.frequency_hz, F_MODES, atol=0.15)
    assert abs(p.frequency_hz[0] - f[np.argmin(abs(f - F_MODES[0]))]) > 0  # refined, not snapped


def test_noise_below_the_snr_limit_makes_no_peak():
    f = np.linspace(5, 600, 300)
    rng = np.random.default_rng(0)
    H = 1 + 0.01 * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    assert measured_peaks(f, H, np.full(f.size, 0.01)).count == 0


def test_wiggles_on_a_dense_grids_resonance_top_are_no_resonances():
    """An FFT AFC's 0.12 Hz bins on a resonance's top wiggle by the estimate's scatter
    (2 % here, the real strips' tops reach 5-7 %): each wiggle is a local maximum high above
    the median, but only the resonances rise above their surroundings."""
    f = np.arange(40.0, 600.0, 0.122)
    rng = np.random.default_rng(3)
    H = two_mode_afc(f) * (1 + 0.02 * rng.standard_normal(f.size))
    mag = np.abs(H)
    top = (mag[1:-1] > mag[:-2]) & (mag[1:-1] >= mag[2:]) & (mag[1:-1] > 3 * np.median(mag))
    assert top.sum() > 10  # what counted as a resonance before the prominence
    p = measured_peaks(f, H)
    assert p.count == 2
    np.testing.assert_allclose(p.frequency_hz, F_MODES, rtol=2 * BETA)


def test_score_is_zero_at_a_match_and_penalises_misses_and_spurious_modes():
    f = np.linspace(5, 600, 300)
    p = measured_peaks(f, two_mode_afc(f))
    strong = np.array([[100.0, 100.0, 100.0]])
    exact = np.array([[*p.frequency_hz, 900.0]])  # a third mode above the band is ignored
    assert float(peak_score(exact, strong, p)[0]) == pytest.approx(0.0, abs=1e-20)
    off = exact * np.array([[1.01, 1.0, 1.0]])  # 1 % off: counted once as unexplained,
    # once as a spurious visible mode -> 2 ln(1.01)^2
    assert float(peak_score(off, strong, p)[0]) == pytest.approx(2 * np.log(1.01) ** 2, rel=1e-9)
    extra = np.array([[*p.frequency_hz, 300.0]])  # a strong mode in the band with no peak
    assert float(peak_score(extra, strong, p)[0]) == pytest.approx(
        np.min(np.log(300.0 / p.frequency_hz) ** 2), rel=1e-9
    )  # the nearest peak, 456.7 Hz
    weak = np.array([[100.0, 100.0, 1e-6]])  # the same mode, too weak to be seen: no penalty
    assert float(peak_score(extra, weak, p)[0]) == pytest.approx(0.0, abs=1e-20)


def test_a_narrow_mode_between_two_steps_is_not_a_peak_the_data_lack():
    """A stepped sine 6 Hz apart around a mode of beta 0.0005 (half-power band 0.125 Hz)
    that lies 3 Hz from both neighbouring steps: its resonance is 48x higher than the grid
    shows it (1 / sqrt(1 + x^2), x = (1 - (f/f_k)^2) / beta), and the data show no peak
    there. Judged by its resonance it is a spurious mode; judged by the grid it is not."""
    f0, beta, a = 250.0, 0.0005, 0.006
    grid = np.arange(103.0, 400.0, 6.0)  # 247 and 253 Hz: f0 midway

    def afc(f):
        w2, wj2 = (2 * np.pi * f) ** 2, (2 * np.pi * f0) ** 2
        return two_mode_afc(f) + a * w2 / (wj2 * (1 + 1j * beta) - w2)

    p = measured_peaks(grid, afc(grid))
    assert p.count == 1  # 123.4 Hz only (456.7 Hz is beyond the grid)
    resonance = a / beta  # the mode's own peak |H| above its background (~1.4 near it)
    x = (1 - (247.0 / f0) ** 2) / beta
    assert resonance / np.sqrt(1 + x**2) < 0.5 * p.height.min() < resonance
    modes = np.array([[p.frequency_hz[0], f0]])
    heights = np.array([[p.height[0], resonance]])
    shown = grid_heights(modes, heights, [beta], grid)
    # the mode's own term at 247 Hz, a r² / sqrt((1 - r²)² + beta²), r = 247 / f0: the
    # formula drops the r² (2.4 % here)
    r2 = (247.0 / f0) ** 2
    assert shown[0, 1] == pytest.approx(a * r2 / np.hypot(1 - r2, beta), rel=0.03)
    assert shown[0, 1] < 0.5 * p.height.min()
    assert float(peak_score(modes, heights, p)[0]) == pytest.approx(
        np.log(f0 / p.frequency_hz[0]) ** 2, rel=1e-9
    )  # counted as spurious
    assert float(peak_score(modes, shown, p)[0]) == pytest.approx(0.0, abs=1e-20)
    assert peaks_matched(modes[0], shown[0], p)
    assert not peaks_matched(modes[0], heights[0], p)


def test_peaks_matched_to_the_grid_resolution():
    # a 10 Hz grid: each peak is placed to within one step of the grid (its resolution is
    # half the distance between the maximum's two neighbours, in ln f)
    f = np.arange(10.0, 600.0, 10.0)
    p = measured_peaks(f, two_mode_afc(f))
    assert p.count == 2
    step = np.array([np.log((g + 10) / (g - 10)) / 2 for g in np.round(p.frequency_hz, -1)])
    np.testing.assert_allclose(p.resolution, step, rtol=1e-12)
    strong = np.array([100.0, 100.0])
    assert peaks_matched(F_MODES, strong, p)  # the true modes
    assert peaks_matched(F_MODES * 1.015, strong, p)  # 1.8 Hz off: inside a 10 Hz step
    assert not peaks_matched(F_MODES * [1.0, 1.05], strong, p)  # 23 Hz off: a wrong basin
    # a strong third mode in the band where the AFC has no peak: not this basin
    assert not peaks_matched([*F_MODES, 300.0], [*strong, 100.0], p)
    assert peaks_matched([*F_MODES, 300.0], [*strong, 1e-6], p)  # too weak to be seen
    assert not peaks_matched(F_MODES[:1], strong[:1], p)  # a measured peak left unexplained


@pytest.mark.slow
def test_a_search_on_the_peaks_alone_ends_in_chi2s_estimate_or_says_it_does_not_fit():
    """identify(peaks_only=...): the search on the peaks alone (the loss factor held at 0.02,
    against 0.003), no chi2 search. On the 25 Hz steps of the loop tests a resonance
    anywhere between two steps matches its peak, so the peaks may leave the search in a
    neighbouring basin: then its chi2 says so (the loop searches chi2 as well); otherwise it
    is chi2's search's estimate."""
    from loop_data import F, data, strip_on
    from vibid.identify.fit import Measurement, SearchOptions, identify
    from vibid.identify.fit.noise import fits_noise

    H, sd = data({}, 1)
    plain = identify(strip_on(), Measurement(F, H, sd), search=SearchOptions(restarts=1, seed=0))
    first = identify(
        strip_on(),
        Measurement(F, H, sd),
        search=SearchOptions(restarts=1, seed=0, peaks_only={"D": 10.0, "nu": 0.1, "beta": 0.02}),
    )
    assert first.global_result.messages[0].startswith("peak matching")  # no chi2 search
    assert plain.global_result.messages[0].startswith("global search")
    assert fits_noise(plain.chi2, plain.dof, True)
    if fits_noise(first.chi2, first.dof, True):
        assert np.all(np.abs(first.values - plain.values) < 0.01 * plain.std)
    else:  # a neighbouring basin, and chi2 tells
        assert first.chi2 > 10 * plain.chi2
