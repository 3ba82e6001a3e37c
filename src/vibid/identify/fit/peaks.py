"""Resonance peaks of a measured AFC, and a global-search score that matches them.

Fitting the AFC itself over a wide prior box is a needle-in-a-haystack search when the
loss factor is small: a model peak earns credit only within its half-power band (about
beta f) of a measured one, so with several stiffness parameters (an orthotropic plate:
D11, D12, D22, D66) differential evolution on chi2 rarely lands in the right basin. The
frequencies of the resonances are smooth functions of the parameters, so a score that
asks each measured peak to be explained by some model mode, and each strong model mode in
the band by some measured peak,

    score(theta) = sum_i min_j (ln f_j - ln F_i)^2 + sum_{j visible} min_i (ln f_j - ln F_i)^2,

(F_i measured peak frequencies, f_j the model's natural frequencies, "visible": in the band
and with a resonance peak at least half as high as the lowest measured one) has wide
basins around every parameter set that reproduces the peaks. Its minima are starts for
the polish on the AFC (:mod:`vibid.identify.fit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import peak_prominences

#: A peak must rise this many times above the AFC's median magnitude (and, with a known
#: uncertainty, this many standard deviations above zero) to count as a resonance.
MIN_PEAK_RATIO = 3.0
MIN_PEAK_SNR = 10.0
#: ... and stand out of its surroundings: its prominence in ln |H| (how far it rises above
#: the higher of the lowest points between it and a higher peak on either side) at least
#: this. A resonance rises by ln sqrt(2) = 0.35 within its half-power band alone; the
#: noise's bin-to-bin wiggles on the tops of measured FFT AFCs (0.12 Hz bins) rise far less
#: (at most 0.05-0.07 on the real strips, the larger on a stand feature: BENCHMARKS.md), and
#: without this bar every one of them was a "resonance": 317 of them on one real AFC, whose
#: two resonances no model could then match, so its declared fit ran a peak search (8 s) on
#: noise.
MIN_PEAK_PROMINENCE = 0.1


@dataclass(frozen=True)
class Peaks:
    """Resonance peaks found in a measured AFC.

    frequency_hz: (m,) peak frequencies, refined by a parabola through the three grid
        points around each maximum of ln |H|; height: (m,) |H| at the grid maximum.
    f_max_hz: the highest frequency of the band searched.
    """

    frequency_hz: np.ndarray
    height: np.ndarray
    f_max_hz: float
    #: (m,) how well the grid places each peak (ln-frequency units): the resonance lies
    #: between the maximum's two grid neighbours, so half their distance
    resolution: np.ndarray | None = None

    @property
    def count(self) -> int:
        return int(self.frequency_hz.size)


def measured_peaks(frequency_hz, H, std=None) -> Peaks:
    """The resonance peaks of ``H`` (complex, (n,)) on the grid ``frequency_hz`` (Hz)."""
    f = np.asarray(frequency_hz, float)
    mag = np.abs(np.asarray(H))
    order = np.argsort(f)
    f, mag = f[order], mag[order]
    s = None if std is None else np.asarray(std, float)[order]
    floor = MIN_PEAK_RATIO * float(np.median(mag))
    inner = np.arange(1, f.size - 1)
    maxima = inner[
        (mag[inner] > mag[inner - 1]) & (mag[inner] >= mag[inner + 1]) & (mag[inner] > floor)
    ]
    with np.errstate(divide="ignore"):  # a zero or missing point: a valley, -inf
        level = np.log(np.where(np.isfinite(mag), mag, 0.0))
        prominent = peak_prominences(level, maxima)[0] >= MIN_PEAK_PROMINENCE
    found_f, found_h, found_r = [], [], []
    for i in maxima[prominent]:
        if s is not None and mag[i] < MIN_PEAK_SNR * s[i]:
            continue
        x, y = f[i - 1 : i + 2], np.log(mag[i - 1 : i + 2])
        a, b, _ = np.polyfit(x - x[1], y, 2)
        shift = -b / (2 * a) if a < 0 else 0.0
        found_f.append(x[1] + float(np.clip(shift, x[0] - x[1], x[2] - x[1])))
        found_h.append(mag[i])
        found_r.append(0.5 * np.log(x[2] / x[0]))
    return Peaks(np.array(found_f), np.array(found_h), float(f.max()), np.array(found_r))


def _visible(f_model_hz, height_model, peaks: Peaks):
    """Which model modes the AFC would show: in the band, with a resonance peak at least
    half as high as the lowest measured one (numpy or JAX arrays)."""
    return (f_model_hz <= peaks.f_max_hz) & (height_model >= 0.5 * float(peaks.height.min()))


def grid_heights(f_model_hz, height_model, beta, grid_hz):
    """(S, n) how high each model mode shows on the measured grid: its resonance peak
    ``height_model`` (S, n) seen from the nearer of the two grid frequencies around it,
    ``height / sqrt(1 + x²)`` with ``x = (1 - (f_grid / f_mode)²) / beta`` (one mode of
    loss factor ``beta`` (S,), away from its resonance). ``grid_hz``: the measured
    frequencies, ascending.

    A stepped sine whose steps are wider than a resonance's half-power band (β f: 0.8 Hz
    for β = 0.005 at 160 Hz, between steps 6.7 Hz apart) may fall between them and show
    no peak where the model has a strong one; the peak score must then not count that
    mode as one the data lack (a plate's torsion mode was, and the search preferred a
    wrong basin whose modes all fell where the data have peaks)."""
    grid = np.asarray(grid_hz, float)
    f = np.maximum(np.asarray(f_model_hz, float), 1e-12)
    b = np.maximum(np.asarray(beta, float), 1e-12).reshape(-1, 1)
    i = np.clip(np.searchsorted(grid, f), 1, grid.size - 1)
    x = np.minimum(np.abs(1 - (grid[i - 1] / f) ** 2), np.abs(1 - (grid[i] / f) ** 2)) / b
    return np.asarray(height_model, float) / np.sqrt(1 + x**2)


def peak_score(f_model_hz, height_model, peaks: Peaks):
    """The score of the module docstring for a population: (S, n) model frequencies and
    peak heights -> (S,) scores, in numpy (the modes arrive as numpy arrays). The heights
    say which modes are visible: their resonance peaks, or how high the measured grid
    would show them (:func:`grid_heights`)."""
    F = np.asarray(peaks.frequency_hz, float)
    fm = np.maximum(np.asarray(f_model_hz, float), 1e-12)
    with np.errstate(invalid="ignore"):
        d2 = (np.log(fm)[:, :, None] - np.log(F)[None, None, :]) ** 2  # (S, n, m)
        explained = np.min(d2, axis=1).sum(axis=1)
        visible = _visible(fm, np.asarray(height_model, float), peaks)
        spurious = np.where(visible, np.min(d2, axis=2), 0.0).sum(axis=1)
        score = explained + spurious
    return np.where(np.isfinite(score), score, np.inf)


def peaks_matched(f_model_hz, height_model, peaks: Peaks) -> bool:
    """Whether one model's modes ((n,) frequencies and peak heights) already reproduce the
    measured peaks to the grid's resolution: every measured peak has a mode within its
    :attr:`Peaks.resolution`, and every visible mode (as in :func:`peak_score`) a measured
    peak within that peak's (the heights as in :func:`peak_score`). A search on the peaks
    would then find this basin again."""
    if peaks.count == 0 or peaks.resolution is None:
        return False
    F = np.log(peaks.frequency_hz)
    fm = np.log(np.maximum(np.asarray(f_model_hz, float), 1e-12))
    d = np.abs(fm[:, None] - F[None, :])  # (n, m)
    if not np.all(np.min(d, axis=0) <= peaks.resolution):
        return False
    visible = _visible(np.exp(fm), np.asarray(height_model), peaks)
    nearest = np.argmin(d, axis=1)
    return bool(np.all(d[visible, nearest[visible]] <= peaks.resolution[nearest[visible]]))
