"""Quality flags of a step: why its AFC point should not be trusted.

Every check is a pure function of the records or of the harmonic fit, vectorised over steps,
and yields a boolean per step plus a one-line reason. The names are stable identifiers (they
end up in reports):

========== ==================================================================================
name        fires when
========== ==================================================================================
overload    the step's status is ``overload``, or a channel has flat tops: more than
            ``flat_top_fraction`` of its samples sit at its maximum (or minimum), as when an
            input clips
aborted     the step's status is ``aborted``
unsettled   fitted on the first and on the second half of the record (frequency held at the
            whole record's), a channel's fundamental amplitude, or H itself, differs beyond
            noise: χ² above the two-sided ``unsettled_sigma`` Gaussian tail (5σ: χ² > 25 for
            an amplitude, 1 dof; > 28.7 for H, 2 dof). H, not each channel's phase, is tested
            for phase: the refined frequency absorbs any common phase slope, but cancels in H
low_snr     a channel's fundamental stands less than ``min_snr_db`` above its own standard
            uncertainty; below ~20 dB the linearised uncertainty of the ratio and the
            frequency search stop being reliable
distortion  a channel's total harmonic distortion (2nd and 3rd, noise power removed) exceeds
            ``max_thd_db`` and its harmonics stand out of the noise (χ² of the harmonic
            phasors above the ``unsettled_sigma`` tail), so that a noisy channel does not
            fire it by chance
clock       the refined frequency is further than ``max_clock_offset_ppm`` (+5σ) from the
            commanded one: the generator and DAQ clocks disagree beyond their tolerance, or
            the fit locked on something else
ringing     a channel holds a free vibration off the drive frequency that dies out
            (its residual's first half stronger than its second beyond ``unsettled_sigma``)
            and moves the fundamental phasor by more than ``ringing_leak_std`` of its
            standard deviations (:func:`free_vibration`): a nearby mode still ringing
few_cycles  the record holds fewer than ``min_cycles`` periods; drift and fundamental blur
fit         the frequency search did not converge (the step is fitted at the commanded
            frequency instead)
invalid     the record cannot be fitted (non-finite samples, too short, unequal lengths)
========== ==================================================================================

A blind spot of ``unsettled``, and the check that covers it (``ringing``: :func:`free_vibration`;
the campaign runner records such a step again, as an unsettled one): a mode a few hertz off the drive
frequency, still ringing after the last change, adds to each half's residual as much as it
moves the halves' phasors, so the halves agree within the noise the ring itself raises; yet
its leakage biases the phasor by many of the (inflated) standard deviations: about
``√N / (π Δ)`` of them for a ring ``Δ`` bins away that dominates the residual of ``N``
samples. On the virtual strip at the default noise, 487.5 Hz recorded after the damping
settle carried the 496.5 Hz mode's ring 9 std into H, unflagged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibid.signal.ratio import phasor_ratio

__all__ = [
    "FLAG_NAMES",
    "FREE_VIBRATION_LEAK_STD",
    "Flag",
    "FlagThresholds",
    "FreeVibration",
    "flat_top_fraction",
    "decay_z",
    "free_vibration",
    "quality_flags",
    "settling_chi2",
    "unsettled_chi2_limit",
]

FLAG_NAMES = (
    "overload",
    "aborted",
    "unsettled",
    "ringing",
    "low_snr",
    "distortion",
    "clock",
    "few_cycles",
    "fit",
    "invalid",
)
CHANNELS = ("base", "response")


@dataclass(frozen=True)
class Flag:
    """One reason to leave a step out: ``name`` from :data:`FLAG_NAMES`, ``reason`` one line."""

    name: str
    reason: str


@dataclass(frozen=True)
class FlagThresholds:
    """Limits of the quality checks (see the module table)."""

    flat_top_fraction: float = 0.005
    unsettled_sigma: float = 5.0
    min_snr_db: float = 20.0
    max_thd_db: float = -20.0
    max_clock_offset_ppm: float = 200.0
    min_cycles: float = 2.0
    ringing_leak_std: float = 3.0


def unsettled_chi2_limit(sigma: float, dof: int = 2) -> float:
    """χ² with ``dof`` degrees of freedom and the tail probability of a two-sided ``sigma``
    Gaussian deviation (``sigma²`` for 1 dof, ``-2 ln p`` for 2)."""
    if dof == 1:
        return sigma**2
    if dof == 2:
        return -2.0 * math.log(math.erfc(sigma / math.sqrt(2.0)))
    from scipy.special import gammainccinv  # χ²_dof survival: Q(dof/2, x/2)

    return float(2.0 * gammainccinv(dof / 2.0, math.erfc(sigma / math.sqrt(2.0))))


def settling_chi2(half_phasors: np.ndarray, half_cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Change between the record halves: amplitude χ² per channel (1 dof) and χ² of H (2 dof).

    ``half_phasors`` (S, 2, 2): channel × (first, second half); ``half_cov`` (S, 2, 4, 4):
    per half, the covariance of (Re X_b, Im X_b, Re X_r, Im X_r). The halves are independent.
    """
    x = half_phasors
    amp = np.abs(x)
    radial = np.stack([np.cos(np.angle(x)), np.sin(np.angle(x))], -1)  # (S, C, 2 halves, 2)
    var = np.zeros(amp.shape)
    for c in range(x.shape[1]):
        blk = half_cov[:, :, 2 * c : 2 * c + 2, 2 * c : 2 * c + 2]  # (S, halves, 2, 2)
        var[:, c] = np.einsum("shi,shij,shj->sh", radial[:, c], blk, radial[:, c])
    with np.errstate(divide="ignore", invalid="ignore"):
        amp_chi2 = (amp[..., 1] - amp[..., 0]) ** 2 / var.sum(-1)
    hs, covs = zip(*(phasor_ratio(x[:, 0, k], x[:, 1, k], half_cov[:, k]) for k in range(2)))
    d = hs[1] - hs[0]
    d = np.stack([d.real, d.imag], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        h_chi2 = np.einsum("si,sij,sj->s", d, np.linalg.inv(covs[0] + covs[1]), d)
    return amp_chi2, h_chi2


#: a free vibration that moves a channel's fundamental phasor by more than this many of its
#: standard deviations makes the record unsettled (:meth:`FreeVibration.unsettled`; the
#: ``ringing`` flag's ``FlagThresholds.ringing_leak_std``)
FREE_VIBRATION_LEAK_STD = 3.0


@dataclass(frozen=True)
class FreeVibration:
    """The strongest decaying tone in a channel's residual, off the step's harmonics.

    ``frequency_hz`` where it rings; ``decay_z`` how much more residual power the record's
    first half holds than its second (``ln`` of the variance ratio over its standard
    deviation under white noise: a z-score); ``leak_std`` how far modelling it moves the
    channel's fundamental phasor, in that phasor's standard deviations.
    """

    frequency_hz: float
    decay_z: float
    leak_std: float

    def unsettled(
        self,
        sigma: float = FlagThresholds.unsettled_sigma,
        leak_std: float = FREE_VIBRATION_LEAK_STD,
    ) -> bool:
        """A free vibration that dies out (``decay_z`` beyond ``sigma``) and biases the
        phasor beyond ``leak_std``: waiting removes it. A steady tone (mains hum) does not
        decay, and waiting would not remove it."""
        return bool(self.decay_z > sigma and self.leak_std > leak_std)


def decay_z(ss_first, n_first: int, ss_second, n_second: int):
    """How much more residual power a record's first half holds than its second, as a
    z-score under white noise: ``ln(v₁/v₂) / sqrt(2/n₁ + 2/n₂)``, ``v`` the mean square
    of each half's residual (``ss`` its sum of squares over ``n`` samples); NaN where a
    half has none. Arrays broadcast."""
    with np.errstate(divide="ignore", invalid="ignore"):
        v1 = np.asarray(ss_first, float) / n_first
        v2 = np.asarray(ss_second, float) / n_second
        z = np.log(v1 / v2) / math.sqrt(2.0 / n_first + 2.0 / n_second)
    return np.where((v1 > 0) & (v2 > 0), z, np.nan)


def free_vibration(
    x,
    frequency_hz: float,
    sample_rate_hz: float,
    *,
    degree: int = 1,
    n_harmonics: int = 3,
    zero_pad: int = 4,
) -> FreeVibration:
    """Look for a free vibration off the drive frequency in one channel's record ``x``.

    The record is fitted as the signal stage does (a polynomial of ``degree``, the harmonics
    1..``n_harmonics`` of ``frequency_hz`` below 0.49 fs, least squares); the strongest line
    of the residual's periodogram (zero-padded ``zero_pad`` times) farther than one bin
    (``1/T``) from DC and from every fitted harmonic is taken as the ring. Refitting with
    that ring as extra columns (cosine and sine times 1, u, u², u the centred time over half
    the record: a decaying envelope) moves the fundamental phasor by ``dX``; ``leak_std`` is
    ``|dX|`` over the phasor's standard deviation per part (residual variance times the
    fit's inverse Gram). A ring within a bin of a harmonic is the ``unsettled`` flag's case
    (its envelope changes between the halves) and is not looked for here.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    nothing = FreeVibration(math.nan, 0.0, 0.0)
    if n < 64 or not (frequency_hz > 0 and sample_rate_hz > 0) or not np.all(np.isfinite(x)):
        return nothing
    t = (np.arange(n) - 0.5 * (n - 1)) / sample_rate_hz
    u = t * (2.0 * sample_rate_hz / n)
    orders = [k for k in range(1, n_harmonics + 1) if k * frequency_hz < 0.49 * sample_rate_hz]
    z = np.exp(2j * np.pi * frequency_hz * t)
    cols, zk = [u**j for j in range(degree + 1)], z
    for _ in orders:
        cols += [zk.real, zk.imag]
        zk = zk * z
    a = np.stack(cols, axis=1)  # well conditioned (u within ±1, unit sinusoids): normal equations
    try:
        gram_inv = np.linalg.inv(a.T @ a)
    except np.linalg.LinAlgError:
        return nothing
    plain = gram_inv @ (a.T @ x)
    resid = x - a @ plain
    half = n // 2
    z = decay_z(
        float(resid[:half] @ resid[:half]), half, float(resid[half:] @ resid[half:]), n - half
    )
    if not math.isfinite(z):
        return nothing
    # the strongest residual line away from DC and the harmonics
    m = zero_pad * n
    spectrum = np.abs(np.fft.rfft(resid, m))
    lines = np.arange(spectrum.size) * (sample_rate_hz / m)
    bin_hz = sample_rate_hz / n
    away = lines >= bin_hz
    for k in orders:
        away &= np.abs(lines - k * frequency_hz) >= bin_hz
    if not away.any():
        return nothing
    k = int(np.flatnonzero(away)[np.argmax(spectrum[away])])
    shift = 0.0
    if 0 < k < spectrum.size - 1:  # the peak between the lines: a parabola through log |X|
        lo, mid, hi = np.log(spectrum[k - 1 : k + 2] + 1e-300)
        curve = lo - 2.0 * mid + hi
        shift = float(np.clip(0.5 * (lo - hi) / curve, -0.5, 0.5)) if curve < 0 else 0.0
    ring_hz = float((k + shift) * sample_rate_hz / m)
    w = np.exp(2j * np.pi * ring_hz * t)
    ring = np.stack([c for j in range(3) for c in ((w * u**j).real, (w * u**j).imag)], axis=1)
    wider = np.concatenate([a, ring], axis=1)
    try:
        ringing = np.linalg.solve(wider.T @ wider, wider.T @ x)
    except np.linalg.LinAlgError:
        return nothing
    fund = slice(degree + 1, degree + 3)  # cos, sin of the fundamental
    dx = ringing[fund] - plain[fund]
    sigma2 = float(resid @ resid) / (n - a.shape[1])
    var = sigma2 * np.diag(gram_inv)[fund]  # the phasor's variance per part: σ² (AᵀA)⁻¹
    leak = float(math.hypot(*dx) / math.sqrt(0.5 * float(var.sum())))
    return FreeVibration(ring_hz, float(z), leak)


def flat_top_fraction(x: np.ndarray, rel_tol: float = 1e-6) -> np.ndarray:
    """Fraction of samples at the channel's extreme value: the larger of top and bottom.

    ``x`` (..., N). A sample counts when within ``rel_tol`` of the peak-to-peak range of the
    maximum (or minimum). A clean sine has ~``√(2 rel_tol)/π`` (0.05 %) there; a clipped one
    has every clipped sample. Coarsely quantised records (a few bits over the signal) have
    wide flat tops too: a known limit of the check.
    """
    hi, lo = x.max(-1, keepdims=True), x.min(-1, keepdims=True)
    tol = rel_tol * (hi - lo)
    top = np.count_nonzero(x >= hi - tol, axis=-1)
    bottom = np.count_nonzero(x <= lo + tol, axis=-1)
    return np.maximum(top, bottom) / x.shape[-1]


def quality_flags(
    *,
    status: list[str],
    flat_top: np.ndarray,
    amplitude_change_chi2: np.ndarray,
    h_change_chi2: np.ndarray,
    estimate_snr_db: np.ndarray,
    thd_db: np.ndarray,
    harmonic_chi2: np.ndarray,
    harmonic_dof: int,
    clock_offset_ppm: np.ndarray,
    clock_std_ppm: np.ndarray,
    cycles: np.ndarray,
    converged: np.ndarray,
    thresholds: FlagThresholds = FlagThresholds(),
    ringing: list | None = None,
) -> list[tuple[Flag, ...]]:
    """The flags of ``S`` steps from their diagnostics; per-channel arrays are (S, 2);
    ``ringing[i][c]`` the :class:`FreeVibration` of step ``i``'s channel ``c`` (None: not
    looked for).

    ``estimate_snr_db`` is ``10 log10(|X|² / var)`` of each channel's fundamental phasor,
    ``var`` its variance per real component; ``harmonic_chi2`` is ``Σ_k |X_k|² / var_k`` over
    the harmonics (``harmonic_dof = 2 (K - 1)`` degrees of freedom under noise alone).
    Each step's flags come in this order: its status, flat tops, settling, SNR,
    distortion, clock, ringing, record length, convergence.
    """
    thr = thresholds
    amp_limit = unsettled_chi2_limit(thr.unsettled_sigma, 1)
    h_limit = unsettled_chi2_limit(thr.unsettled_sigma, 2)
    harmonic_limit = (
        unsettled_chi2_limit(thr.unsettled_sigma, harmonic_dof) if harmonic_dof else math.inf
    )
    out = []
    for i, st in enumerate(status):
        flags = [
            *_status_flags(st),
            *_flat_top_flags(flat_top[i], st, thr),
            *_unsettled_flags(amplitude_change_chi2[i], h_change_chi2[i], amp_limit, h_limit, thr),
            *_snr_flags(estimate_snr_db[i], thr),
            *_distortion_flags(thd_db[i], harmonic_chi2[i], harmonic_limit, thr),
            *_clock_flags(clock_offset_ppm[i], clock_std_ppm[i], thr),
            *_ringing_flags(None if ringing is None else ringing[i], thr),
            *_record_flags(cycles[i], converged[i], thr),
        ]
        out.append(tuple(flags))
    return out


def _status_flags(st: str) -> list[Flag]:
    """``overload``, ``aborted`` or ``invalid`` from the step's status (none for ``ok``)."""
    if st == "overload":
        return [Flag("overload", "step status is 'overload' (an input clipped)")]
    if st == "aborted":
        return [Flag("aborted", "step status is 'aborted'")]
    if st != "ok":
        return [Flag("invalid", f"unknown step status {st!r}")]
    return []


