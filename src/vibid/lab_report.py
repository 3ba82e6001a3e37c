"""The readable report of one identified session: ``report.md`` with PNG figures, in a
folder; and the summary table of many sessions (CSV and markdown).

Built from the same content as the JSON report (:mod:`vibid.report`), plus what only the
in-memory results hold: the model evaluated on a fine frequency grid (so a resonance is a
peak, not a one-point spike), every loop stage's residual, the optimiser's history.

The text speaks a lab's language: values with units and standard deviation, the effect the
loop found and what it changed, χ² before and after; the optimiser's internals (status
sentence, runs, evaluations) go to the "Details" section.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from vibid.parameters import DESCRIPTIONS, describe, known_parameter

#: Points of the fine grid the model is drawn on, spread evenly over the measured band;
#: each natural frequency in the band gets FINE_PER_MODE more within a few half-power
#: bandwidths of it, so its peak is drawn at its height.
FINE_POINTS = 2000
FINE_PER_MODE = 161
#: Half-widths around a mode densely sampled, in half-power bandwidths.
FINE_HALF_WIDTH_BANDWIDTHS = 12.0
#: Modes asked of the model to find those in the band.
N_MODES = 12

#: File names in the report folder.
REPORT_MD = "report.md"
REPORT_JSON = "report.json"
AFC_PNG = "afc.png"
RESIDUALS_PNG = "residuals.png"
CONVERGENCE_PNG = "convergence.png"
#: Each figure's caption, in the order a report shows them (report.md, the Prefect UI).
FIGURE_CAPTIONS = {
    AFC_PNG: "Measured AFC (±2 std) and the identified model on a fine grid; natural "
             "frequencies dotted, flagged steps crossed",
    RESIDUALS_PNG: "Normalised residual with its ±2 band, before and after each effect",
    CONVERGENCE_PNG: "The local optimiser's χ² per iteration",
}

#: What a lab engineer calls each parameter (the catalogue's :data:`vibid.parameters.
#: DESCRIPTIONS`; an instance's through :func:`vibid.parameters.describe`).
MEANING = DESCRIPTIONS


# -- numbers a person reads -------------------------------------------------------------------
def unit_of(name: str) -> str:
    """The SI unit of a report parameter (material, effect or engineering constant)."""
    if name.endswith("_Pa"):
        return "Pa"
    q = known_parameter(name)
    return "1" if q is None else q.unit


def _unit_text(unit: str) -> str:
    return "" if unit == "1" else f" {unit.replace(' ', '·')}"


def with_std(value, std) -> str:
    """``value ± std`` with the value rounded to the std's second significant digit."""
    if value is None:
        return "n/a"
    if std is None or not math.isfinite(std) or std <= 0:
        return f"{value:.6g}"
    digits = max(0, 1 - int(math.floor(math.log10(std))))
    if abs(value) >= 1e5 or (abs(value) < 1e-3 and value != 0):
        exp = int(math.floor(math.log10(abs(value))))
        scale = 10.0**exp
        d = max(0, 1 - int(math.floor(math.log10(std / scale))))
        return f"({value / scale:.{d}f} ± {std / scale:.{d}f})e{exp:+d}"
    return f"{value:.{digits}f} ± {std:.{digits}f}"


def _chi2(x) -> str:
    return "n/a" if x is None else f"{x:.4g}"


