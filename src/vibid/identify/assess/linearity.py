"""Is a measured resonance the response of a linear structure? A test on the AFC alone.

A linear, time-invariant structure's AFC near a resonance is a rational function: a few
pole pairs (the mode, any close neighbour) plus a smooth background from the modes outside
the band. Fitted by 1 to :data:`MAX_PAIRS` pole pairs, a constant and a slope, it must come
down to the data's own point-to-point scatter. When no number of linear modes does, the
response holds something a linear FRF cannot: most often an amplitude-dependent clamp (the
friction of a clamped edge grows with the motion, which is largest at a resonance), or
the way the AFC was estimated. Two linear modes close together pass: two pole pairs fit
them.

The test needs a dense grid: at least :data:`POINTS_PER_BANDWIDTH` points per half-power
bandwidth (an FFT analyser's AFC; a stepped sine of a few hundred steps rarely has them).
An analyser's H at a bin is the response averaged over its resolution bandwidth (a Hann
window's: 1.5 bins), which lowers a linear resonance's top by a few per cent at 6 points
per band, over a few of the band's hundreds of points: one pole pair still fits it well
within the scatter (the tests' analyser-smoothed oscillator). A linear
structure's poles are stable: the pole pairs are fitted with their damping ≥ 0 (left free,
an unstable pole of negative Q bends the sum onto a nonlinear resonance, which then passes
as "linear": a real strip's first resonance took one of Q −45, BENCHMARKS.md).
It does not use vibid's plate model, so it also says something the model cannot: whether
any linear model could fit this resonance at all.

Where no linear model fits, the flanks say which way the response depends on its amplitude.
Away from the top (further than :data:`FLANK_WIDTHS` half-power widths of the whole band's
one-mode fit) the motion is smallest: one pole pair fitted there alone is the structure at
small amplitude. If it fits the flanks to the scatter, is damped less than the whole
resonance (beyond :data:`Q_RATIO`) and sits higher, the structure softens and loses more
energy as its motion grows: a joint that sticks at small amplitude and slips at large (the
micro-slip of a clamp; under a broadband excitation, whose amplitude varies, such a
stiffness spreads the top over frequencies as well). If the flanks are damped more than
the top, the motion outgrows a dry friction instead. A drift of the temperature during the
measurement would broaden every resonance by the same relative spread; the sentence gives
the flanks' and the top's frequency and Q, so the resonances of one AFC can be compared.

Scatter: second differences of H/|H| on the grid, ``√(mean |Δ²|² / 12)`` per real and
imaginary part for white noise (Δ² of white noise of std e per part has variance 6 e²
per part); smooth curvature adds to it, so it is an upper estimate of the noise.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

#: Pole pairs tried.
MAX_PAIRS = 3
#: A resonance is linear when some linear model leaves a relative RMS residual within this
#: factor of the scatter (√2 × the per-part scatter, for the complex residual).
FACTOR = 3.0
#: Points the grid must have per half-power bandwidth (f / Q) for the test to run (an FFT
#: analyser's 0.122 Hz bins give a real strip's first resonance 7: BENCHMARKS.md).
POINTS_PER_BANDWIDTH = 5
#: The band fitted: this fraction of the peak's frequency either side (cut halfway to a
#: neighbouring peak).
HALF_BAND = 0.2
#: The flanks: points further from the one-mode fit's frequency than this many half-power
#: widths (f / Q) of it.
FLANK_WIDTHS = 6.0
#: The flanks' mode is damped less (or more) than the top's beyond this ratio of Q.
Q_RATIO = 1.5


@dataclass(frozen=True)
class Linearity:
    """The test at one resonance: its frequency (Hz), the points fitted, the scatter (per
    part, relative to |H|), the relative RMS residual of 1..MAX_PAIRS pole pairs, and the
    verdict with its sentence."""

    f_hz: float
    n_points: int
    scatter: float
    rms: tuple[float, ...]
    linear: bool
    note: str
    #: (Hz, Q) of the whole band's one pole pair, and (Hz, Q, relative RMS) of the one
    #: fitted to the flanks alone (module doc); None where the resonance is linear or the
    #: flanks hold too few points
    top: tuple[float, float] | None = None
    flanks: tuple[float, float, float] | None = None
    #: (lo, hi) Hz of the top that a linear model is not asked to fit (:func:`linear_part`);
    #: None where the top stays
    left_out_hz: tuple[float, float] | None = None

    @property
    def left_out_note(self) -> str:
        """What the fit leaves out here, in a lab's words ("" where nothing)."""
        if self.left_out_hz is None:
            return ""
        lo, hi = self.left_out_hz
        return (
            f"left out of the fit: {lo:.4g}-{hi:.4g} Hz, the top of the resonance at "
            f"{self.f_hz:.4g} Hz, whose response depends on its amplitude (a linear model "
            "fits its flanks, where the motion is small)"
        )

    def as_report(self) -> dict:
        out = {
            "f_hz": self.f_hz,
            "n_points": self.n_points,
            "scatter": self.scatter,
            "rms_by_pole_pairs": list(self.rms),
            "linear": self.linear,
            "note": self.note,
        }
        if self.flanks is not None:
            out["top"] = {"f_hz": self.top[0], "q": self.top[1]}
            out["flanks"] = {"f_hz": self.flanks[0], "q": self.flanks[1], "rms": self.flanks[2]}
        if self.left_out_hz is not None:
            out["left_out_hz"] = list(self.left_out_hz)
        return out


