"""From the steps of a session to the measured AFC: one complex point per step, with flags.

Each step's two records go through the joint harmonic fit (:mod:`vibid.signal.harmonic`);
steps of equal length and harmonic count are fitted together. The point is
``H = X_response / X_base`` at the frequency found in the record (the DAQ's clock), with the
delta-method covariance of ``(Re H, Im H)`` (:mod:`vibid.signal.ratio`).

Reported uncertainty: ``std_re`` and ``std_im`` are the standard uncertainties of the real
and imaginary parts; ``std`` (the report's single value per point) is their RMS,
``√((var Re + var Im)/2)``. With white noise the two agree to a few per cent.

A step is *used* when its status is ``ok`` and it carries no flag (:mod:`vibid.signal.flags`)
other than those listed in ``ignore_flags``. Flagged steps stay in the table, with reasons.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Collection, Iterable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Protocol

import numpy as np

from vibid.signal.basis import Layout
from vibid.signal.flags import (
    CHANNELS,
    Flag,
    FlagThresholds,
    FreeVibration,
    decay_z,
    flat_top_fraction,
    free_vibration,
    quality_flags,
    settling_chi2,
)
from vibid.signal.harmonic import fit_harmonics, max_harmonics
from vibid.signal.ratio import phasor_ratio

__all__ = ["AfcPoint", "AfcTable", "StepRecord", "afc_from_records", "afc_from_session"]

Pair = tuple[float, float]


class StepLike(Protocol):
    """What :func:`afc_from_records` reads of a step (a session step has all of it)."""

    frequency_hz: float
    sample_rate_hz: float
    base: np.ndarray
    response: np.ndarray


@dataclass(frozen=True)
class StepRecord:
    """A step's records in memory: commanded frequency, sample rate, base and response (m/s²)."""

    frequency_hz: float
    sample_rate_hz: float
    base: np.ndarray
    response: np.ndarray
    status: str = "ok"
    index: int | None = None