# -- the model on a fine grid ----------------------------------------------------------------
def fine_model(setup, result, *, n_points: int = FINE_POINTS):
    """``(frequency_hz, H, natural_hz)``: the final model's AFC on a fine grid over the
    measured band (:data:`FINE_POINTS` evenly spread, plus :data:`FINE_PER_MODE` around
    each natural frequency in the band) and those natural frequencies (Hz), from the
    reduced model rebuilt around the estimate (accurate to about 1e-6 of max |H|)."""
    from vibid.identify import build_forward_model, natural_frequencies

    f_used = np.asarray(result.frequency_hz, float)[np.asarray(result.used, bool)]
    lo, hi = float(f_used.min()), float(f_used.max())
    fn, decay = natural_frequencies(setup, result.parameters, N_MODES)
    fn, decay = np.asarray(fn, float), np.asarray(decay, float)
    inband = (fn >= lo) & (fn <= hi)
    grids = [np.linspace(lo, hi, n_points)]
    for f0, g in zip(fn[inband], decay[inband]):
        half = FINE_HALF_WIDTH_BANDWIDTHS * max(g / np.pi, 1e-6 * f0)
        grids.append(np.clip(np.linspace(f0 - half, f0 + half, FINE_PER_MODE), lo, hi))
    grid = np.unique(np.concatenate(grids))
    model = build_forward_model(setup, grid, model=result.plate_model, theta0=result.parameters)
    return grid, np.asarray(model.afc(np.asarray(result.values, float))), fn[inband]


def flat_name(effect: dict, name: str) -> str:
    """An effect parameter's name in a flat list: with the instance's suffix ``_k`` for an
    effect that occurs more than once (report format)."""
    return name if "instance" not in effect else f"{name}_{effect['instance']}"


# -- the figures -------------------------------------------------------------------------------
def _values_text(report: dict) -> str:
    rows = [(n, p["value"], p["std"]) for n, p in report["parameters"].items()]
    rows += [(flat_name(e, n), p["value"], p["std"])
             for e in report["effects"] for n, p in e["parameters"].items()]
    rows += [(n, p["value"], p["std"]) for n, p in engineering_of(report).items()
             if n.endswith("_Pa")]
    return "\n".join(f"{n:>7} = {with_std(v, s)}{_unit_text(unit_of(n))}" for n, v, s in rows)


def _flagged(afc) -> list:
    from vibid.plots import Flagged

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
    from vibid.plots import StageResidual

    u = np.asarray(result.used, bool)
    w = (np.asarray(result.H_std)[u] if result.H_std is not None
         else result.weights if result.weights is not None else np.ones(int(u.sum())))
    r = (np.asarray(result.H)[u] - np.asarray(result.model_afc)[u]) / np.asarray(w, float)
    features = tuple((float(f.f_hz), f"{f.kind} {f.f_hz:.4g} Hz")
                     for f in getattr(diagnosis, "features", ()) if np.isfinite(f.f_hz))
    trend = "; ".join(f.note for f in getattr(diagnosis, "features", ()) if f.kind == "trend")
    return StageResidual(label, np.asarray(result.frequency_hz, float)[u], r.real, r.imag,
                         float(result.chi2_reduced_reported), features, trend)


def _stages(identified) -> list[tuple[str, Any, Any]]:
    """(label, result, diagnosis) of every stage."""
    if identified.loop is None:
        return [("declared model", identified.result, None)]
    return [("declared model" if st.added is None else f"+ {st.added}", st.result,
             st.diagnosis) for st in identified.loop.stages]


def figures(data, identified, report: dict) -> dict[str, Any]:
    """The report's figures by file name (:data:`AFC_PNG`, :data:`RESIDUALS_PNG`,
    :data:`CONVERGENCE_PNG`); the last only when the optimiser recorded its history."""
    from vibid.plots import afc_figure, convergence_figure, residual_figure

    afc, result = data.afc, identified.result
    used = np.asarray(afc.used, bool)
    grid, Hm, natural = fine_model(data.setup, result)
    name = data.setup.specimen.name or "specimen"
    out = {AFC_PNG: afc_figure(
        np.asarray(afc.frequency_hz)[used], np.asarray(afc.H)[used],
        None if afc.std is None else np.asarray(afc.std)[used],
        model_frequency_hz=grid, model_H=Hm, natural_hz=natural, flagged=_flagged(afc),
        values_text=_values_text(report),
        title=f"{name}: measured AFC and the identified model ({report['model']}"
              + "".join(f" + {e['name']}" for e in report["effects"]) + ")")}
    stages = _stages(identified)
    out[RESIDUALS_PNG] = residual_figure(
        [_stage_residual(label, r, d) for label, r, d in stages],
        title="normalised residual (measured − model) / std, loop stage by stage")
    histories = [(label, [[h.loss for h in run.history] for run in r.local_results])
                 for label, r, _ in stages]
    if any(len(h) for _, runs in histories for h in runs):
        out[CONVERGENCE_PNG] = convergence_figure(
            histories, title="local optimiser: χ² per iteration")
    return out


