"""Where a specimen's report is kept: the report folder (``report.md``, ``report.json`` and
the figures of :data:`vibid.report.figures.FIGURES`, written together) and the keys of its
Prefect artifacts, stable per specimen."""

from __future__ import annotations

import os
import re

from vibid.not_done import NOT_DONE, attempt
from vibid.report.document import write_report
from vibid.report.figures import draw_figures
from vibid.report.markdown import summary_markdown
from vibid.report.plots import save_png

#: File names in the report folder (besides the figures').
REPORT_MD = "report.md"
REPORT_JSON = "report.json"


def write_lab_report(
    report_dir: str | os.PathLike,
    data,
    identified,
    report: dict,
    *,
    session_path: str | None = None,
    curve=None,
) -> dict[str, str]:
    """Write ``report.md``, ``report.json`` and the PNG figures into ``report_dir``
    (created); return their paths by file name (``curve``: the model's AFC on a fine grid,
    :func:`vibid.identify.assess.curve.model_curve`; without it, no AFC figure). Figures that cannot be drawn, or a
    report.md that cannot be made, are left out in one line of ``report``'s ``not_done``
    (which it appends to, before report.json is written: :mod:`vibid.not_done`)."""
    os.makedirs(report_dir, exist_ok=True)
    paths = {}
    not_done = report.setdefault(NOT_DONE, [])
    figs = attempt(
        "figures",
        not_done,
        draw_figures,
        data,
        identified,
        report,
        not_done,
        curve=curve,
        default={},
    )
    for name, fig in figs.items():
        paths[name] = save_png(fig, os.path.join(report_dir, name))
    name = data.setup.specimen.name or "specimen"
    text = attempt(
        "report.md",
        not_done,
        summary_markdown,
        report,
        figures=list(figs),
        session_path=session_path,
        title=f"{name}: identification report",
    )
    if text is not None:
        paths[REPORT_MD] = os.path.join(report_dir, REPORT_MD)
        with open(paths[REPORT_MD], "w", encoding="utf-8") as fh:
            fh.write(text)
    paths[REPORT_JSON] = os.path.join(report_dir, REPORT_JSON)
    write_report(report, paths[REPORT_JSON])
    return paths


def artifact_key(specimen_name: str, suffix: str) -> str:
    """A Prefect artifact key (lowercase letters, digits, dashes) stable per specimen, so
    one specimen's reports form a history."""
    slug = re.sub(r"[^a-z0-9]+", "-", (specimen_name or "specimen").lower()).strip("-")
    return f"{slug or 'specimen'}-{suffix}"