@dataclass(frozen=True)
class AfcPoint:
    """The AFC at one step and how it was obtained. Pairs are (base, response).

    Phases are those of the channel's fundamental at the record centre, rad (``e^{+iωt}``,
    positive when leading); ``h`` is dimensionless, positive phase when the response leads.
    """

    index: int
    status: str
    commanded_hz: float
    frequency_hz: float  #: refined, on the DAQ clock
    frequency_std_hz: float
    clock_offset_ppm: float
    sample_rate_hz: float
    n_samples: int
    h: complex
    std_re: float
    std_im: float
    cov_re_im: float
    amplitude_m_s2: Pair
    phase_rad: Pair
    offset_m_s2: Pair
    drift_m_s2_per_s: Pair
    noise_std_m_s2: Pair
    snr_db: Pair  #: per sample: (A²/2)/σ²
    estimate_snr_db: Pair  #: fundamental phasor over its standard uncertainty
    thd_db: Pair
    amplitude_change_chi2: Pair  #: first vs second half of the record, 1 dof
    h_change_chi2: float  #: first vs second half of the record, 2 dof
    flat_top_fraction: Pair
    iterations: int
    flags: tuple[Flag, ...]
    used: bool

    @property
    def std(self) -> float:
        """RMS of the standard uncertainties of Re H and Im H."""
        return math.sqrt(0.5 * (self.std_re**2 + self.std_im**2))

    @property
    def flag_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(f.name for f in self.flags))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready diagnostics (NaN and infinities become ``null``)."""
        channels = {
            name: {
                "amplitude_m_s2": self.amplitude_m_s2[c],
                "phase_rad": self.phase_rad[c],
                "offset_m_s2": self.offset_m_s2[c],
                "drift_m_s2_per_s": self.drift_m_s2_per_s[c],
                "noise_std_m_s2": self.noise_std_m_s2[c],
                "snr_db": self.snr_db[c],
                "estimate_snr_db": self.estimate_snr_db[c],
                "thd_db": self.thd_db[c],
                "amplitude_change_chi2": self.amplitude_change_chi2[c],
                "flat_top_fraction": self.flat_top_fraction[c],
            }
            for c, name in enumerate(CHANNELS)
        }
        out = {
            "index": self.index,
            "status": self.status,
            "used": self.used,
            "commanded_hz": self.commanded_hz,
            "frequency_hz": self.frequency_hz,
            "frequency_std_hz": self.frequency_std_hz,
            "clock_offset_ppm": self.clock_offset_ppm,
            "sample_rate_hz": self.sample_rate_hz,
            "n_samples": self.n_samples,
            "re": self.h.real,
            "im": self.h.imag,
            "std": self.std,
            "std_re": self.std_re,
            "std_im": self.std_im,
            "cov_re_im": self.cov_re_im,
            "h_change_chi2": self.h_change_chi2,
            "iterations": self.iterations,
            **channels,
            "flags": [{"name": f.name, "reason": f.reason} for f in self.flags],
        }
        return _json_safe(out)


@dataclass(frozen=True)
class AfcTable:
    """The AFC of a session, one :class:`AfcPoint` per step in step order, with array views."""

    points: tuple[AfcPoint, ...] = field(default_factory=tuple)

    def __len__(self) -> int:
        return len(self.points)

    @cached_property
    def frequency_hz(self) -> np.ndarray:
        """Refined frequency of each step, Hz."""
        return np.array([p.frequency_hz for p in self.points], dtype=float)

    @cached_property
    def commanded_hz(self) -> np.ndarray:
        return np.array([p.commanded_hz for p in self.points], dtype=float)

    @cached_property
    def H(self) -> np.ndarray:  # noqa: N802 - the AFC's usual symbol
        """Complex AFC of each step."""
        return np.array([p.h for p in self.points], dtype=complex)

    @cached_property
    def std(self) -> np.ndarray:
        """Standard uncertainty per real and imaginary part (RMS of the two)."""
        return np.array([p.std for p in self.points], dtype=float)

    @cached_property
    def std_re(self) -> np.ndarray:
        return np.array([p.std_re for p in self.points], dtype=float)

    @cached_property
    def std_im(self) -> np.ndarray:
        return np.array([p.std_im for p in self.points], dtype=float)

    @cached_property
    def used(self) -> np.ndarray:
        """Mask of the steps the identification uses."""
        return np.array([p.used for p in self.points], dtype=bool)

    @cached_property
    def flags(self) -> tuple[tuple[str, ...], ...]:
        """Flag names of each step (empty for a clean step)."""
        return tuple(p.flag_names for p in self.points)

    @cached_property
    def status(self) -> tuple[str, ...]:
        return tuple(p.status for p in self.points)

    def by_frequency(self) -> AfcTable:
        """The points sorted by commanded frequency (a stable sort: equal frequencies keep
        their step order). The identification reads an AFC this way; a session keeps the
        order acquired, which an adaptive campaign does not choose by frequency."""
        order = sorted(range(len(self.points)), key=lambda i: self.points[i].commanded_hz)
        if order == list(range(len(self.points))):
            return self
        return AfcTable(tuple(self.points[i] for i in order))

    def to_report_block(self) -> dict[str, Any]:
        """The report's ``afc`` block: the used steps, plus ``diagnostics`` for every step."""
        used = [p for p in self.points if p.used]
        return {
            "frequency_hz": [p.frequency_hz for p in used],
            "re": [p.h.real for p in used],
            "im": [p.h.imag for p in used],
            "std": [p.std for p in used],
            "diagnostics": [p.to_dict() for p in self.points],
        }


def afc_from_session(session, **options) -> AfcTable:
    """:func:`afc_from_records` over ``session.steps()`` (an open :mod:`vibid.session` reader)."""
    return afc_from_records(session.steps(), **options)


def afc_from_records(
    steps: Iterable[StepLike],
    *,
    thresholds: FlagThresholds = FlagThresholds(),
    n_harmonics: int = 3,
    drift_degree: int = 1,
    ignore_flags: Collection[str] = (),
) -> AfcTable:
    """Fit every step and flag it.

    Parameters
    ----------
    steps : objects with ``frequency_hz``, ``sample_rate_hz``, ``base``, ``response`` (m/s²)
        and optionally ``status`` (default ``ok``) and ``index`` (default: position).
    thresholds : limits of the quality flags.
    n_harmonics : harmonics fitted (fundamental included), fewer where ``k f`` nears fs/2.
    drift_degree : degree of the polynomial offset and drift.
    ignore_flags : flag names that do not exclude a step with status ``ok``.
    """
    points: dict[int, AfcPoint] = {}
    groups: dict[tuple[int, int], list[_Step]] = defaultdict(list)
    for position, raw in enumerate(steps):
        step = _Step.of(raw, position)
        k = (
            int(max_harmonics(step.frequency_hz, step.sample_rate_hz, n_harmonics))
            if step.problem is None
            else 1
        )
        layout = Layout(drift_degree, k)
        if step.problem is None and step.base.size < 2 * layout.n_model + 2:
            step = step.with_problem(f"record of {step.base.size} samples is too short")
        if step.problem is not None:
            points[step.index] = _invalid_point(step)
        else:
            groups[(step.base.size, k)].append(step)
    for (_, k), members in groups.items():
        for point in _fit_group(
            members, Layout(drift_degree, k), thresholds, frozenset(ignore_flags)
        ):
            points[point.index] = point
    return AfcTable(tuple(points[i] for i in sorted(points)))


