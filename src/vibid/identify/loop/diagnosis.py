"""Read a fit's residual as a structural dynamicist would: the poles of measured / model.

Fitted: ``R(f) = H_measured / H_model`` (1 where the model is right) by a real-system rational
model ``R ≈ d + e s + Σ r_k / (s - p_k) (+ conjugates)``, ``s = 2πi f``. A resonance the
model lacks is a pole of R; a misplaced mode, a pole at the measured mode beside a zero at
the model's; a delay or gain, a smooth ``d + e s`` plus real poles. Not ``H_measured -
H_model``: that carries every plate mode as a pole, R only the discrepancies.

How: scikit-rf's ``VectorFitting`` (any frequencies, ``fit_proportional=True``) places the
poles. It has no per-frequency weights (only one weight per response), so it sees only the
points where R's noise ``std_R = std / |H_model|`` is below 10 times its median (it is huge
at the model's antiresonances), at most ``_VF_POINTS`` of them. Residues, ``d``, ``e`` are
re-solved here by least squares weighted by ``1 / std_R`` on all points (giving ``chi2``),
and the best ``_POLISHED`` candidates' poles moved to the weighted optimum (real poles may
cross into the right half-plane: a zero of a non-minimum-phase H_model is a pole of R there,
which vector fitting flips). The model (0..``max_pole_pairs`` complex pairs, 0..2 real poles)
is chosen by BIC, ``chi2 + k ln 2N`` (``k`` real parameters, ``2N`` real data): pure noise
gives no poles. Without ``std``: weights 1 and ``2N ln(chi2 / 2N) + k ln 2N``.

Classification of a complex pole ``p`` (``f_hz = |p| / 2π``, ``q = |p| / 2|Re p|``): out of
the band (2 % margin) or ``q < 2`` → part of the trend; within ``max(2 f_k / Q_k, 3 % f_k)``
(5 % without ``plate_q``) of a plate mode ``f_k`` → ``mode_shift`` if the offset from the
model's pole is mostly in frequency (``|Δ Im p| ≥ |Δ Re p|``; without ``plate_q``: ``|f - f_k|
> f_k / 4q``), else ``damping``; at a dip of ``|H_model|`` (a misplaced antiresonance of the
model is a pole of R) → ``mode_shift``, the note says so; else ``extra_pole``, with
``hidden_mode_hz`` the nearest mode of the model that its sensor does not see
(``hidden_hz``) within :data:`HIDDEN_SPAN` of it: a sensor off the node line the model puts
it on shows a mode the model hides (the plate modes ``plate_modes_hz`` are those it shows),
and, on a uniform grid, ``causal``: whether its phase is that of a causal factor of its
magnitude (:func:`causal`; a resonance of a linear stand is). One ``trend`` gathers
``T = d + e s`` + real and out-of-band poles; its note gives the phase and magnitude change
and the delay a linear phase means. ``size``: the peak over the band
of ``|ΔR|``, the feature's term in R (trend: ``|T - 1|``).

Significance: ``sqrt(max(Δchi2 / b - ν, 0))``; ``Δchi2`` the rise of chi2 when the feature's
terms are dropped and the rest refitted (trend: ``T`` fixed to 1), ``ν`` its number of linear
parameters, ``b = max(1, chi2 / (2N - k))`` (the fit's reduced chi2 where it leaves more than
noise). Pure noise gives 0 to about 2, a lone feature about its amplitude over the noise.
Features below ``min_significance`` are dropped; without ``std`` it is NaN and features with
``size < min_size`` are dropped instead. So is a pole whose half-power band
``f (1 ± 1/2q)`` lies inside a band the fit leaves out (``left_out_hz``: a resonance's
top whose response depends on its amplitude): no fitted point sees it; the rational fit
bridged the gap (a real strip's "mode at 142.4 Hz (Q 53)" inside its left-out
133.6-144.7 Hz).
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from vibid.identify.engine.threads import numpy_only

if TYPE_CHECKING:
    from vibid.identify.fit.result import IdentificationResult
    from vibid.identify.model.plate import Modes

log = logging.getLogger(__name__)

_VF_POINTS = 1500  # vector fitting sees at most this many points (its time grows with N)
_POLISHED = 3  # how many of the best candidates get their poles polished
#: The polish keeps each pole within this factor of the band's top frequency: a real pole
#: far outside it is the constant again (their columns become one), a direction in which
#: the fit is flat and the pole would run off.
_REACH = 10.0
#: On a uniform grid (an FFT's bins) an extra pole's phase is compared, within this factor
#: of its frequency, with the phase a causal factor of its magnitude would have
#: (:func:`causal`).
CAUSAL_SPAN = 1.2
#: An extra pole within this factor of a mode of the model that its sensor does not see
#: may be that mode (the model's sensor on its node line, the material bent to place the
#: modes it does see: a strip's torsion 10 % off).
HIDDEN_SPAN = 1.25
_NAN = float("nan")


@dataclass(frozen=True)
class Feature:
    kind: str  # "extra_pole" | "mode_shift" | "damping" | "trend"
    f_hz: float = _NAN
    q: float = _NAN
    size: float = _NAN
    significance: float = _NAN
    note: str = ""
    #: an extra pole's nearest mode of the model that its sensor does not see (Hz)
    hidden_mode_hz: float = _NAN
    #: whether an extra pole's phase is a causal factor's (None: not judged, :func:`causal`)
    causal: bool | None = None
    #: a trend's parts (:data:`TREND_PARTS`) and each one's size by name: the phase's
    #: change across the band in rad, the magnitude's relative change, its mean offset
    part_sizes: tuple[tuple[str, float], ...] = ()

    def part_size(self, name: str) -> float:
        """The size of a trend's part ``name`` (0 where it has none)."""
        return abs(dict(self.part_sizes).get(name, 0.0))

    @property
    def parts(self) -> tuple[str, ...]:
        """A trend's parts worth a word in its note (:func:`_worth_a_word`)."""
        return _worth_a_word(self.part_sizes)

    @property
    def kinds(self) -> tuple[str, ...]:
        """Its kind, a trend's :attr:`parts`, and ``"hidden_mode"`` for an extra pole beside a
        mode of the model that its sensor does not see (what a candidate may explain);
        ``"acausal_pole"`` alone
        for an extra pole whose phase is not a causal factor's (:func:`causal`): no
        resonance of the stand or the plate makes it, only a term that divides by the
        base sensor's motion (the fixture's mode, which the base sensor's spot shares
        otherwise than the clamp) explains it."""
        if self.causal is False:
            return ("acausal_pole",)
        return (
            (self.kind,)
            + self.parts
            + (("hidden_mode",) if math.isfinite(self.hidden_mode_hz) else ())
        )

    def as_report(self) -> dict:
        out = {"kind": self.kind}
        for key in ("f_hz", "q", "size", "hidden_mode_hz"):
            if math.isfinite(getattr(self, key)):
                out[key] = float(getattr(self, key))
        if self.causal is not None:
            out["causal"] = bool(self.causal)
        return out | ({"note": self.note} if self.note else {})