# -- the text ----------------------------------------------------------------------------------
def engineering_of(report: dict) -> dict:
    """The report's engineering constants (``engineering`` without its ``budget``)."""
    return {n: p for n, p in report.get("engineering", {}).items() if n != "budget"}


def _budget_text(budget: dict | None, notes) -> list[str]:
    """The uncertainty budget as a table (one column per source, standard uncertainties in
    the constant's unit) and each constant's largest part in words."""
    if not budget:
        return []
    sources = list(dict.fromkeys(s for parts in budget.values() for s in parts))
    lines = ["", "Uncertainty budget (standard uncertainties; they add in quadrature):", "",
             "| constant | " + " | ".join(sources) + " |", "|---|" + "---|" * len(sources)]
    for k, parts in budget.items():
        lines.append(f"| {k} | " + " | ".join(
            "–" if parts.get(s) is None else f"{parts[s]:.3g}" for s in sources) + " |")
    return lines + [""] + [f"- {n}" for n in notes]


def _plausibility_text(pl: dict | None) -> list[str]:
    if not pl:
        return []
    cls = pl.get("material_class")
    lines = ["", "Plausibility" + (f" (the specimen is {cls}):" if cls else
                                   " (no material class named: only what physics allows):"), ""]
    lines += [f"- **not physical**: {v}" for v in pl["violations"]]
    lines += [f"- **outside the handbook range**: {v}" for v in pl["outside_handbook"]]
    lines += [f"- {v}" for v in pl["inside_handbook"]]
    if len(lines) == 3:
        lines.append("- every constant is physically possible")
    return lines


def _param_rows(params: dict) -> list[str]:
    return [f"| {n} | {describe(n)} | {with_std(p['value'], p['std'])} | "
            f"{unit_of(n).replace(' ', '·')} |" for n, p in params.items()]


def _effect_text(report: dict) -> list[str]:
    from vibid.identify.effects import meaning_of

    stages = report["loop"]["stages"]
    first, last = stages[0], stages[-1]
    lines = []
    if "rounds" not in report["loop"]:
        fit = ("does **not** fit" if report["loop"]["unexplained_residual"] else "fits")
        return [f"The closed loop did not run; the declared model {fit} the data to the "
                "noise level."]
    if not report["effects"]:
        if report["loop"]["unexplained_residual"]:
            lines.append("The declared model does **not** fit the data to the noise level, and "
                         "no candidate effect explained the residual (`unexplained_residual`): "
                         "look at the residual figure for what the model lacks.")
        else:
            lines.append("No effect needed: the declared model fits the data to the noise level.")
        return lines
    for e in report["effects"]:
        vals = ", ".join(f"{n} = {with_std(p['value'], p['std'])}{_unit_text(unit_of(n))}"
                         for n, p in e["parameters"].items())
        lines.append(f"- **{e['name']}**: {meaning_of(e['name'])}"
                     + (f"; {vals}" if vals else ""))
    lines.append("")
    lines.append(f"With it χ²/dof went from {_chi2(first['chi2_reduced'])} to "
                 f"{_chi2(last['chi2_reduced'])}, and the relative RMS residual from "
                 f"{_pct(first['rel_rms_residual'])} to {_pct(last['rel_rms_residual'])}.")
    changes = []
    for n, v1 in last["parameters"].items():
        v0 = first["parameters"].get(n)
        if v0 is None or v1 is None or v0 == 0:
            continue
        changes.append(f"{n} {100 * (v1 - v0) / abs(v0):+.3g} %")
    if changes:
        lines.append("Against the declared model's fit it changed " + ", ".join(changes) + ".")
    if report["loop"]["unexplained_residual"]:
        lines.append("The residual is still above the noise (`unexplained_residual`).")
    return lines