@dataclass(frozen=True)
class _Step:
    index: int
    frequency_hz: float
    sample_rate_hz: float
    status: str
    base: np.ndarray
    response: np.ndarray
    problem: str | None = None

    @classmethod
    def of(cls, raw, position: int) -> _Step:
        index = getattr(raw, "index", None)
        index = position if index is None else int(index)
        f, fs = float(raw.frequency_hz), float(raw.sample_rate_hz)
        base = np.asarray(raw.base, dtype=np.float64)
        response = np.asarray(raw.response, dtype=np.float64)
        step = cls(index, f, fs, str(getattr(raw, "status", "ok")), base, response)
        problem = None
        if not (np.isfinite(fs) and fs > 0 and np.isfinite(f) and 0 < f < fs / 2):
            problem = f"frequency {f!r} Hz is not within (0, fs/2) for fs = {fs!r} Hz"
        elif base.ndim != 1 or response.ndim != 1 or base.size != response.size:
            problem = (
                f"base {base.shape} and response {response.shape} are not two records of one length"
            )
        elif not (np.all(np.isfinite(base)) and np.all(np.isfinite(response))):
            problem = "records hold non-finite samples"
        return step if problem is None else step.with_problem(problem)

    def with_problem(self, problem: str) -> _Step:
        return _Step(
            self.index,
            self.frequency_hz,
            self.sample_rate_hz,
            self.status,
            self.base,
            self.response,
            problem,
        )


def _fit_group(
    steps: list[_Step], layout: Layout, thr: FlagThresholds, ignore: frozenset
) -> list[AfcPoint]:
    x = np.stack([np.stack([s.base, s.response]) for s in steps])
    n = x.shape[-1]
    f = np.array([s.frequency_hz for s in steps])
    fs = np.array([s.sample_rate_hz for s in steps])
    fit = fit_harmonics(x, f, fs, layout=layout, max_offset_ppm=thr.max_clock_offset_ppm)
    fund = fit.phasors_m_s2[..., 0]
    h, cov_h = phasor_ratio(fund[:, 0], fund[:, 1], fit.fundamental_cov)
    amp = np.abs(fund)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr_db = 10 * np.log10(0.5 * amp**2 / fit.noise_std_m_s2**2)
        est_snr_db = 10 * np.log10(amp**2 / fit.phasor_var[..., 0])
        harmonics = np.abs(fit.phasors_m_s2[..., 1:]) ** 2
        harmonic_chi2 = (harmonics / fit.phasor_var[..., 1:]).sum(-1)
        if layout.n_harmonics > 1:  # E|X̂_k|² = |X_k|² + 2 var_k: remove the noise's share
            power = (harmonics - 2.0 * fit.phasor_var[..., 1:]).sum(-1)
            thd_db = 10 * np.log10(np.maximum(power, 0.0) / amp**2)
        else:
            thd_db = np.full(amp.shape, np.nan)
    ppm = (fit.frequency_hz / f - 1.0) * 1e6
    ppm_std = fit.frequency_std_hz / f * 1e6
    flat = flat_top_fraction(x)
    amp_chi2, h_chi2 = settling_chi2(fit.half_phasors_m_s2, fit.half_cov)
    ringing = _ringing(x, fit, f, fs, layout, thr)
    flags = quality_flags(
        status=[s.status for s in steps],
        flat_top=flat,
        amplitude_change_chi2=amp_chi2,
        h_change_chi2=h_chi2,
        estimate_snr_db=est_snr_db,
        thd_db=thd_db,
        harmonic_chi2=harmonic_chi2,
        harmonic_dof=2 * (layout.n_harmonics - 1),
        clock_offset_ppm=ppm,
        clock_std_ppm=ppm_std,
        cycles=f * n / fs,
        converged=fit.converged,
        thresholds=thr,
        ringing=ringing,
    )
    with np.errstate(invalid="ignore"):
        std_re, std_im = np.sqrt(cov_h[:, 0, 0]), np.sqrt(cov_h[:, 1, 1])
    pair = lambda a, i: (float(a[i, 0]), float(a[i, 1]))  # noqa: E731
    points = []
    for i, s in enumerate(steps):
        used = s.status == "ok" and all(fl.name in ignore for fl in flags[i])
        points.append(
            AfcPoint(
                index=s.index,
                status=s.status,
                commanded_hz=s.frequency_hz,
                frequency_hz=float(fit.frequency_hz[i]),
                frequency_std_hz=float(fit.frequency_std_hz[i]),
                clock_offset_ppm=float(ppm[i]),
                sample_rate_hz=s.sample_rate_hz,
                n_samples=n,
                h=complex(h[i]),
                std_re=float(std_re[i]),
                std_im=float(std_im[i]),
                cov_re_im=float(cov_h[i, 0, 1]),
                amplitude_m_s2=pair(amp, i),
                phase_rad=pair(np.angle(fund), i),
                offset_m_s2=pair(fit.offset_m_s2, i),
                drift_m_s2_per_s=pair(fit.drift_m_s2_per_s, i),
                noise_std_m_s2=pair(fit.noise_std_m_s2, i),
                snr_db=pair(snr_db, i),
                estimate_snr_db=pair(est_snr_db, i),
                thd_db=pair(thd_db, i),
                amplitude_change_chi2=pair(amp_chi2, i),
                h_change_chi2=float(h_chi2[i]),
                flat_top_fraction=pair(flat, i),
                iterations=int(fit.iterations[i]),
                flags=flags[i],
                used=used,
            )
        )
    return points