@dataclass(frozen=True)
class Diagnosis:
    features: tuple[Feature, ...] = ()
    poles: tuple[complex, ...] = ()  # rad/s, one of each conjugate pair
    residues: tuple[complex, ...] = ()  # real for a real pole
    constant: float = 1.0
    proportional_s: float = 0.0  # coefficient of s = 2πi f
    chi2: float = _NAN  # weighted chi2 of the rational fit
    chi2_unity: float = _NAN  # weighted chi2 of R - 1
    n_points: int = 0
    message: str = ""  # why there is no diagnosis, or what failed

    @property
    def poles_hz(self) -> tuple[float, ...]:
        return tuple(abs(p) / (2 * math.pi) for p in self.poles)

    def ratio(self, frequency_hz) -> np.ndarray:
        """The fitted rational model of H_measured / H_model at ``frequency_hz``."""
        f = np.asarray(frequency_hz, float)
        coef = [self.constant, self.proportional_s]
        for p, r in zip(self.poles, self.residues):
            coef += [r.real] if p.imag == 0 else [r.real, r.imag]
        A = np.concatenate(_columns(f.ravel(), np.asarray(self.poles, complex)), axis=1)
        return (A @ np.asarray(coef, float)).reshape(f.shape)

    def extra_poles(self) -> tuple[Feature, ...]:
        return tuple(x for x in self.features if x.kind == "extra_pole")

    def as_report(self) -> list[dict]:
        return [x.as_report() for x in self.features]