def resonance_linearity(frequency_hz, H, peaks_hz) -> list[Linearity]:
    """The test at each peak of ``peaks_hz`` that the grid resolves (module doc)."""
    f = np.asarray(frequency_hz, float)
    order = np.argsort(f)
    f, H = f[order], np.asarray(H, complex)[order]
    peaks = _separated(f, np.abs(H), np.asarray(peaks_hz, float))
    out = []
    for k, fp in enumerate(peaks):
        lo = max(fp * (1 - HALF_BAND), 0.5 * (fp + peaks[k - 1]) if k > 0 else 0.0)
        hi = min(fp * (1 + HALF_BAND), 0.5 * (fp + peaks[k + 1]) if k + 1 < peaks.size else np.inf)
        band = (f > lo) & (f < hi) & np.isfinite(H)
        if (
            band.sum() < 8 * (MAX_PAIRS + 1)
            or _half_power_points(f[band], H[band]) < POINTS_PER_BANDWIDTH
        ):
            continue  # too few points, or a grid that does not resolve the resonance
        found = _test(f[band], H[band], fp)
        if found is not None:
            out.append(found)
    return out


def _separated(f, mag, peaks_hz) -> np.ndarray:
    """The peaks, highest first, without those within :data:`HALF_BAND` of a higher one (a
    noisy top has many local maxima; close modes are tested together) and without those
    that are not the highest point of ``mag`` within :data:`HALF_BAND` of themselves (a
    noisy flank's bumps, which would cut a resonance's band short), sorted."""
    index = np.clip(np.searchsorted(f, peaks_hz), 1, f.size - 1)
    height = np.maximum(mag[index - 1], mag[index])  # the grid points either side of each
    kept = []
    for fp, h in zip(peaks_hz[np.argsort(-height)], np.sort(height)[::-1]):
        near = np.abs(f - fp) <= HALF_BAND * fp  # empty on a grid coarser than the band
        if near.any() and h < mag[near].max():
            continue
        if all(abs(fp - k) > HALF_BAND * k for k in kept):
            kept.append(fp)
    return np.sort(np.array(kept, float))


def _half_power_points(f, H) -> int:
    """Grid points in the contiguous run around the band's maximum where |H| stays above
    the maximum over √2 (the half-power band)."""
    mag = np.abs(H)
    k = int(np.argmax(mag))
    above = mag >= mag[k] / math.sqrt(2)
    lo, hi = k, k
    while lo > 0 and above[lo - 1]:
        lo -= 1
    while hi + 1 < mag.size and above[hi + 1]:
        hi += 1
    return hi - lo + 1


