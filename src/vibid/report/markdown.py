"""report.md: the result of one identification in a lab's language, from the JSON report.

Values with units and standard deviation (:func:`vibid.report.values.quantities`), the
effect the loop found and what it changed, χ² before and after, the figures of
:data:`vibid.report.figures.FIGURES`; the optimiser's internals (status sentence, runs,
evaluations) go to the "Details" section.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from vibid.not_done import not_done_lines
from vibid.report import figures as report_figures
from vibid.report.figures import figure_markdown
from vibid.report.values import (
    Quantity,
    chi2_text,
    percent_text,
    quantities,
    reading,
    stage_label,
    unit_of,
)

#: What the budget's columns that are no declared quantity hold
#: (:mod:`vibid.identify.assess.budget`; a declared quantity's column is named by its setup field).
BUDGET_PARTS = {
    "fit": "the data's noise and the model's misfit",
    "discretisation": "the mesh's error, Richardson-extrapolated over three meshes (the shift "
    "of the estimate it causes)",
    "model": "the spread across the models the loop compared",
    "clamp_line": "the clamp's effective line, which the data cannot tell from the stiffness",
}


def _budget_text(budget: dict | None, notes) -> list[str]:
    """The uncertainty budget as a table (one column per source, standard uncertainties in
    the constant's unit), what its columns that are no declared quantity hold, and each
    constant's largest part in words."""
    if not budget:
        return []
    sources = list(dict.fromkeys(s for parts in budget.values() for s in parts))
    lines = [
        "",
        "Uncertainty budget (standard uncertainties; they add in quadrature):",
        "",
        "| constant | " + " | ".join(sources) + " |",
        "|---|" + "---|" * len(sources),
    ]
    for k, parts in budget.items():
        lines.append(
            f"| {k} | "
            + " | ".join("–" if parts.get(s) is None else f"{parts[s]:.3g}" for s in sources)
            + " |"
        )
    named = [f"{s}: {BUDGET_PARTS[s]}" for s in sources if s in BUDGET_PARTS]
    return (
        lines
        + [""]
        + ([f"- columns: {'; '.join(named)}"] if named else [])
        + [f"- {n}" for n in notes]
    )


def _plausibility_text(pl: dict | None) -> list[str]:
    if not pl:
        return []
    cls = pl.get("material_class")
    lines = [
        "",
        "Plausibility"
        + (
            f" (the specimen is {cls}):"
            if cls
            else " (no material class named: only what physics allows):"
        ),
        "",
    ]
    lines += [f"- **not physical**: {v}" for v in pl["violations"]]
    lines += [f"- **outside the handbook range**: {v}" for v in pl["outside_handbook"]]
    lines += [f"- {v}" for v in pl["inside_handbook"]]
    if len(lines) == 3:
        lines.append("- every constant is physically possible")
    return lines


def _param_rows(rows: list[Quantity]) -> list[str]:
    return [f"| {q.name} | {q.meaning} | {q.text} | {q.unit.replace(' ', '·')} |" for q in rows]


def _effect_text(report: dict) -> list[str]:
    from vibid.identify.effects import meaning_of

    stages = report["loop"]["stages"]
    first, last = stages[0], stages[-1]
    lines = []
    if "rounds" not in report["loop"]:
        fit = "does **not** fit" if report["loop"]["unexplained_residual"] else "fits"
        return [
            f"The closed loop did not run; the declared model {fit} the data to the noise level."
        ]
    if not report["effects"]:
        if report["loop"]["unexplained_residual"]:
            lines.append(
                "The declared model does **not** fit the data to the noise level, and "
                "no candidate effect explained the residual (`unexplained_residual`): "
                "look at the residual figure for what the model lacks."
            )
        else:
            lines.append("No effect needed: the declared model fits the data to the noise level.")
        return lines
    for e in report["effects"]:
        vals = ", ".join(
            f"{n} = {reading(p['value'], p['std'], unit_of(n))}" for n, p in e["parameters"].items()
        )
        lines.append(f"- **{e['name']}**: {meaning_of(e['name'])}" + (f"; {vals}" if vals else ""))
    lines.append("")
    lines.append(
        f"With it χ²/dof went from {chi2_text(first['chi2_reduced'])} to "
        f"{chi2_text(last['chi2_reduced'])}, and the relative RMS residual from "
        f"{percent_text(first['rel_rms_residual'])} to "
        f"{percent_text(last['rel_rms_residual'])}."
    )
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


def _points_text(frequency_hz, linearity) -> str:
    """The AFC's points and those the fit used: the bands left out (a resonance's top
    whose response depends on its amplitude) are not fitted."""
    bands = [t["left_out_hz"] for t in linearity if t.get("left_out_hz") is not None]
    out = sum(any(lo <= f <= hi for lo, hi in bands) for f in frequency_hz)
    if not out:
        return f"- AFC points used: {len(frequency_hz)}"
    said = ", ".join(f"{lo:.4g}-{hi:.4g} Hz" for lo, hi in bands)
    return (
        f"- AFC points used: {len(frequency_hz) - out} of {len(frequency_hz)} ({said} left "
        "out: a top whose response depends on its amplitude)"
    )


#: How many explanations of a stage the report names (most probable first).
ODDS_NAMED = 4


def _odds_text(report: dict) -> list[str]:
    """How sure the loop is: at each stage, the explanations it compared by its criterion
    (``loop.criterion``) with their probabilities, the chosen first."""
    stages = report["loop"].get("stages") or []
    if not any(st.get("alternatives") for st in stages):
        return []
    crit = (report["loop"].get("criterion") or {}).get("name", "its criterion")
    lines = [
        "",
        f"How sure the loop is: each explanation's probability at each stage, by "
        f"`{crit}` (`loop.criterion` says what it means), the chosen first:",
        "",
    ]
    for st in stages:
        alts = st.get("alternatives")
        if not alts:
            continue
        after = "the declared model" if st["added"] is None else f"+ {st['added']}"
        named = []
        for a in alts[:ODDS_NAMED]:
            what = "stop here" if a["added"] is None else a["added"].replace("_", " ")
            if a.get("f_hz"):
                what += f" at {a['f_hz']:.4g} Hz"
            p = a["probability"]
            named.append(f"{what}: {p:.2g}" + (" (estimated)" if a.get("estimated") else ""))
        lines.append(f"- after {after}: " + "; ".join(named))
    return lines


#: How many of the candidates the loop kept out the report names (largest χ² drop first).
KEPT_OUT_NAMED = 3


def _kept_out_text(report: dict) -> list[str]:
    """Where a residual remains: the candidates of the last round that lowered χ² most and
    were not kept (:func:`vibid.identify.loop.verdicts.is_close_call`: moved off their null),
    with the loop's reason, so that a lab sees what came closest."""
    from vibid.identify.loop.verdicts import is_close_call

    rounds = report["loop"].get("rounds") or []
    if not rounds or not report["loop"].get("unexplained_residual"):
        return []
    stage = report["loop"]["stages"][min(len(rounds), len(report["loop"]["stages"])) - 1]
    dof = report.get("identification", {}).get("dof")
    tried = sorted(
        (c for c in rounds[-1] if is_close_call(c["verdict"], c["delta_chi2"])),
        key=lambda c: -c["delta_chi2"],
    )[:KEPT_OUT_NAMED]
    if not tried:
        return []
    lines = ["", "What came closest and was kept out (the last round, largest χ² drop first):", ""]
    for c in tried:
        share = (
            f", {100 * c['delta_chi2'] / (stage['chi2_reduced'] * dof):.0f} % of the misfit"
            if dof
            else ""
        )
        lines.append(f"- **{c['candidate']}** (χ² −{c['delta_chi2']:.3g}{share}): {c['note']}")
    return lines


def _diagnosis_text(report: dict) -> list[str]:
    """What each stage's residual showed (``loop.diagnosis``), as a list."""
    per_stage = report["loop"].get("diagnosis")
    if not per_stage:
        return []
    lines = ["", "What the residual showed (its diagnosis, stage by stage):", ""]
    for st, features in zip(report["loop"]["stages"], per_stage):
        said = "; ".join(f["note"] for f in features) or "nothing beyond the noise"
        # bold: a label "+ effect" at an item's start would open a nested list (two bullets)
        lines.append(f"- **{stage_label(st['added'])}**: {said}")
    return lines


def summary_markdown(
    report: dict, *, figures: Sequence[str] = (), title: str = "", session_path: str | None = None
) -> str:
    """``report.md``: the result in a lab's language, the figures (file names relative to
    the report folder; those of :data:`vibid.report.figures.FIGURES` among them are shown,
    in its order), and a Details section with the optimiser's internals."""
    lines = _header_lines(report, title=title, session_path=session_path)
    lines += _values_lines(report)
    lines += _loop_lines(report)
    lines += _figure_lines(figures)
    lines += _details_lines(report)
    return "\n".join(lines) + "\n"


def _header_lines(report: dict, *, title: str, session_path: str | None) -> list[str]:
    """The title and what was identified from what: the session, the points or steps
    used, the model, the data, whether it converged and the stages left out."""
    ident = report.get("identification", {})
    afc = report["afc"]
    diag = afc.get("diagnostics")
    n_used = len(afc["frequency_hz"])
    lines = [f"# {title or 'Identification report'}", ""]
    lines.append(
        f"- session: `{report['session_id']}`"
        + (f" (`{os.path.basename(session_path)}`)" if session_path else "")
    )
    if diag is not None:
        left_out = [d for d in diag if not d.get("used")]
        lines.append(
            f"- steps used: {n_used} of {len(diag)}"
            + (
                " — left out: "
                + "; ".join(
                    f"{d['commanded_hz']:.4g} Hz ({', '.join(f['name'] for f in d['flags']) or d['status']})"
                    for d in left_out
                )
                if left_out
                else ""
            )
        )
    else:
        lines.append(_points_text(afc["frequency_hz"], report.get("linearity") or ()))
    model = report["model"] + (
        ""
        if report["model"] == report["declared_model"]
        else f" (declared {report['declared_model']})"
    )
    lines.append(f"- model: {model}")
    if ident.get("data") == "magnitude":
        ratio = ident.get("magnitude_only_std_ratio") or {}
        lines.append(
            "- data: **|H| alone** (the phase was not used); each standard deviation "
            "against the complex fit of the same points: "
            + ", ".join(f"{n} ×{r:.2g}" for n, r in ratio.items() if r is not None)
        )
    if ident and not ident.get("converged", True):
        lines.append(f"- **the identification did not converge**: {ident.get('message', '')}")
    lines += [f"- **{line}**" for line in not_done_lines(report)]  # stages left out, and why
    return lines


def _values_lines(report: dict) -> list[str]:
    """The identified values, the engineering constants with their budget, the
    plausibility and the reference specimen."""
    ident = report.get("identification", {})
    lines: list[str] = []
    lines += [
        "",
        "## Identified values (value ± standard deviation)",
        "",
        "| parameter | meaning | value | unit |",
        "|---|---|---|---|",
    ]
    table = quantities(report)
    lines += _param_rows([q for q in table if q.source == "model"])
    if ident.get("model_error_std"):
        lines += [
            "",
            "Each std holds, in quadrature, the fit's noise (the data's Fisher information, "
            "widened by rival minima where there are some) and the discretisation error of "
            "the estimate against a mesh-converged model (Richardson's extrapolation over "
            "three meshes): "
            + ", ".join(
                f"{n} {v:.2g}" for n, v in ident["model_error_std"].items() if v is not None
            )
            + ".",
        ]
    if "engineering" in report:
        lines += [
            "",
            "Engineering constants (from the stiffnesses and the declared thickness):",
            "",
            "| constant | meaning | value | unit |",
            "|---|---|---|---|",
        ]
        lines += _param_rows([q for q in table if q.source == "engineering"])
        lines += _budget_text(
            report["engineering"].get("budget"), ident.get("uncertainty_notes", [])
        )
    lines += _plausibility_text(report.get("plausibility"))
    if "reference" in report:
        lines += [
            "",
            "Reference specimen (it calibrates the clamp: from bending resonances a "
            "modulus trades with the free length as L⁴):",
            "",
            f"- {report['reference']['note']}",
        ]
    return lines


def _loop_lines(report: dict) -> list[str]:
    """The effects the loop found, the odds, the fit quality stage by stage, the
    residual's diagnosis and the linearity of the measured resonances."""
    lines: list[str] = []
    lines += (
        ["", "## Effects the loop found", ""]
        + _effect_text(report)
        + _odds_text(report)
        + _kept_out_text(report)
    )
    lines += [
        "",
        "## Fit quality, stage by stage",
        "",
        "| stage | χ²/dof (the data's std) | χ²/dof (with the model's own error) | "
        "relative RMS residual |",
        "|---|---|---|---|",
    ]
    for st in report["loop"]["stages"]:
        lines.append(
            f"| {stage_label(st['added'])} | "
            f"{chi2_text(st['chi2_reduced'])} | "
            f"{chi2_text(st.get('chi2_reduced_with_model_error'))} | "
            f"{percent_text(st['rel_rms_residual'])} |"
        )
    lines += _diagnosis_text(report)
    if report.get("linearity"):
        lines += ["", "Are the measured resonances linear? (rational fits of the AFC alone):", ""]
        for t in report["linearity"]:
            lo_hi = t.get("left_out_hz")
            lines.append(
                f"- {t['note']}"
                + (
                    ""
                    if lo_hi is None
                    else f" (its top, {lo_hi[0]:.4g}-{lo_hi[1]:.4g} Hz, is left out of the fit)"
                )
            )
    return lines


def _figure_lines(figures: Sequence[str]) -> list[str]:
    """The figures shown, in :data:`vibid.report.figures.FIGURES`' order, and what each
    absent one leaves out."""
    lines: list[str] = []
    if figures:
        lines += ["", "## Figures", ""]
        lines += [
            line
            for fig in report_figures.FIGURES
            if fig.file in figures
            for line in figure_markdown(fig.caption, fig.file)
        ]
        lines += [
            fig.absent for fig in report_figures.FIGURES if fig.file not in figures and fig.absent
        ]
    return lines


def _details_lines(report: dict) -> list[str]:
    """The optimiser's internals: its message, χ², the searches, the bias, the warnings,
    the times and each round of the loop."""
    ident = report.get("identification", {})
    lines: list[str] = []
    lines += ["", "## Details", ""]
    if ident:
        lines.append(f"- optimiser: {ident.get('message', '')}")
        lines.append(
            f"- χ² = {chi2_text(ident.get('chi2'))} over {ident.get('dof')} degrees of "
            "freedom (weights: the data's std and the model's own error);"
            f" χ²/dof with the data's own weights {chi2_text(ident.get('chi2_reduced_data_weights'))}"
        )
        g = ident.get("global_search")
        if g:
            lines.append(
                f"- global search: {len(g['restart_loss'])} restarts, "
                f"{g['evaluations']} model evaluations"
            )
        for r in ident.get("local_runs", [])[:5]:
            lines.append(
                f"- local run {r['method']}: χ² {chi2_text(r['chi2'])}, "
                f"{r['iterations']} iterations, {r['status']}"
            )
        if ident.get("model_error_std"):
            lines.append(
                "- the model's discretisation bias (included in the std): "
                + ", ".join(
                    f"{n} {v:.2g}" for n, v in ident["model_error_std"].items() if v is not None
                )
            )
        for w in ident.get("warnings", []):
            lines.append(f"- warning: {w}")
        if ident.get("seconds") is not None:
            lines.append(
                f"- identification time: {ident['seconds']:.1f} s"
                + (
                    f", loop {report['loop']['seconds']:.1f} s"
                    if report["loop"].get("seconds") is not None
                    else ""
                )
            )
    for rnd, scores in enumerate(report["loop"].get("rounds", []), start=1):
        for sc in scores:
            lines.append(
                f"- loop round {rnd}: {sc['candidate']} score {chi2_text(sc['score'])}"
                f" (p {chi2_text(sc['p_value'])}), Δχ² {chi2_text(sc['delta_chi2'])}"
                f"{', kept' if sc['kept'] else ''}{'; ' + sc['note'] if sc['note'] else ''}"
            )
    return lines