#: Python's warning filters are global: two threads' ``catch_warnings`` that interleave
#: can leave the other's "ignore" behind for good, so one diagnosis is quiet at a time.
_QUIET = threading.Lock()


@contextlib.contextmanager
def _quiet():
    """scikit-rf's warnings and log silenced (while held, another thread's warnings too)."""
    log = logging.getLogger("skrf")
    with _QUIET:
        level = log.level
        log.setLevel(logging.CRITICAL)
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore")
                yield
        finally:
            log.setLevel(level)


def _columns(f_hz, poles) -> list[np.ndarray]:
    """Column groups of the real-coefficient basis: [1], [s], then one group per pole."""
    s = 2j * np.pi * np.asarray(f_hz, float)[:, None]
    groups = [np.ones_like(s), s]
    for p in poles:
        a, b = 1 / (s - p), 1 / (s - np.conj(p))
        groups.append(a if p.imag == 0 else np.hstack([a + b, 1j * (a - b)]))
    return groups


def _stacked(Z, w) -> np.ndarray:
    """A complex vector or matrix (rows: frequencies) as real rows, its real parts above its
    imaginary parts, each row times its point's weight ``w``."""
    ww = np.concatenate([w, w])
    return np.concatenate([Z.real, Z.imag]) * ww.reshape((-1,) + (1,) * (Z.ndim - 1))


def _column_scale(Ar) -> np.ndarray:
    """1 / each column's norm: the basis's columns (1, s, 1/(s - p)) differ by orders of
    magnitude, the least squares sees them at unit norm."""
    return 1 / np.maximum(np.linalg.norm(Ar, axis=0), 1e-300)


def _solve(groups, R, w, keep=None):
    """Weighted least squares of R (of R - 1 when the constant is dropped) on the kept groups:
    coefficients and weighted residual vector."""
    keep = [True] * len(groups) if keep is None else keep
    kept = [g for g, k in zip(groups, keep) if k]
    A = np.concatenate(kept, axis=1) if kept else np.zeros((len(R), 0))
    Ar = _stacked(A, w)
    b = _stacked(R if keep[0] else R - 1, w)
    if not A.shape[1]:
        return np.zeros(0), b
    scale = _column_scale(Ar)
    x = np.linalg.lstsq(Ar * scale, b, rcond=None)[0] * scale
    return x, b - Ar @ x


def _chi2(groups, R, w, keep=None) -> float:
    return float(np.sum(_solve(groups, R, w, keep)[1] ** 2))


def _vector_fit(f_hz, R, n_real, n_cmplx) -> np.ndarray:
    from skrf import Network
    from skrf.vectorFitting import VectorFitting

    vf = VectorFitting(Network(f=f_hz, s=R, f_unit="Hz"))
    vf.max_iterations = 50
    vf.vector_fit(n_poles_real=n_real, n_poles_cmplx=n_cmplx, fit_proportional=True)
    return np.asarray(vf.poles, complex)