def _test(f, H, fp) -> Linearity | None:
    fits = []
    for n in range(1, MAX_PAIRS + 1):
        fitted = rational_fit(f, H, n)
        if fitted is None:
            return None
        fits.append(fitted)
    rms = [r for r, _ in fits]
    scatter = relative_scatter(H)
    best, limit = min(rms), FACTOR * math.sqrt(2) * scatter
    linear = best <= limit
    top = flanks = left_out = None
    if linear:
        n = next(k for k, r in enumerate(rms, start=1) if r <= limit)  # the fewest that fit
        best = rms[n - 1]
        note = (
            f"the resonance at {fp:.4g} Hz is a linear one: {n} pole pair"
            f"{'s fit' if n > 1 else ' fits'} it to {100 * best:.2g} % (scatter "
            f"{100 * scatter:.2g} %)"
        )
    else:
        note = (
            f"the resonance at {fp:.4g} Hz is no sum of linear modes: {len(rms)} pole pairs "
            f"still leave {100 * best:.2g} % against a point-to-point scatter of "
            f"{100 * scatter:.2g} % (1 pair: {100 * rms[0]:.2g} %)"
        )
        top = tuple(float(v) for v in fits[0][1][0])
        flanks = flank_mode(f, H, *top)
        note += "; " + amplitude_sentence(top, flanks, limit)
        if amplitude_told(top, flanks, limit):
            width = FLANK_WIDTHS * top[0] / top[1]
            left_out = (top[0] - width, top[0] + width)
    return Linearity(
        float(fp), int(f.size), scatter, tuple(rms), bool(linear), note, top, flanks, left_out
    )


def linear_part(frequency_hz, H, std=None, used=None) -> tuple[np.ndarray, tuple[Linearity, ...]]:
    """The points a linear model can be asked to fit, and the test at each resolved
    resonance of the measured peaks (module doc): ``used`` (default: every finite point)
    less the tops whose response is shown to depend on its amplitude."""
    from vibid.identify.fit.peaks import measured_peaks

    f = np.asarray(frequency_hz, float)
    H = np.asarray(H, complex)
    used = np.isfinite(f) & np.isfinite(H) if used is None else np.asarray(used, bool).copy()
    s = None if std is None else np.asarray(std, float)[used]
    peaks_hz = measured_peaks(f[used], H[used], s).frequency_hz
    tests = tuple(resonance_linearity(f[used], H[used], peaks_hz))
    for t in tests:
        if t.left_out_hz is not None:
            used &= ~((f > t.left_out_hz[0]) & (f < t.left_out_hz[1]))
    return used, tests


def flank_mode(f, H, f_top, q_top) -> tuple[float, float, float] | None:
    """(Hz, Q, relative RMS) of one pole pair fitted to the flanks alone: the points
    further than :data:`FLANK_WIDTHS` half-power widths from ``f_top`` (module doc), with
    at least a quarter of the band's points on either side; None otherwise."""
    if not (np.isfinite(f_top) and q_top > 0):
        return None
    away = np.abs(f - f_top) > FLANK_WIDTHS * f_top / q_top
    enough = f.size // 4
    if (away & (f < f_top)).sum() < enough or (away & (f > f_top)).sum() < enough:
        return None
    fitted = rational_fit(f[away], H[away], 1)
    if fitted is None or not fitted[1]:
        return None
    rms, ((f_hz, q),) = fitted
    return float(f_hz), float(q), float(rms)


def amplitude_told(top, flanks, limit: float) -> bool:
    """Whether the flanks show the response to depend on its amplitude: one linear mode
    fits them to ``limit`` and its Q differs from the top's beyond :data:`Q_RATIO`."""
    if flanks is None or flanks[2] > limit:
        return False
    return flanks[1] > Q_RATIO * top[1] or flanks[1] * Q_RATIO < top[1]


