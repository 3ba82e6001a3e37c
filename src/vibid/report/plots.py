"""Drawing from plain arrays: the measured AFC against the identified model, the normalised
residual of every loop stage, the optimiser's convergence.

Every function builds a :class:`matplotlib.figure.Figure` from plain arrays (no pyplot: the
process's backend is left alone) and returns it; :func:`save_png` writes one. Every axis
label names its unit in parentheses, so a figure read on its own says what it shows.
What each report figure draws, from an identification, is :mod:`vibid.report.figures`.
"""

from __future__ import annotations

import os
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: The label of a dimensionless ratio of two accelerations (H = response / base).
H_UNIT = "m/s² per m/s²"


@dataclass(frozen=True)
class Flagged:
    """A step the identification left out, shown on the AFC with its reason."""

    frequency_hz: float
    H: complex
    label: str


@dataclass(frozen=True)
class StageResidual:
    """One loop stage's residual ``(H_measured − H_model) / weight`` on the used points
    (real and imaginary parts, in standard deviations), and what the stage is."""

    label: str
    frequency_hz: np.ndarray
    re: np.ndarray
    im: np.ndarray
    chi2_reduced: float
    #: what the residual's diagnosis found: (frequency_hz, short label) per feature
    features: tuple[tuple[float, str], ...] = ()
    #: a diagnosed smooth trend across the band (no frequency of its own), in words
    trend: str = ""


def _figure(figsize):
    from matplotlib.figure import Figure

    return Figure(figsize=figsize)


def phase_near(phase_rad, reference_rad):
    """``phase_rad`` shifted by whole turns to lie within half a turn of ``reference_rad``."""
    return phase_rad - 2 * np.pi * np.round((phase_rad - reference_rad) / (2 * np.pi))


def afc_figure(
    frequency_hz,
    H,
    std,
    *,
    model_frequency_hz,
    model_H,
    natural_hz: Sequence[float] = (),
    flagged: Sequence[Flagged] = (),
    values_text: str = "",
    title: str = "",
    left_out_hz: Sequence[tuple[float, float]] = (),
):
    """|H| and phase against frequency: the measured points with ±2 std error bars (their
    standard uncertainty per real and imaginary part, ``std``; None if unknown), the model
    as a line on its own (fine) grid ``model_frequency_hz``, the model's natural
    frequencies ``natural_hz`` as dotted lines, the flagged steps as labelled crosses, the
    bands ``left_out_hz`` (Hz) that the fit left out shaded, and ``values_text`` (the
    identified values with units) in a box.

    The model's phase is unwrapped along its fine grid; every measured phase is drawn
    within half a turn of the model's at its frequency, so a resonance's phase turn is
    continuous and no jump from −180° to +180° appears where nothing happens.
    """
    f = np.asarray(frequency_hz, float)
    H = np.asarray(H, complex)
    s = np.zeros_like(f) if std is None else np.asarray(std, float)
    fm = np.asarray(model_frequency_hz, float)
    Hm = np.asarray(model_H, complex)
    order = np.argsort(fm)
    fm, Hm = fm[order], Hm[order]
    ph_model = np.unwrap(np.angle(Hm))
    fig = _figure((12.5, 7.5) if values_text else (10, 7.5))
    ax_mag, ax_ph = fig.subplots(2, 1, sharex=True)
    _draw_measured(ax_mag, ax_ph, (f, H, s), (fm, Hm, ph_model))
    _draw_flagged(ax_mag, ax_ph, flagged, fm, ph_model)
    _draw_left_out(ax_mag, ax_ph, left_out_hz)
    _draw_natural(ax_mag, ax_ph, natural_hz)
    _finish_afc(fig, ax_mag, ax_ph, title=title, values_text=values_text)
    return fig


