"""The summary of many identified sessions: one row per session (its parameters' values
and std, the effects found, χ²/dof before and after), as CSV and as a markdown table."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from typing import Any

from vibid.report.values import chi2_text, quantities, unit_of, with_std


def summary_row(name: str, report: dict | None, *, error: str = "") -> dict[str, Any]:
    """One session's row of the batch summary: its parameters (value and std columns),
    the effects found, χ²/dof before and after the loop."""
    if report is None:
        return {"session": name, "status": f"failed: {error}"}
    stages = report["loop"]["stages"]
    row: dict[str, Any] = {
        "session": name,
        "session_id": report["session_id"],
        "status": "ok"
        if report.get("identification", {}).get("converged", True)
        else "not converged",
        "model": report["model"],
        "effects": " ".join(e["name"] for e in report["effects"]) or "none",
    }
    for q in quantities(report):
        if q.source == "engineering":
            continue
        row[q.name] = q.value
        row[f"{q.name}_std"] = q.std
    row["chi2_reduced_before"] = stages[0]["chi2_reduced"]
    row["chi2_reduced_after"] = stages[-1]["chi2_reduced"]
    row["unexplained_residual"] = report["loop"]["unexplained_residual"]
    return row


def _columns(rows) -> list[str]:
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    return cols


def summary_csv(rows: Sequence[dict]) -> str:
    """The batch summary as CSV (one row per session; empty cells where a session lacks a
    column; floats written with repr, so they read back exactly)."""
    out = io.StringIO()
    w = csv.DictWriter(out, fieldnames=_columns(rows), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return out.getvalue()


def summary_table_markdown(rows: Sequence[dict]) -> str:
    """The batch summary as a markdown table: parameters as ``value ± std`` with units,
    the effects found, χ²/dof before → after."""
    params = [c for c in _columns(rows) if f"{c}_std" in _columns(rows)]
    head = [
        "session",
        "status",
        "model",
        *[p if unit_of(p) == "1" else f"{p} ({unit_of(p).replace(' ', '·')})" for p in params],
        "effects",
        "χ²/dof before → after",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [str(r.get("session", "")), str(r.get("status", "")), str(r.get("model", ""))]
        cells += [with_std(r[p], r.get(f"{p}_std")) if r.get(p) is not None else "" for p in params]
        cells.append(str(r.get("effects", "")))
        cells.append(
            f"{chi2_text(r.get('chi2_reduced_before'))} → {chi2_text(r.get('chi2_reduced_after'))}"
            if "chi2_reduced_before" in r
            else ""
        )
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
