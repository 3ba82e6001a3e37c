"""Synthetic accelerometer records of one stepped-sine step, with known truth.

:func:`synthetic_step` returns what the two DAQ inputs would hold at one frequency step:
the table's (``base``) and the specimen's (``response``) acceleration in m/s², sampled on the
DAQ clock ``t_n = n / sample_rate_hz``. It is pure: the same arguments and seed give the same
arrays.

Model (phasors ``e^{+iωt}``, phase positive when the response leads)::

    base(t)     = A cos(ω t + φ)              + nuisance_b(t)
    response(t) = |H| A cos(ω t + φ + arg H)  + nuisance_r(t) [+ transient(t)]

with ``ω = 2π f (1 + clock_offset_ppm·1e-6)``: the generator's clock differs from the DAQ's,
so the frequency in the record is not exactly the commanded one. Each channel's nuisance is
``dc + drift·t + Σ_k A_k cos(k ω t + ψ_k) + noise``, where the 2nd, 3rd, ... harmonic
amplitudes are ``harmonics_db`` relative to that channel's own fundamental and the phases
``ψ_k`` are drawn from ``rng`` (uniform). Noise is white Gaussian. Clipping, last, limits each
channel to ``±clip`` as an overloaded ADC input would.

Notes (where this differs from a real stand): the drift is a straight line, the noise is
white and the two channels' noise independent, samples are not quantised, the transient is
one decaying sinusoid on the response channel only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Transient", "synthetic_step", "true_frequency_hz"]

Pair = tuple[float, float]


@dataclass(frozen=True)
class Transient:
    """A left-over free vibration on the response channel (the settle was too short).

    Adds ``amplitude_m_s2 · exp(-t / decay_s) · cos(2π frequency_hz t + phase_rad)``, ``t`` from
    the first sample. ``frequency_hz=None`` uses the step's true frequency (an envelope that
    has not yet reached its steady value); a specimen's natural frequency gives a beat.
    """

    amplitude_m_s2: float
    decay_s: float
    frequency_hz: float | None = None
    phase_rad: float = 0.0


def true_frequency_hz(frequency_hz: float, clock_offset_ppm: float = 0.0) -> float:
    """The frequency the record holds, on the DAQ clock, for a commanded ``frequency_hz``."""
    return float(frequency_hz) * (1.0 + 1e-6 * float(clock_offset_ppm))


def synthetic_step(
    frequency_hz: float,
    h: complex,
    *,
    sample_rate_hz: float,
    n_samples: int,
    base_amplitude_m_s2: float = 1.0,
    base_phase_rad: float = 0.0,
    clock_offset_ppm: float = 0.0,
    dc_m_s2: Pair = (0.0, 0.0),
    drift_m_s2_per_s: Pair = (0.0, 0.0),
    harmonics_db: Sequence[float] = (),
    noise_std_m_s2: Pair = (0.0, 0.0),
    transient: Transient | None = None,
    clip_m_s2: float | tuple[float | None, float | None] | None = None,
    dtype: type = np.float64,
    rng: np.random.Generator | int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Records of both accelerometers at one step.

    Parameters
    ----------
    frequency_hz : commanded frequency, Hz.
    h : the true AFC at this step, response phasor / base phasor (complex, dimensionless).
    sample_rate_hz : DAQ sample clock, Hz.
    n_samples : record length (any integer ≥ 1; need not hold whole cycles).
    base_amplitude_m_s2 : amplitude of the table's acceleration, m/s².
    base_phase_rad : phase of the base at the first sample, rad.
    clock_offset_ppm : relative frequency error of the generator against the DAQ, ppm.
    dc_m_s2 : (base, response) offsets, m/s².
    drift_m_s2_per_s : (base, response) linear drift rates, m/s² per second.
    harmonics_db : levels of the 2nd, 3rd, ... harmonics relative to each channel's
        fundamental, dB (e.g. ``(-40, -40)``).
    noise_std_m_s2 : (base, response) white-noise standard deviations, m/s².
    transient : optional :class:`Transient` on the response channel.
    clip_m_s2 : clipping level, m/s²: one value for both channels, or (base, response)
        with ``None`` for an unclipped channel.
    dtype : float type of the returned arrays (``np.float32`` as a DAQ may store).
    rng : numpy Generator or integer seed of the noise and harmonic phases.

    Returns
    -------
    (base, response) : two 1-D arrays of ``n_samples`` values, m/s².
    """
    if n_samples < 1:
        raise ValueError(f"n_samples must be at least 1, got {n_samples}")
    if not (sample_rate_hz > 0 and frequency_hz > 0):
        raise ValueError("frequency_hz and sample_rate_hz must be positive")
    rng = np.random.default_rng(rng)
    t_s = np.arange(n_samples, dtype=np.float64) / sample_rate_hz
    omega = 2.0 * np.pi * true_frequency_hz(frequency_hz, clock_offset_ppm)
    h = complex(h)
    amplitudes = (base_amplitude_m_s2, abs(h) * base_amplitude_m_s2)
    phases = (base_phase_rad, base_phase_rad + np.angle(h))
    levels = 10.0 ** (np.asarray(harmonics_db, dtype=np.float64) / 20.0)
    harmonic_phases = rng.uniform(0.0, 2.0 * np.pi, size=(2, levels.size))
    channels = []
    for c in range(2):
        x = amplitudes[c] * np.cos(omega * t_s + phases[c])
        for j, level in enumerate(levels):
            k = j + 2
            x += level * amplitudes[c] * np.cos(k * omega * t_s + harmonic_phases[c, j])
        x += dc_m_s2[c] + drift_m_s2_per_s[c] * t_s
        if noise_std_m_s2[c] > 0:
            x += rng.normal(0.0, noise_std_m_s2[c], size=n_samples)
        channels.append(x)
    if transient is not None:
        f_t = transient.frequency_hz
        omega_t = omega if f_t is None else 2.0 * np.pi * f_t
        channels[1] += (
            transient.amplitude_m_s2
            * np.exp(-t_s / transient.decay_s)
            * np.cos(omega_t * t_s + transient.phase_rad)
        )
    clips = clip_m_s2 if isinstance(clip_m_s2, tuple) else (clip_m_s2, clip_m_s2)
    for c, level in enumerate(clips):
        if level is not None:
            np.clip(channels[c], -level, level, out=channels[c])
    return channels[0].astype(dtype), channels[1].astype(dtype)