def _polish(f, R, w, poles) -> np.ndarray:
    """Poles moved to the minimum of the weighted chi2, residues solved inside (variable
    projection). The Jacobian is Kaufman's, ``-P⊥ (∂A/∂θ) x``: its gradient ``Jᵀ r`` is the
    exact one (the term it leaves out is orthogonal to the residual), so the trust region
    stops at a stationary point, not where a finite-difference step stalls in a flat
    valley, and a perturbation of the data by rounding moves the poles by about as little.
    Each pole stays within :data:`_REACH` times the band's top (its real part, and a
    complex pole's imaginary part above a thousandth of that)."""
    from scipy.optimize import least_squares

    cplx, unit = poles.imag != 0, 2 * np.pi * np.mean(f)
    s = 2j * np.pi * np.asarray(f, float)
    b = _stacked(R, w)

    def unpack(x):
        p = x[: len(poles)] * unit + 0j
        p[cplx] += 1j * x[len(poles) :] * unit
        return p

    def projected(x):
        """Weighted residual, and its Jacobian with the residues held (Kaufman)."""
        p = unpack(x)
        Ar = _stacked(np.concatenate(_columns(f, p), axis=1), w)
        scale = _column_scale(Ar)
        Q, T = np.linalg.qr(Ar * scale)
        coef = np.linalg.lstsq(T, Q.T @ b, rcond=None)[0] * scale
        d_re, d_im, at = [], [], 2  # ∂(A coef)/∂Re p and ∂/∂Im p; columns 0, 1: 1 and s
        for pk in p:
            a = 1 / (s - pk)
            if pk.imag == 0:
                d_re.append(coef[at] * a**2)
                at += 1
                continue
            up = (coef[at] + 1j * coef[at + 1]) * a**2
            down = (coef[at] - 1j * coef[at + 1]) / (s - np.conj(pk)) ** 2
            d_re.append(up + down)
            d_im.append(1j * (up - down))
            at += 2
        Dr = _stacked(np.stack(d_re + d_im, axis=1) * unit, w)
        return b - Q @ (Q.T @ b), Q @ (Q.T @ Dr) - Dr

    memo = {}

    def both(x):
        if x.tobytes() not in memo:
            memo.clear()
            memo[x.tobytes()] = projected(x)
        return memo[x.tobytes()]

    reach = _REACH * np.max(f) / np.mean(f)  # in units of the mean angular frequency
    lo = np.concatenate([np.full(len(poles), -reach), np.full(cplx.sum(), 1e-3 * reach)])
    hi = np.full(lo.shape, reach)
    x0 = np.clip(np.concatenate([poles.real, poles.imag[cplx]]) / unit, lo, hi)
    fit = least_squares(
        lambda x: both(x)[0],
        x0,
        jac=lambda x: both(x)[1],
        bounds=(lo, hi),
        method="trf",
        ftol=1e-12,
        xtol=1e-12,
        gtol=1e-10,
        max_nfev=100 * (len(x0) + 1),
    )
    return unpack(fit.x)


def _n_params(poles) -> int:
    return 2 + sum(2 if p.imag == 0 else 4 for p in poles)


def _select(f, R, w, known_noise, max_pairs):
    """Poles of the BIC-best rational model of R, its chi2, and skrf's errors if any."""
    use = np.flatnonzero(w >= 0.1 * np.median(w))
    use = use[np.unique(np.linspace(0, len(use) - 1, min(len(use), _VF_POINTS)).astype(int))]
    n2 = 2 * len(f)

    def scored(poles):
        poles = poles[np.isfinite(poles) & (np.abs(poles) > 0)]
        chi2 = _chi2(_columns(f, poles), R, w)
        fit = chi2 if known_noise else n2 * math.log(max(chi2, 1e-300) / n2)
        bic = fit + _n_params(poles) * math.log(n2)
        ok = math.isfinite(bic) and np.count_nonzero(poles.imag) <= max_pairs
        return (bic if ok else math.inf), chi2, poles

    candidates, errors = [scored(np.zeros(0, complex))], []
    for n_real in range(3):
        for n_cmplx in range(max_pairs + 1):
            if 0 < n_real + n_cmplx and n_real + 2 * n_cmplx + 3 <= len(use):
                try:
                    candidates.append(scored(_vector_fit(f[use], R[use], n_real, n_cmplx)))
                except Exception as exc:  # noqa: BLE001 - a failure of skrf: try the next order
                    errors.append(f"{type(exc).__name__}: {exc}")
    candidates.sort(key=lambda c: c[0])
    for _, _, poles in [c for c in candidates[:_POLISHED] if len(c[2]) and math.isfinite(c[0])]:
        try:
            candidates.append(scored(_polish(f[use], R[use], w[use], poles)))
        except Exception as exc:  # noqa: BLE001 - keep the unpolished poles
            errors.append(f"{type(exc).__name__}: {exc}")
    _, chi2, poles = min(candidates, key=lambda c: c[0])
    return poles, chi2, errors