def amplitude_sentence(top, flanks, limit: float) -> str:
    """What the flanks say of the amplitude dependence (module doc), in a lab's words."""
    generic = (
        "the response depends on something a linear FRF does not hold, most likely "
        "its amplitude (a clamp whose friction depends on the motion)"
    )
    if flanks is None or flanks[2] > limit:
        return generic
    (f_top, q_top), (f_fl, q_fl, rms) = top, flanks
    told = (
        f"on its flanks alone one linear mode fits to {100 * rms:.2g} %: Q {q_fl:.0f} at "
        f"{f_fl:.5g} Hz, where the whole resonance needs Q {q_top:.0f} at {f_top:.5g} Hz"
    )
    if q_fl > Q_RATIO * q_top and f_fl > f_top:
        return (
            told + ": at large motion the structure is softer and more damped than at "
            "small, as a joint is that sticks at small amplitude and slips at large (a "
            "clamp's micro-slip; under a broadband excitation, whose amplitude varies, "
            "such a stiffness also spreads the top over frequencies)"
        )
    if q_fl * Q_RATIO < q_top:
        return (
            told + ": the top is damped less than the flanks, as by a dry friction "
            "that the motion outgrows"
        )
    return told + "; " + generic


def relative_scatter(H) -> float:
    """The point-to-point scatter of ``H`` on its grid, per real and imaginary part,
    relative to |H| (module doc)."""
    d2 = H[2:] - 2 * H[1:-1] + H[:-2]
    return float(np.sqrt(np.mean(np.abs(d2 / H[1:-1]) ** 2) / 12.0))


def rational_fit(f, H, n) -> tuple[float, list[tuple[float, float]]] | None:
    """(relative RMS residual, the poles as (Hz, Q)) of the best rational model with ``n``
    stable pole pairs, a constant and a slope, in relative terms (weights 1/|H|):
    scikit-rf's VectorFitting places the poles, least squares polishes them with each
    pair's damping kept ≥ 0 (a linear structure's poles are stable). None where it
    fails."""
    import skrf
    from scipy.optimize import least_squares
    from skrf.vectorFitting import VectorFitting

    s, s0 = 2j * np.pi * f, 2j * np.pi * f.mean()
    try:
        nw = skrf.Network(frequency=skrf.Frequency.from_f(f, unit="hz"), s=H.reshape(-1, 1, 1))
        vf = VectorFitting(nw)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            vf.vector_fit(n_poles_real=0, n_poles_cmplx=n, fit_constant=True, fit_proportional=True)
    except Exception:  # noqa: BLE001 - no fit, no verdict
        return None
    c0, c1 = complex(vf.constant_coeff[0]), complex(vf.proportional_coeff[0] * s0)
    x0 = [c0.real, c0.imag, c1.real, c1.imag]
    for p, r in zip(vf.poles, vf.residues[0]):
        if p.imag > 0:
            x0 += [-p.real, p.imag, r.real, r.imag]
    pairs = (len(x0) - 4) // 4

    def model(x):
        out = (x[0] + 1j * x[1]) + (x[2] + 1j * x[3]) * s / s0
        for k in range(pairs):
            a, b, rr, ri = x[4 + 4 * k : 8 + 4 * k]
            out = out + (rr + 1j * ri) / (s - (-a + 1j * b)) + (rr - 1j * ri) / (s - (-a - 1j * b))
        return out

    def residual(x):
        e = (model(x) - H) / np.abs(H)
        return np.concatenate([e.real, e.imag])

    lower = np.full(len(x0), -np.inf)
    lower[4::4] = 0.0  # each pair's damping a: the pole -a ± ib in the left half-plane
    x0 = np.maximum(x0, lower)
    x = least_squares(residual, x0, bounds=(lower, np.inf), x_scale="jac", max_nfev=4000).x
    e = np.abs(model(x) - H) / np.abs(H)
    poles = [
        (
            x[5 + 4 * k] / (2 * np.pi),
            x[5 + 4 * k] / (2 * x[4 + 4 * k]) if x[4 + 4 * k] > 0 else math.inf,
        )
        for k in range(pairs)
    ]
    return float(np.sqrt(np.mean(e**2))), poles