def _diagnosis_text(report: dict) -> list[str]:
    """What each stage's residual showed (``loop.diagnosis``), as a list."""
    per_stage = report["loop"].get("diagnosis")
    if not per_stage:
        return []
    lines = ["", "What the residual showed (its diagnosis, stage by stage):", ""]
    for st, features in zip(report["loop"]["stages"], per_stage):
        name = "declared model" if st["added"] is None else "+ " + st["added"]
        said = "; ".join(f["note"] for f in features) or "nothing beyond the noise"
        lines.append(f"- {name}: {said}")
    return lines


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.3g} %"


def summary_markdown(report: dict, *, figures: Sequence[str] = (), title: str = "",
                     session_path: str | None = None) -> str:
    """``report.md``: the result in a lab's language, the figures (file names relative to
    the report folder), and a Details section with the optimiser's internals."""
    ident = report.get("identification", {})
    afc = report["afc"]
    diag = afc.get("diagnostics")
    n_used = len(afc["frequency_hz"])
    lines = [f"# {title or 'Identification report'}", ""]
    lines.append(f"- session: `{report['session_id']}`"
                 + (f" (`{os.path.basename(session_path)}`)" if session_path else ""))
    if diag is not None:
        left_out = [d for d in diag if not d.get("used")]
        lines.append(f"- steps used: {n_used} of {len(diag)}"
                     + (" — left out: " + "; ".join(
                         f"{d['commanded_hz']:.4g} Hz ({', '.join(f['name'] for f in d['flags']) or d['status']})"
                         for d in left_out) if left_out else ""))
    else:
        lines.append(f"- AFC points used: {n_used}")
    model = report["model"] + ("" if report["model"] == report["declared_model"]
                               else f" (declared {report['declared_model']})")
    lines.append(f"- model: {model}")
    if ident.get("data") == "magnitude":
        ratio = ident.get("magnitude_only_std_ratio") or {}
        lines.append("- data: **|H| alone** (the phase was not used); each standard deviation "
                     "against the complex fit of the same points: " + ", ".join(
                         f"{n} ×{r:.2g}" for n, r in ratio.items() if r is not None))
    if ident and not ident.get("converged", True):
        lines.append(f"- **the identification did not converge**: {ident.get('message', '')}")
    lines += ["", "## Identified values (value ± standard deviation)", "",
              "| parameter | meaning | value | unit |", "|---|---|---|---|"]
    lines += _param_rows(report["parameters"])
    if "engineering" in report:
        lines += ["", "Engineering constants (from the stiffnesses and the declared thickness):", "",
                  "| constant | meaning | value | unit |", "|---|---|---|---|"]
        lines += _param_rows(engineering_of(report))
        lines += _budget_text(report["engineering"].get("budget"),
                              ident.get("uncertainty_notes", []))
    lines += _plausibility_text(report.get("plausibility"))
    lines += ["", "## Effects the loop found", ""] + _effect_text(report)
    lines += ["", "## Fit quality, stage by stage", "",
              "| stage | χ²/dof (the data's std) | χ²/dof (with the model's own error) | "
              "relative RMS residual |", "|---|---|---|---|"]
    for st in report["loop"]["stages"]:
        lines.append(f"| {'declared model' if st['added'] is None else '+ ' + st['added']} | "
                     f"{_chi2(st['chi2_reduced'])} | "
                     f"{_chi2(st.get('chi2_reduced_with_model_error'))} | "
                     f"{_pct(st['rel_rms_residual'])} |")
    lines += _diagnosis_text(report)
    if report.get("linearity"):
        lines += ["", "Are the measured resonances linear? (rational fits of the AFC alone):", ""]
        lines += [f"- {t['note']}" for t in report["linearity"]]
    if figures:
        lines += ["", "## Figures", ""]
        for name in figures:
            caption = FIGURE_CAPTIONS.get(name, name)
            lines += [f"![{caption}]({name})", "", f"*{caption}*", ""]
        if CONVERGENCE_PNG not in figures:
            lines.append("(No convergence figure: the optimiser recorded no iteration history.)")
    lines += ["", "## Details", ""]
    if ident:
        lines.append(f"- optimiser: {ident.get('message', '')}")
        lines.append(f"- χ² = {_chi2(ident.get('chi2'))} over {ident.get('dof')} degrees of "
                     "freedom (weights: the data's std and the model's own error);"
                     f" χ²/dof with the data's own weights {_chi2(ident.get('chi2_reduced_data_weights'))}")
        g = ident.get("global_search")
        if g:
            lines.append(f"- global search: {len(g['restart_loss'])} restarts, "
                         f"{g['evaluations']} model evaluations")
        for r in ident.get("local_runs", [])[:5]:
            lines.append(f"- local run {r['method']}: χ² {_chi2(r['chi2'])}, "
                         f"{r['iterations']} iterations, {r['status']}")
        if ident.get("model_error_std"):
            lines.append("- the model's discretisation bias (included in the std): " + ", ".join(
                f"{n} {v:.2g}" for n, v in ident["model_error_std"].items() if v is not None))
        for w in ident.get("warnings", []):
            lines.append(f"- warning: {w}")
        if ident.get("seconds") is not None:
            lines.append(f"- identification time: {ident['seconds']:.1f} s"
                         + (f", loop {report['loop']['seconds']:.1f} s"
                            if report["loop"].get("seconds") is not None else ""))
    for rnd, scores in enumerate(report["loop"].get("rounds", []), start=1):
        for sc in scores:
            lines.append(f"- loop round {rnd}: {sc['candidate']} score {_chi2(sc['score'])}"
                         f" (p {_chi2(sc['p_value'])}), Δχ² {_chi2(sc['delta_chi2'])}"
                         f"{', kept' if sc['kept'] else ''}{'; ' + sc['note'] if sc['note'] else ''}")
    return "\n".join(lines) + "\n"