def unseen(f_hz: float, q: float, left_out_hz) -> bool:
    """Whether a pole's half-power band ``f (1 ± 1/2q)`` lies inside one of the bands
    ``left_out_hz`` ((lo, hi), Hz) that the fit leaves out (module doc)."""
    half = f_hz / (2 * q)
    return any(lo < f_hz - half and f_hz + half < hi for lo, hi in left_out_hz)


def _classify(p, f_lo, f_hi, modes_hz, modes_q, dips, hidden_hz=()):
    """(kind, note, hidden mode's Hz or NaN) of the complex pole p (rad/s); kind "trend"
    when it is no resonance."""
    f_p, q_p = abs(p) / (2 * math.pi), abs(p) / (2 * abs(p.real))
    if q_p < 2 or not 0.98 * f_lo <= f_p <= 1.02 * f_hi:
        return "trend", "", _NAN
    for f_k, q_k in zip(modes_hz, modes_q):
        if abs(f_p - f_k) > (max(2 * f_k / q_k, 0.03 * f_k) if q_k > 0 else 0.05 * f_k):
            continue
        if q_k > 0:  # the model's pole: -w_k / 2Q_k + i w_k sqrt(1 - 1 / 4Q_k²)
            w_k = 2 * math.pi * f_k
            d_im = abs(p.imag - w_k * math.sqrt(max(1 - 1 / (4 * q_k**2), 0)))
            shift = d_im >= abs(abs(p.real) - w_k / (2 * q_k))
            model = f", {q_k:.3g} in the model"
        else:
            shift, model = abs(f_p - f_k) > f_k / (4 * q_p), ""
        if shift:
            return (
                "mode_shift",
                (
                    f"the mode the model puts at {f_k:.4g} Hz is at {f_p:.4g} Hz "
                    f"in the data ({100 * (f_p / f_k - 1):+.1f} %)"
                ),
                _NAN,
            )
        return (
            "damping",
            (f"the mode at {f_p:.4g} Hz is damped otherwise: Q {q_p:.3g} in the data{model}"),
            _NAN,
        )
    if any(lo <= f_p <= hi or abs(f_p - mid) <= 0.03 * mid for lo, mid, hi in dips):
        return (
            "mode_shift",
            (
                f"the ratio resonates at {f_p:.4g} Hz (Q {q_p:.3g}) where the "
                "model has an antiresonance: the modes around it are misplaced "
                "or misweighted"
            ),
            _NAN,
        )
    near = [f_k for f_k in hidden_hz if abs(math.log(f_k / f_p)) <= math.log(HIDDEN_SPAN)]
    if near:
        f_k = min(near, key=lambda f_k: abs(math.log(f_k / f_p)))
        return (
            "extra_pole",
            (
                f"a resonance at {f_p:.4g} Hz (Q {q_p:.3g}) where the plate has "
                f"no mode its sensor sees: the model's mode at {f_k:.4g} Hz, "
                "which its sensor does not see, may be it"
            ),
            f_k,
        )
    return (
        "extra_pole",
        (f"a resonance at {f_p:.4g} Hz (Q {q_p:.3g}) where the plate has no mode"),
        _NAN,
    )


