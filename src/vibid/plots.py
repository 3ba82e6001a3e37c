"""Figures for people: the measured AFC beside the identified model's."""

from __future__ import annotations

import os

import numpy as np


def plot_afc_fit(path: str | os.PathLike, frequency_hz, H, std, model_afc, *, title: str = "") -> str:
    """Write a PNG of |H| and phase, measured (with ±2 std) and modelled; return its path."""
    from matplotlib.figure import Figure  # no pyplot: the process's backend is left alone

    f = np.asarray(frequency_hz, float)
    H = np.asarray(H, complex)
    Hm = np.asarray(model_afc, complex)
    s = np.asarray(std, float) if std is not None else np.zeros_like(f)
    fig = Figure(figsize=(9, 6.5))
    ax_mag, ax_ph = fig.subplots(2, 1, sharex=True)
    ax_mag.semilogy(f, np.abs(Hm), "-", color="C1", lw=1.2, label="model")
    ax_mag.errorbar(f, np.abs(H), yerr=2 * s, fmt=".", ms=3, color="C0", elinewidth=0.8,
                    label="measured (±2 std)")
    ax_mag.set_ylabel("|H|")
    ax_mag.legend(loc="upper right")
    ax_mag.grid(True, which="both", alpha=0.3)
    ax_ph.plot(f, np.degrees(np.angle(Hm)), "-", color="C1", lw=1.2)
    ax_ph.plot(f, np.degrees(np.angle(H)), ".", ms=3, color="C0")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_xlabel("frequency (Hz)")
    ax_ph.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return os.fspath(path)