def console_summary(report: dict) -> str:
    """A few lines for the console at the end of a job: the identified values with std and
    units, the effects the loop found (with their values), χ²/dof before and after."""
    from vibid.identify.effects import meaning_of

    stages = report["loop"]["stages"]
    lines = ["identified (value ± std):"]
    for q in parameter_table(report):
        if q["source"] == "engineering":
            continue
        unit = _unit_text(q["unit"])
        lines.append(f"  {q['quantity']:<20} {with_std(q['value'], q['std'])}{unit}"
                     + ("" if q["source"] == "model" else f"   ({q['source']})"))
    names = [e["name"] for e in report["effects"]]
    if names:
        lines.append("effects found: " + ", ".join(
            f"{n} ({meaning_of(n)})" for n in names))
    elif report["loop"]["unexplained_residual"]:
        lines.append("effects found: none, and the residual is above the noise "
                     "(unexplained_residual)")
    else:
        lines.append("effects found: none needed (the declared model fits to the noise level)")
    lines.append(f"chi2/dof: {_chi2(stages[0]['chi2_reduced'])} (declared model) -> "
                 f"{_chi2(stages[-1]['chi2_reduced'])} (final)")
    lines += plausibility_lines(report)
    return "\n".join(lines)


def plausibility_lines(report: dict) -> list[str]:
    """The report's plausibility findings for the console: never silent about a constant
    no material allows or one outside its material's handbook range."""
    pl = report.get("plausibility") or {}
    return ([f"NOT PHYSICAL: {v}" for v in pl.get("violations", [])]
            + [f"implausible: {v}" for v in pl.get("outside_handbook", [])])