def causal(f_hz, R, f_p: float) -> bool | None:
    """Whether the ratio ``R`` near ``f_p`` has the phase of a causal factor of its magnitude:
    within :data:`CAUSAL_SPAN` of ``f_p``, ``ln |R|`` and the phase each detrended to the
    window's edges, the minimum phase ``−Hilbert{ln |R|}`` against the measured phase within
    10 % of ``f_p`` (correlation above 0.5: True, below −0.5: False). None where the grid
    there is not uniform and dense (200 points or more: an FFT's bins), or where the
    minimum phase swings by less than 0.1 rad (too small a feature to judge). Any resonance
    of a linear stand multiplies or adds to H causally (on a real strip's 664 Hz feature
    the phase rose by 27° where a causal factor's would fall by 57°)."""
    window = (f_hz >= f_p / CAUSAL_SPAN) & (f_hz <= f_p * CAUSAL_SPAN)
    f, R = f_hz[window], R[window]
    step = np.diff(f)
    if f.size < 200 or np.ptp(step) > 0.01 * np.median(step):
        return None
    from scipy.signal import hilbert  # here: importing scipy.signal takes 2 s

    ln_mag, phase = np.log(np.abs(R)), np.unwrap(np.angle(R))
    ln_mag = ln_mag - np.interp(f, f[[0, -1]], ln_mag[[0, -1]])
    phase = phase - np.interp(f, f[[0, -1]], phase[[0, -1]])
    pad = np.zeros(2 * f.size)
    minimum = -np.imag(hilbert(np.concatenate([pad, ln_mag, pad])))[pad.size : -pad.size]
    near = np.abs(f - f_p) <= 0.1 * f_p
    if np.ptp(minimum[near]) < 0.1:
        return None
    c = float(np.corrcoef(phase[near], minimum[near])[0, 1])
    return True if c > 0.5 else False if c < -0.5 else None


#: A trend's parts, each what one kind of effect explains: its phase across the band (a
#: delay between the channels), its magnitude across the band, its magnitude's mean offset
#: (a sensitivity error). A part is worth a word where it is at least a fifth of the
#: largest (:func:`_worth_a_word`).
TREND_PARTS = ("phase_slope", "magnitude_slope", "magnitude_offset")


def _worth_a_word(part_sizes) -> tuple[str, ...]:
    """The parts (``(name, size)`` pairs) at least a fifth of the largest, and 1e-3."""
    least = max(0.2 * max((abs(x) for _, x in part_sizes), default=0.0), 1e-3)
    return tuple(name for name, x in part_sizes if abs(x) >= least)


def _trend_measures(f_hz, T):
    """``(part_sizes, slope, linear)`` of the trend ``T`` on ``f_hz``: its
    :data:`TREND_PARTS` by name (the phase's and the magnitude's change across the band,
    the magnitude's mean offset from 1), the phase's slope (rad/Hz) and whether it is
    linear."""
    mag, phase = np.abs(T), np.unwrap(np.angle(T))
    slope, intercept = np.polyfit(f_hz, phase, 1)
    d_phase, d_mag, gain = phase[-1] - phase[0], mag[-1] / mag[0] - 1, float(np.mean(mag)) - 1
    linear = bool(np.max(np.abs(phase - slope * f_hz - intercept)) <= 0.2 * abs(d_phase))
    sizes = tuple(zip(TREND_PARTS, map(float, (d_phase, d_mag, gain))))
    return sizes, float(slope), linear


def _trend_note(part_sizes, slope, linear) -> str:
    size = dict(part_sizes)
    d_phase, d_mag, gain = (size[p] for p in TREND_PARTS)
    worth = _worth_a_word(part_sizes)
    parts = []
    if "phase_slope" in worth:
        tau_us = -slope / (2 * math.pi) * 1e6
        why = f": a time delay of {tau_us:.3g} µs?" if tau_us > 0 else ": a time advance?"
        parts.append(
            f"phase {'falls' if d_phase < 0 else 'rises'} {'linearly ' * linear}by "
            f"{abs(math.degrees(d_phase)):.2g}° across the band "
            f"(slope {slope:.3g} rad/Hz{why * linear})"
        )
    if "magnitude_slope" in worth:
        parts.append(
            f"magnitude {'rises' if d_mag > 0 else 'falls'} by {abs(100 * d_mag):.3g} % "
            "across the band"
        )
    if "magnitude_offset" in worth:
        parts.append(f"magnitude {100 * gain:+.3g} % off the model on average")
    return "; ".join(parts)


