"""The report's figures: one list, :data:`FIGURES`, that the report folder's PNG files,
report.md and the Prefect UI all follow.

A new figure is one function ``draw(source) -> matplotlib Figure | None`` (None: nothing to
draw this time) and one :class:`ReportFigure` entry in :data:`FIGURES`. The drawing from
plain arrays is :mod:`vibid.report.plots`; this module says what each figure shows of an
identification; the identified model is drawn on the fine frequency grid the assess stage
computed (:mod:`vibid.identify.assess.curve`), so a resonance is a peak, not a one-point
spike.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibid.report.values import quantities, stage_label


@dataclass(frozen=True)
class Source:
    """What a report figure is drawn from: the session's AFC and declared setup
    (:class:`vibid.pipeline.SessionAfc`), the identification
    (:class:`vibid.pipeline.Identified`), its JSON report and the model's AFC on a fine
    grid (:class:`vibid.identify.assess.curve.ModelCurve`; None where it was not
    computed: then no AFC figure)."""

    data: Any
    identified: Any
    report: dict
    curve: Any = None


@dataclass(frozen=True)
class ReportFigure:
    """One figure of the report."""

    #: its file in the report folder (a PNG)
    file: str
    #: what it shows, in report.md and the Prefect UI
    caption: str
    #: ``draw(source)``: the figure, or None when there is nothing to draw
    draw: Callable[[Source], Any]
    #: what report.md says when ``draw`` drew nothing ("" for nothing)
    absent: str = ""


def values_text(report: dict) -> str:
    """The identified values with units, one a line, for the AFC figure's box (the
    engineering constants in Pa only)."""
    return "\n".join(
        f"{q.name:>7} = {q.reading}"
        for q in quantities(report)
        if q.source != "engineering" or q.name.endswith("_Pa")
    )


def _flagged(afc) -> list:
    from vibid.report.plots import Flagged

    out = []
    used = np.asarray(afc.used, bool)
    flags = getattr(afc, "flags", None) or ((),) * used.size
    status = getattr(afc, "status", None) or ("ok",) * used.size
    for k in np.flatnonzero(~used):
        H = complex(afc.H[k])
        if not (np.isfinite(H) and np.isfinite(afc.frequency_hz[k])):
            continue
        label = ", ".join(flags[k]) or status[k]
        out.append(Flagged(float(afc.frequency_hz[k]), H, label))
    return out


def _stage_residual(label, result, diagnosis=None):
    """One stage's residual in the data's standard deviations (the reported chi2's
    weights; the fit's own where the data's are unknown), with its diagnosed features."""
    from vibid.report.plots import StageResidual

    u = np.asarray(result.used, bool)
    w = (
        np.asarray(result.H_std)[u]
        if result.H_std is not None
        else result.weights
        if result.weights is not None
        else np.ones(int(u.sum()))
    )
    r = (np.asarray(result.H)[u] - np.asarray(result.model_afc)[u]) / np.asarray(w, float)
    features = tuple(
        (float(f.f_hz), f"{f.kind} {f.f_hz:.4g} Hz")
        for f in getattr(diagnosis, "features", ())
        if np.isfinite(f.f_hz)
    )
    trend = "; ".join(f.note for f in getattr(diagnosis, "features", ()) if f.kind == "trend")
    return StageResidual(
        label,
        np.asarray(result.frequency_hz, float)[u],
        r.real,
        r.imag,
        float(result.chi2_reduced_reported),
        features,
        trend,
    )


def _stages(identified) -> list[tuple[str, Any, Any]]:
    """(label, result, diagnosis) of every stage."""
    if identified.loop is None:
        return [(stage_label(None), identified.result, None)]
    return [(stage_label(st.added), st.result, st.diagnosis) for st in identified.loop.stages]


def draw_afc(source: Source):
    """The measured AFC with the identified model on a fine grid, its natural frequencies,
    the flagged steps and the identified values."""
    from vibid.report.plots import afc_figure

    data, report = source.data, source.report
    measured = data.afc
    used = np.asarray(measured.used, bool)
    if source.curve is None:
        return None
    grid, Hm, natural = source.curve
    name = data.setup.specimen.name or "specimen"
    return afc_figure(
        np.asarray(measured.frequency_hz)[used],
        np.asarray(measured.H)[used],
        None if measured.std is None else np.asarray(measured.std)[used],
        model_frequency_hz=grid,
        model_H=Hm,
        natural_hz=natural,
        flagged=_flagged(measured),
        values_text=values_text(report),
        left_out_hz=[
            t.left_out_hz
            for t in getattr(source.identified, "linearity", ())
            if t.left_out_hz is not None
        ],
        title=f"{name}: measured AFC and the identified model ({report['model']}"
        + "".join(f" + {e['name']}" for e in report["effects"])
        + ")",
    )


def draw_residuals(source: Source):
    """The normalised residual of every loop stage."""
    from vibid.report.plots import residual_figure

    return residual_figure(
        [_stage_residual(label, r, d) for label, r, d in _stages(source.identified)],
        title="normalised residual (measured − model) / std, loop stage by stage",
    )


def draw_convergence(source: Source):
    """The local optimiser's χ² per iteration, stage by stage; None when it recorded no
    history."""
    from vibid.report.plots import convergence_figure

    histories = [
        (label, [[h.loss for h in run.history] for run in r.local_results])
        for label, r, _ in _stages(source.identified)
    ]
    if not any(len(h) for _, runs in histories for h in runs):
        return None
    return convergence_figure(histories, title="local optimiser: χ² per iteration")


#: The report's figures, in the order report.md and the Prefect UI show them.
FIGURES: tuple[ReportFigure, ...] = (
    ReportFigure(
        "afc.png",
        "Measured AFC (±2 std) and the identified model on a fine grid; "
        "natural frequencies dotted, flagged steps crossed, bands left out of the "
        "fit shaded",
        draw_afc,
    ),
    ReportFigure(
        "residuals.png",
        "Normalised residual with its ±2 band, before and after each effect",
        draw_residuals,
    ),
    ReportFigure(
        "convergence.png",
        "The local optimiser's χ² per iteration",
        draw_convergence,
        absent="(No convergence figure: the optimiser recorded no iteration history.)",
    ),
)


def draw_figures(
    data, identified, report: dict, not_done: list | None = None, *, curve=None
) -> dict[str, Any]:
    """Every figure of :data:`FIGURES` that has something to draw, by file name (``curve``:
    :attr:`Source.curve`). With ``not_done`` (the report's, :mod:`vibid.not_done`), a
    figure that cannot be drawn is left out with one line there, and the others are
    drawn."""
    from vibid.not_done import attempt

    source = Source(data, identified, report, curve)
    if not_done is None:
        drawn = {fig.file: fig.draw(source) for fig in FIGURES}
    else:
        drawn = {
            fig.file: attempt("figures", not_done, fig.draw, source, about=fig.file)
            for fig in FIGURES
        }
    return {file: fig for file, fig in drawn.items() if fig is not None}


#: Characters of a caption its image's alt text leaves out or replaces: markdown would
#: read them as syntax, HTML escapes them (the Prefect UI showed ``optimiser&#39;s``).
_ALT_REPLACED = str.maketrans(
    {
        "'": "’",
        "&": "and",
        '"': None,
        "<": None,
        ">": None,
        "[": None,
        "]": None,
        "*": None,
        "_": None,
        "`": None,
        "\\": None,
    }
)


def alt_text(caption: str) -> str:
    """A caption as plain image alt text (:data:`_ALT_REPLACED`: no character that markdown
    or HTML escapes)."""
    return " ".join(caption.translate(_ALT_REPLACED).split())


def figure_markdown(caption: str, src: str) -> list[str]:
    """One figure as markdown lines: the image (``src``: a file name or a data URI; its alt
    text the caption made plain, :func:`alt_text`) and the caption below it as text."""
    return [f"![{alt_text(caption)}]({src})", "", f"*{caption}*", ""]