def _flat_top_flags(flat_top, st: str, thr: FlagThresholds) -> list[Flag]:
    """``overload`` per channel with flat tops (``flat_top`` (2,)), unless the status says it."""
    return [
        Flag(
            "overload",
            f"{name} has flat tops: {100 * flat_top[c]:.1f} % of samples at "
            f"its extreme (limit {100 * thr.flat_top_fraction:.1f} %), clipping",
        )
        for c, name in enumerate(CHANNELS)
        if flat_top[c] > thr.flat_top_fraction and st != "overload"
    ]


def _unsettled_flags(
    amplitude_chi2, h_chi2, amp_limit: float, h_limit: float, thr: FlagThresholds
) -> list[Flag]:
    """``unsettled`` per channel whose amplitude changes between the record halves
    (``amplitude_chi2`` (2,)), then for H (``h_chi2`` a scalar)."""
    flags = [
        Flag(
            "unsettled",
            f"{name} amplitude changes between the record halves: "
            f"chi2 {amplitude_chi2[c]:.1f} > {amp_limit:.1f} "
            f"(1 dof, {thr.unsettled_sigma:g} sigma)",
        )
        for c, name in enumerate(CHANNELS)
        if amplitude_chi2[c] > amp_limit
    ]
    if h_chi2 > h_limit:
        flags.append(
            Flag(
                "unsettled",
                f"H changes between the record halves: chi2 {h_chi2:.1f} "
                f"> {h_limit:.1f} (2 dof, {thr.unsettled_sigma:g} sigma)",
            )
        )
    return flags


