"""Independent reference for tests: the exact beam of tests/beam_reference.py whose first
mode slips at large motion (a modal Jenkins joint: the single-nonlinear-mode idea of
Segalman's modal Iwan model, in which a bolted or clamped joint acts on each mode's own
coordinate), under a stepped sine of constant base acceleration.

numpy only; never import ``vibid`` here. Near its first resonance the beam's AFC is its
mode's term ``c ω² z(ω)`` on a smooth background, ``z = 1 / (ω₁² (1 + iβ) - ω²)`` the
mode's coordinate per unit base acceleration and ``c = iβ H(ω₁)`` its participation (to
O(β)). Here the mode's stiffness holds a Jenkins joint (a spring of ``kappa`` times the
mode's own in series with a Coulomb slider that slips once the spring stretches by
``slip``): stuck, the mode is the beam's exactly; at amplitude ``a > slip`` the joint is
Iwan's describing function ``k_j (φ - sin 2φ / 2) / π + 4 i k_j slip (a - slip) / (π a²)``
(``cos φ = 1 - 2 slip / a``), the amplitude solved by fixed-point iteration along the sweep
(first harmonic balance, as tests/test_linearity.py's oscillator). The AFC is the exact
beam's plus ``c ω² (z_joint - z)``: where the joint sticks (the flanks) it is the exact
linear beam's to rounding, at the top the mode softens and loses energy.
"""

from __future__ import annotations

import numpy as np

import beam_reference as beam


def afc(omega, *, kappa, slip, f1_hz, **beam_kw):
    """H(omega) of the beam (``beam_kw``: tests/beam_reference.py's ``afc`` arguments, EI
    complex with the loss factor) whose first mode, at ``f1_hz`` (its natural frequency,
    Hz), slips (module doc); ``slip`` as a fraction of the stuck mode's peak amplitude."""
    omega = np.asarray(omega, float)
    H = beam.afc(omega, **beam_kw)
    EI = complex(beam_kw["EI"])
    loss = EI.imag / EI.real
    w1 = 2 * np.pi * f1_hz
    c = 1j * loss * beam.afc(np.array([w1]), **beam_kw)[0]
    w0_sq = w1**2 / (1 + kappa)  # the mode without the joint's spring
    kj = kappa * w0_sq
    slip_amp = slip / (loss * w1**2)  # the stuck mode's peak |z| is 1 / (β ω₁²)

    z = stepped_sine(omega, lambda w: w0_sq + 1j * loss * w1**2 - w * w, kj, slip_amp)
    z_lin = 1 / (w1**2 * (1 + 1j * loss) - omega**2)
    return H + c * omega**2 * (z - z_lin)


def jenkins(a, k_j, slip):
    """Iwan's describing function of a Jenkins joint (a spring ``k_j`` in series with a
    Coulomb slider that slips once the spring stretches by ``slip``) at amplitude ``a``."""
    if a <= slip:
        return k_j + 0j
    phi = np.arccos(1 - 2 * slip / a)
    return k_j * (phi - 0.5 * np.sin(2 * phi)) / np.pi + 4j * k_j * slip * (a - slip) / (
        np.pi * a * a
    )


def stepped_sine(omega, linear, k_j, slip):
    """The coordinate ``z`` at each of ``omega`` (a sweep upwards) of a mode whose stiffness
    holds a Jenkins joint: ``z = 1 / (linear(ω) + jenkins(|z|))``, ``linear(ω)`` the rest
    of its dynamic stiffness, the amplitude the fixed point reached from the previous
    step's (first harmonic balance)."""
    z, a = np.empty(np.size(omega), complex), 0.0
    for i, w in enumerate(omega):
        for _ in range(2000):
            z[i] = 1 / (linear(w) + jenkins(a, k_j, slip))
            if abs(abs(z[i]) - a) <= 1e-12 * abs(z[i]):
                break
            a = 0.5 * (a + abs(z[i]))
    return z