def write_lab_report(report_dir: str | os.PathLike, data, identified, report: dict, *,
                     session_path: str | None = None) -> dict[str, str]:
    """Write ``report.md``, ``report.json`` and the PNG figures into ``report_dir``
    (created); return their paths by file name."""
    from vibid.plots import save_png
    from vibid.report import write_report

    os.makedirs(report_dir, exist_ok=True)
    paths = {}
    figs = figures(data, identified, report)
    for name, fig in figs.items():
        paths[name] = save_png(fig, os.path.join(report_dir, name))
    name = data.setup.specimen.name or "specimen"
    text = summary_markdown(report, figures=list(figs), session_path=session_path,
                            title=f"{name}: identification report")
    paths[REPORT_MD] = os.path.join(report_dir, REPORT_MD)
    with open(paths[REPORT_MD], "w", encoding="utf-8") as fh:
        fh.write(text)
    paths[REPORT_JSON] = os.path.join(report_dir, REPORT_JSON)
    write_report(report, paths[REPORT_JSON])
    return paths


# -- tables ------------------------------------------------------------------------------------
def parameter_table(report: dict) -> list[dict[str, Any]]:
    """One row per identified quantity (parameters, effects' parameters, engineering
    constants): name, value, std, unit, and which block it comes from."""
    rows = [{"quantity": n, "value": p["value"], "std": p["std"], "unit": unit_of(n),
             "source": "model"} for n, p in report["parameters"].items()]
    rows += [{"quantity": flat_name(e, n), "value": p["value"], "std": p["std"],
              "unit": unit_of(n), "source": e["name"]}
             for e in report["effects"] for n, p in e["parameters"].items()]
    rows += [{"quantity": n, "value": p["value"], "std": p["std"], "unit": unit_of(n),
              "source": "engineering"} for n, p in engineering_of(report).items()]
    return rows


def summary_row(name: str, report: dict | None, *, error: str = "") -> dict[str, Any]:
    """One session's row of the batch summary: its parameters (value and std columns),
    the effects found, χ²/dof before and after the loop."""
    if report is None:
        return {"session": name, "status": f"failed: {error}"}
    stages = report["loop"]["stages"]
    row: dict[str, Any] = {"session": name, "session_id": report["session_id"],
                           "status": "ok" if report.get("identification", {}).get("converged", True)
                           else "not converged", "model": report["model"],
                           "effects": " ".join(e["name"] for e in report["effects"]) or "none"}
    for q in parameter_table(report):
        if q["source"] == "engineering":
            continue
        row[q["quantity"]] = q["value"]
        row[f"{q['quantity']}_std"] = q["std"]
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
    head = ["session", "status", "model", *[p if unit_of(p) == "1" else f"{p} ({unit_of(p).replace(' ', '·')})" for p in params],
            "effects", "χ²/dof before → after"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [str(r.get("session", "")), str(r.get("status", "")), str(r.get("model", ""))]
        cells += [with_std(r[p], r.get(f"{p}_std")) if r.get(p) is not None else "" for p in params]
        cells.append(str(r.get("effects", "")))
        cells.append(f"{_chi2(r.get('chi2_reduced_before'))} → {_chi2(r.get('chi2_reduced_after'))}"
                     if "chi2_reduced_before" in r else "")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def artifact_key(specimen_name: str, suffix: str) -> str:
    """A Prefect artifact key (lowercase letters, digits, dashes) stable per specimen, so
    one specimen's reports form a history."""
    slug = re.sub(r"[^a-z0-9]+", "-", (specimen_name or "specimen").lower()).strip("-")
    return f"{slug or 'specimen'}-{suffix}"