def _snr_flags(snr_db, thr: FlagThresholds) -> list[Flag]:
    """``low_snr`` per channel (``snr_db`` (2,); NaN fires it)."""
    return [
        Flag(
            "low_snr",
            f"{name} fundamental is {snr_db[c]:.1f} dB above its "
            f"uncertainty (minimum {thr.min_snr_db:g} dB)",
        )
        for c, name in enumerate(CHANNELS)
        if not snr_db[c] >= thr.min_snr_db
    ]


def _distortion_flags(thd_db, harmonic_chi2, limit: float, thr: FlagThresholds) -> list[Flag]:
    """``distortion`` per channel whose harmonics are strong and out of the noise."""
    return [
        Flag(
            "distortion",
            f"{name} harmonic distortion {thd_db[c]:.1f} dB (limit {thr.max_thd_db:g} dB)",
        )
        for c, name in enumerate(CHANNELS)
        if thd_db[c] > thr.max_thd_db and harmonic_chi2[c] > limit
    ]


def _clock_flags(off, std, thr: FlagThresholds) -> list[Flag]:
    """``clock`` when the refined frequency is off the commanded beyond tolerance + 5σ."""
    if abs(off) - 5.0 * std > thr.max_clock_offset_ppm:
        return [
            Flag(
                "clock",
                f"frequency in the record is {off:+.0f} ppm from the commanded "
                f"(tolerance {thr.max_clock_offset_ppm:g} ppm)",
            )
        ]
    return []


def _ringing_flags(rings, thr: FlagThresholds) -> list[Flag]:
    """``ringing`` per channel whose :class:`FreeVibration` (``rings[c]``, None: not looked
    for; ``rings`` None: none looked for) dies out and moves the phasor."""
    flags = []
    for c, name in enumerate(CHANNELS):
        ring = None if rings is None else rings[c]
        if ring is not None and ring.unsettled(thr.unsettled_sigma, thr.ringing_leak_std):
            flags.append(
                Flag(
                    "ringing",
                    f"{name} rings at {ring.frequency_hz:.1f} Hz, dying out "
                    f"(decay z {ring.decay_z:.1f}), moving the phasor "
                    f"{ring.leak_std:.1f} std",
                )
            )
    return flags


def _record_flags(cycles, converged, thr: FlagThresholds) -> list[Flag]:
    """``few_cycles`` for a record too short, then ``fit`` where the search did not converge."""
    flags = []
    if cycles < thr.min_cycles:
        flags.append(
            Flag("few_cycles", f"record holds {cycles:.2f} cycles (minimum {thr.min_cycles:g})")
        )
    if not converged:
        flags.append(
            Flag("fit", "frequency search did not converge; fitted at the commanded frequency")
        )
    return flags
