"""Huang's (1961) closed-form frequency equation of a clamped-free Rayleigh (rotary inertia)
or Timoshenko beam with nu = 0 (EI = E h³ b / 12, G = E / 2): an independent reference for
tests; numpy/scipy only, nothing of vibid's."""

import numpy as np
from scipy.optimize import brentq


def frequencies_hz(n, *, L, B, H, rho, E, kappa, shear: bool):
    """The first ``n`` natural frequencies (Hz) of the beam (SI units)."""
    EI, A = E * H**3 * B / 12, B * H
    r2 = H**2 / 12 / L**2
    s2 = EI / (kappa * E / 2 * A * L**2) if shear else 0.0

    def g(b):
        root = np.sqrt((r2 - s2) ** 2 + 4 / b**2)
        a, c = np.sqrt((-(r2 + s2) + root) / 2), np.sqrt(((r2 + s2) + root) / 2)
        return (
            2 / np.cosh(b * a)
            + (b**2 * (r2 - s2) ** 2 + 2) * np.cos(b * c)
            - b * (r2 + s2) / np.sqrt(1 - b**2 * r2 * s2) * np.tanh(b * a) * np.sin(b * c)
        )

    grid = np.linspace(0.5, 60.0, 6000)
    vals = g(grid)
    roots = [
        brentq(g, grid[i], grid[i + 1], xtol=1e-14)
        for i in range(len(grid) - 1)
        if vals[i] * vals[i + 1] < 0
    ][:n]
    return np.sqrt(np.array(roots) ** 2 * EI / (rho * A * L**4)) / (2 * np.pi)