def diagnose(
    frequency_hz,
    H_measured,
    H_model,
    std,
    *,
    plate_modes_hz,
    plate_q=None,
    hidden_hz=(),
    max_pole_pairs: int = 4,
    min_significance: float = 5.0,
    min_size: float = 0.02,
    left_out_hz=(),
) -> Diagnosis:
    """Features of ``H_measured / H_model`` (module docstring); never raises, prints nothing.
    ``left_out_hz``: (lo, hi) bands, Hz, that the fit leaves out."""
    try:
        with _quiet():
            return _diagnose(
                frequency_hz,
                H_measured,
                H_model,
                std,
                plate_modes_hz,
                plate_q,
                hidden_hz,
                max(int(max_pole_pairs), 0),
                min_significance,
                min_size,
                tuple(left_out_hz),
            )
    except Exception as exc:  # noqa: BLE001 - a diagnosis must never stop the loop
        return Diagnosis(message=f"diagnosis failed: {type(exc).__name__}: {exc}")


def _usable_ratio(frequency_hz, H_measured, H_model, std):
    """``(f, R, H_model, std)`` sorted by frequency, at the points where the ratio
    ``R = measured / model`` is finite and the frequency positive."""
    f = np.asarray(frequency_hz, float).ravel()
    sd = np.broadcast_to(np.asarray(np.nan if std is None else std, float), f.shape)
    order = np.argsort(f, kind="stable")
    f, sd = f[order], sd[order]
    H0 = np.asarray(H_model, complex).ravel()[order]
    R = np.asarray(H_measured, complex).ravel()[order] / H0
    ok = np.isfinite(f) & (f > 0) & np.isfinite(R)
    return f[ok], R[ok], H0[ok], sd[ok]


def _pole_features(
    poles, f, R, H0, term, significance, plate_modes_hz, plate_q, hidden_hz, left_out_hz
) -> tuple[list, list]:
    """``(features, trend)``: a :class:`Feature` for each fitted pole that is not part of
    the trend (:func:`_classify` against the plate's modes and the model's antiresonances,
    left out where the fit does not see it, :func:`unseen`), and the indices of the terms
    that make the trend (the constant and the slope, 0 and 1, and the trend's poles)."""
    modes_hz = np.atleast_1d(np.asarray(plate_modes_hz, float)).ravel()
    modes_q = np.broadcast_to(
        np.asarray(np.nan if plate_q is None else plate_q, float), modes_hz.shape
    )
    a = np.abs(H0)
    i = np.flatnonzero((a[1:-1] < a[:-2]) & (a[1:-1] < a[2:])) + 1
    dips = np.stack([f[i - 1], f[i], f[i + 1]], axis=1)  # the model's antiresonances
    hidden_hz = np.atleast_1d(np.asarray(hidden_hz, float))
    features, trend = [], [0, 1]
    for k, p in enumerate(poles, start=2):
        kind, note, hidden = "trend", "", _NAN
        if p.imag != 0:
            kind, note, hidden = _classify(p, f[0], f[-1], modes_hz, modes_q, dips, hidden_hz)
        if kind == "trend":
            trend.append(k)
            continue
        f_p, q_p = float(abs(p) / (2 * math.pi)), float(abs(p) / (2 * abs(p.real)))
        if unseen(f_p, q_p, left_out_hz):
            continue
        size = float(np.max(np.abs(term[k])))
        is_causal = causal(f, R, f_p) if kind == "extra_pole" else None
        if is_causal is False:
            note += (
                "; its phase moves against the phase a causal resonance of its "
                "magnitude would have: no resonance of the stand or the plate makes "
                "it (a bias of the H estimate where the base's signal is weak?)"
            )
        features.append(Feature(kind, f_p, q_p, size, significance({k}), note, hidden, is_causal))
    return features, trend