def _draw_measured(ax_mag, ax_ph, measured, model) -> None:
    """The model's |H| and phase as lines, the ``measured`` (f, H, std) points with ±2
    std error bars, each phase within half a turn of the ``model`` (f, H, unwrapped
    phase)'s at its frequency."""
    f, H, s = measured
    fm, Hm, ph_model = model
    ax_mag.semilogy(fm, np.abs(Hm), "-", color="C1", lw=1.2, label="identified model")
    ax_mag.errorbar(
        f,
        np.abs(H),
        yerr=2 * s,
        fmt="o",
        ms=3,
        color="C0",
        elinewidth=0.9,
        capsize=2,
        label="measured (±2 std)",
    )
    ph = phase_near(np.angle(H), np.interp(f, fm, ph_model))
    ph_err = 2 * s / np.maximum(np.abs(H), 1e-300)
    ax_ph.plot(fm, np.degrees(ph_model), "-", color="C1", lw=1.2)
    ax_ph.errorbar(
        f,
        np.degrees(ph),
        yerr=np.degrees(ph_err),
        fmt="o",
        ms=3,
        color="C0",
        elinewidth=0.9,
        capsize=2,
    )


def _draw_flagged(ax_mag, ax_ph, flagged: Sequence[Flagged], fm, ph_model) -> None:
    """The flagged steps as labelled crosses."""
    for i, fx in enumerate(flagged):
        p = phase_near(np.angle(fx.H), np.interp(fx.frequency_hz, fm, ph_model))
        kw = {"label": "flagged, not used"} if i == 0 else {}
        ax_mag.plot(fx.frequency_hz, max(abs(fx.H), 1e-300), "x", color="C3", ms=7, mew=1.5, **kw)
        ax_mag.annotate(
            fx.label,
            (fx.frequency_hz, max(abs(fx.H), 1e-300)),
            fontsize=7,
            color="C3",
            xytext=(3, 6),
            textcoords="offset points",
        )
        ax_ph.plot(fx.frequency_hz, np.degrees(p), "x", color="C3", ms=7, mew=1.5)


def _draw_left_out(ax_mag, ax_ph, left_out_hz: Sequence[tuple[float, float]]) -> None:
    """The bands (Hz) the fit left out, shaded."""
    for i, (lo, hi) in enumerate(left_out_hz):
        for ax in (ax_mag, ax_ph):
            kw = (
                {"label": "left out of the fit (response depends on its amplitude)"}
                if (i == 0 and ax is ax_mag)
                else {}
            )
            ax.axvspan(lo, hi, color="0.85", zorder=0, **kw)


def _draw_natural(ax_mag, ax_ph, natural_hz: Sequence[float]) -> None:
    """The model's natural frequencies as dotted lines, named on the |H| axis."""
    for k, fn in enumerate(natural_hz, start=1):
        for ax in (ax_mag, ax_ph):
            ax.axvline(fn, color="0.5", ls=":", lw=0.9)
        ax_mag.annotate(
            f"f{k} = {fn:.4g} Hz",
            (fn, 1.0),
            xycoords=("data", "axes fraction"),
            rotation=90,
            fontsize=7,
            color="0.35",
            va="top",
            ha="right",
            xytext=(-2, -3),
            textcoords="offset points",
        )


def _finish_afc(fig, ax_mag, ax_ph, *, title: str, values_text: str) -> None:
    """The AFC figure's labels, grids, legend and title, and the identified values in a
    box beside the axes, never over the data."""
    ax_mag.set_ylabel(f"|H| ({H_UNIT})")
    ax_mag.grid(True, which="both", alpha=0.3)
    ax_mag.legend(loc="lower left", fontsize=8)
    ax_ph.set_ylabel("phase of H (deg)")
    ax_ph.set_xlabel("frequency (Hz)")
    ax_ph.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    if values_text:
        fig.tight_layout(rect=(0, 0, 0.74, 1))
        fig.text(
            0.75,
            0.9,
            "identified\n" + values_text,
            ha="left",
            va="top",
            fontsize=8,
            family="monospace",
            bbox={"boxstyle": "round", "fc": "white", "ec": "0.6", "alpha": 0.9},
        )
    else:
        fig.tight_layout()