def _ringing(x, fit, f, fs, layout: Layout, thr: FlagThresholds) -> list:
    """Per step and channel, the free vibration of the record (``ringing``'s evidence). A
    ring has to die out to matter (:meth:`~vibid.signal.flags.FreeVibration.unsettled`): it
    is looked for (:func:`~vibid.signal.flags.free_vibration`) only where the fit's residual
    decays from the first half of the record to the second beyond ``unsettled_sigma``."""
    h = x.shape[-1] // 2
    halves = fit.residual_ss_halves
    z = decay_z(halves[..., 0], h, halves[..., 1], h)
    out = []
    for i in range(x.shape[0]):
        f_i = float(fit.frequency_hz[i]) if np.isfinite(fit.frequency_hz[i]) else f[i]
        out.append(
            [
                free_vibration(
                    x[i, c], f_i, fs[i], degree=layout.degree, n_harmonics=layout.n_harmonics
                )
                if z[i, c] > thr.unsettled_sigma
                else FreeVibration(math.nan, float(z[i, c]), 0.0)
                for c in range(x.shape[1])
            ]
        )
    return out


def _invalid_point(step: _Step) -> AfcPoint:
    nan2 = (math.nan, math.nan)
    flags = [Flag("invalid", step.problem or "cannot be fitted")]
    if step.status in ("overload", "aborted"):
        flags.insert(0, Flag(step.status, f"step status is {step.status!r}"))
    return AfcPoint(
        index=step.index,
        status=step.status,
        commanded_hz=step.frequency_hz,
        frequency_hz=math.nan,
        frequency_std_hz=math.nan,
        clock_offset_ppm=math.nan,
        sample_rate_hz=step.sample_rate_hz,
        n_samples=int(step.base.size) if step.base.ndim == 1 else 0,
        h=complex(math.nan, math.nan),
        std_re=math.nan,
        std_im=math.nan,
        cov_re_im=math.nan,
        amplitude_m_s2=nan2,
        phase_rad=nan2,
        offset_m_s2=nan2,
        drift_m_s2_per_s=nan2,
        noise_std_m_s2=nan2,
        snr_db=nan2,
        estimate_snr_db=nan2,
        thd_db=nan2,
        amplitude_change_chi2=nan2,
        h_change_chi2=math.nan,
        flat_top_fraction=nan2,
        iterations=0,
        flags=tuple(flags),
        used=False,
    )


def _json_safe(value):
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