def _diagnose(
    frequency_hz,
    H_measured,
    H_model,
    std,
    plate_modes_hz,
    plate_q,
    hidden_hz,
    max_pairs,
    min_significance,
    min_size,
    left_out_hz=(),
) -> Diagnosis:
    f, R, H0, sd = _usable_ratio(frequency_hz, H_measured, H_model, std)
    if len(f) < 10:
        return Diagnosis(n_points=len(f), message=f"too few usable points ({len(f)}) to diagnose")
    sd_R = sd / np.abs(H0)
    good = np.isfinite(sd_R) & (sd_R > 0)
    known_noise = bool(good.any())
    w = 1 / np.where(good, sd_R, np.median(sd_R[good]) if known_noise else 1.0)
    poles, chi2, errors = _select(f, R, w, known_noise, max_pairs)
    groups = _columns(f, poles)
    coef = _solve(groups, R, w)[0]
    starts = np.cumsum([0] + [g.shape[1] for g in groups])
    f_dense = np.union1d(f, np.geomspace(f[0], f[-1], 400))
    term = [g @ coef[a:b] for g, a, b in zip(_columns(f_dense, poles), starts[:-1], starts[1:])]
    birge = max(1.0, chi2 / max(2 * len(f) - _n_params(poles), 1))

    def significance(drop):
        if not known_noise:
            return _NAN
        rise = (_chi2(groups, R, w, [i not in drop for i in range(len(groups))]) - chi2) / birge
        return math.sqrt(max(rise - sum(groups[i].shape[1] for i in drop), 0.0))

    features, trend = _pole_features(
        poles, f, R, H0, term, significance, plate_modes_hz, plate_q, hidden_hz, left_out_hz
    )
    T = sum(term[k] for k in trend)
    sizes, slope, linear = _trend_measures(f_dense, T)
    size = float(np.max(np.abs(T - 1)))
    note = (
        _trend_note(sizes, slope, linear)
        or f"the ratio drifts smoothly by up to {100 * size:.2g} %"
    )
    features.append(
        Feature(
            "trend", size=size, significance=significance(set(trend)), note=note, part_sizes=sizes
        )
    )
    rank = (lambda x: x.significance) if known_noise else (lambda x: x.size)
    limit = min_significance if known_noise else min_size
    residues = [complex(*coef[a:b]) for a, b in zip(starts[2:-1], starts[3:])]
    kept = sorted((x for x in features if rank(x) >= limit), key=rank, reverse=True)
    return Diagnosis(
        tuple(kept),
        tuple(complex(p) for p in poles),
        tuple(residues),
        float(coef[0]),
        float(coef[1]),
        chi2,
        float(np.sum((w * np.abs(R - 1)) ** 2)),
        len(f),
        "; ".join(dict.fromkeys(errors)) if errors and not len(poles) else "",
    )


@numpy_only
def diagnosis_of(modes: Modes | None, r: IdentificationResult, left_out_hz=()):
    """The diagnosis of a fit's residual (:mod:`vibid.identify.loop.diagnosis`) given its
    plate's ``modes``, or None; ``left_out_hz``: bands the fit leaves out, where no pole is
    a feature (:class:`~vibid.identify.loop.state.Inputs`; not every unused stretch: an adaptive campaign's planner
    wants the pole its residual shows between two steps, to measure there)."""
    if modes is None:
        return None
    try:
        modes_hz, q, hidden_hz = model_resonances(modes, r)
        u = np.asarray(r.used)
        return diagnose(
            r.frequency_hz[u],
            r.H[u],
            r.model_afc[u],
            None if r.H_std is None else np.asarray(r.H_std)[u],
            plate_modes_hz=modes_hz,
            plate_q=q,
            hidden_hz=hidden_hz,
            left_out_hz=left_out_hz,
        )
    except Exception as exc:  # noqa: BLE001 - the diagnosis informs, it never stops a fit
        log.warning("loop: the residual could not be diagnosed: %s", exc)
        return None


def model_resonances(modes: Modes, result):
    """``(frequency_hz, Q, hidden_hz)`` of the fitted model's resonances: the plate's
    ``modes`` its sensor sees and its stand resonances; and the plate's modes its sensor
    does not see (:attr:`Modes.seen`)."""
    params = result.parameters
    shown = modes.seen
    hidden_hz = modes.frequency_hz[~shown]
    f_hz, q = modes.frequency_hz[shown], modes.q[shown]
    stand = [
        (params[t.names[0]], params[t.names[1]])  # (f_hz_k, q_k)
        for t in result.plate_model.effects
        if t.rotates_base
    ]
    if stand:
        f_hz = np.concatenate([f_hz, [s[0] for s in stand]])
        q = np.concatenate([q, [s[1] for s in stand]])
    return np.asarray(f_hz, float), np.asarray(q, float), hidden_hz