def residual_figure(stages: Sequence[StageResidual], *, title: str = ""):
    """The normalised residual against frequency with its ±2 band, one panel per loop
    stage side by side (the declared model first): the error before and after each
    effect the loop added, with the features its diagnosis found marked."""
    n = max(1, len(stages))
    fig = _figure((max(7.0, 4.2 * n + 1), 4.4))
    axes = np.atleast_1d(fig.subplots(1, n, squeeze=False)[0])
    for ax, st in zip(axes, stages):
        ax.axhspan(-2, 2, color="C2", alpha=0.15, label="±2")
        ax.plot(st.frequency_hz, st.re, "o-", ms=3, lw=0.7, color="C0", label="Re")
        ax.plot(st.frequency_hz, st.im, "s-", ms=3, lw=0.7, color="C1", label="Im")
        ax.axhline(0, color="0.4", lw=0.6)
        for k, (f_hz, text) in enumerate(st.features):
            ax.axvline(
                f_hz, color="C3", lw=1.0, ls="--", label="diagnosed feature" if k == 0 else None
            )
            ax.annotate(
                text,
                (f_hz, 1.0),
                xycoords=("data", "axes fraction"),
                rotation=90,
                va="top",
                ha="right",
                fontsize=7,
                color="C3",
            )
        if st.trend:
            # wrapped to the panel and kept out of the layout: a long note laid out as one
            # line squeezed every panel to a sliver
            note = ax.text(
                0.02,
                0.02,
                textwrap.fill("trend: " + st.trend, 62),
                transform=ax.transAxes,
                fontsize=7,
                color="C3",
                va="bottom",
            )
            note.set_in_layout(False)
        if np.nanmax(np.abs(np.concatenate([st.re, st.im])), initial=0.0) > 20:
            # linear within the band, logarithmic beyond: a misfit of thousands of std and
            # the ±2 band show on one axis
            ax.set_yscale("symlog", linthresh=2.0)
        ax.set_title(f"{st.label}\nχ²/dof = {st.chi2_reduced:.4g}", fontsize=9)
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel("residual / std (standard deviations)")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def convergence_figure(stages: Sequence[tuple[str, Sequence[Sequence[float]]]], *, title: str = ""):
    """χ² against iteration of the local optimiser: per loop stage (label, the loss
    histories of its local runs, the run that gave the answer first), one panel each."""
    n = max(1, len(stages))
    fig = _figure((max(7.0, 4.2 * n + 1), 4.2))
    axes = np.atleast_1d(fig.subplots(1, n, squeeze=False)[0])
    for ax, (label, runs) in zip(axes, stages):
        for i, losses in enumerate(runs):
            losses = np.asarray(losses, float)
            if losses.size == 0:
                continue
            it = np.arange(losses.size)
            if i == 0:
                ax.semilogy(it, losses, "o-", ms=3, lw=1.5, color="C0", label="answer")
            else:
                ax.semilogy(
                    it, losses, "-", lw=0.8, color="0.6", label="other starts" if i == 1 else None
                )
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("iteration (count)")
        ax.set_ylabel("χ² (dimensionless)")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def axis_labels(fig) -> list[str]:
    """Every non-empty x and y label of ``fig``'s axes (for checks that each names a unit)."""
    out = []
    for ax in fig.axes:
        out += [t for t in (ax.get_xlabel(), ax.get_ylabel()) if t]
    return out


def png_data_uri(png: bytes) -> str:
    """A PNG as a ``data:image/png;base64,...`` URI (Prefect's UI renders it in markdown)."""
    import base64

    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def save_png(fig, path: str | os.PathLike, *, dpi: int = 110) -> str:
    """Write ``fig`` as a PNG; return its path."""
    fig.savefig(path, dpi=dpi, format="png")
    return os.fspath(path)
