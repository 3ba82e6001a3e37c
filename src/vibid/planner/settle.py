"""How long each planned step settles: until the free vibration left by the change of
frequency is below a third of the step's noise.

After the drive changes from ``f_prev`` to ``f``, mode ``n`` (natural frequency ``f_n``, loss
``β``, resonance peak ``|H(f_n)|``) rings freely with the jump of its steady response, the
one-mode resonance ``g_n(f) = |H(f_n)| iβ f² / (f_n² − f² + iβ f_n²)`` (base excitation loads
a mode in proportion to ``f²``), and decays as ``exp(−t/τ_n)``, ``τ_n = 1 / (π f_n β)``
(``Q = 1/β``). The phasor fit at ``f`` over a record of ``T`` seconds passes a vibration at
``f_n`` attenuated by about ``L_n = min(1, 1 / (π |f − f_n| T))`` (the envelope of its
Dirichlet kernel), so the step waits ``max_n τ_n ln(L_n |g_n(f) − g_n(f_prev)| / (s / 3))``
(zero when that is already below one), ``s`` its noise per part (:mod:`.information`); the
first step starts from rest. Per draw of the prior; the plan takes a high quantile over draws,
floored and capped by the stand's timing.
"""

from __future__ import annotations

import numpy as np

#: the transient left at the first sample, as a fraction of the step's noise std
LEFT_OVER = 1.0 / 3.0


def one_mode(f_hz, f_n, peak, beta):
    """``g_n(f)`` for every mode: (..., n_modes) complex, broadcasting ``f_hz`` (...)."""
    f = np.asarray(f_hz, float)[..., None]
    return peak * 1j * beta * f**2 / (f_n**2 - f**2 + 1j * beta * f_n**2)


def settle_s(f_hz, f_prev_hz, noise, record_s, f_n, peak, beta):
    """Settle time of a step at ``f_hz`` after ``f_prev_hz`` (None: from rest) recorded
    ``record_s`` for one draw (``f_n``, ``peak`` (n_modes,), scalar ``beta``) and noise per
    part ``noise``, s."""
    jump = one_mode(f_hz, f_n, peak, beta)
    if f_prev_hz is not None:
        jump = jump - one_mode(f_prev_hz, f_n, peak, beta)
    tau = 1.0 / (np.pi * f_n * beta)
    detuning = (
        np.pi
        * np.abs(np.asarray(f_hz, float)[..., None] - f_n)
        * np.asarray(record_s, float)[..., None]
    )
    passed = np.minimum(1.0, 1.0 / np.maximum(detuning, 1e-300))
    ratio = passed * np.abs(jump) / (LEFT_OVER * np.asarray(noise, float)[..., None])
    return np.max(tau * np.log(np.maximum(ratio, 1.0)), axis=-1)
