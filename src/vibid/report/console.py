"""What the console says at the end of a job, from the JSON report: the identified values
(:func:`vibid.report.values.quantities`), the effects found, χ²/dof before and after, and
never silence about a constant no material allows."""

from __future__ import annotations

from vibid.not_done import not_done_lines
from vibid.report.values import chi2_text, quantities


def console_summary(report: dict) -> str:
    """A few lines for the console at the end of a job: the identified values with std and
    units, the effects the loop found (with their values), χ²/dof before and after."""
    from vibid.identify.effects import meaning_of

    stages = report["loop"]["stages"]
    lines = ["identified (value ± std):"]
    for q in quantities(report):
        if q.source == "engineering":
            continue
        lines.append(
            f"  {q.name:<20} {q.reading}" + ("" if q.source == "model" else f"   ({q.source})")
        )
    names = [e["name"] for e in report["effects"]]
    if names:
        lines.append("effects found: " + ", ".join(f"{n} ({meaning_of(n)})" for n in names))
    elif report["loop"]["unexplained_residual"]:
        lines.append(
            "effects found: none, and the residual is above the noise (unexplained_residual)"
        )
    else:
        lines.append("effects found: none needed (the declared model fits to the noise level)")
    lines.append(
        f"chi2/dof: {chi2_text(stages[0]['chi2_reduced'])} (declared model) -> "
        f"{chi2_text(stages[-1]['chi2_reduced'])} (final)"
    )
    lines += plausibility_lines(report)
    return "\n".join(lines)


def plausibility_lines(report: dict) -> list[str]:
    """The report's plausibility findings for the console: never silent about a constant
    no material allows or one outside its material's handbook range; then what a
    reference specimen says of the clamp (:mod:`vibid.identify.assess.reference`); then, one line
    each, the stages the report could not do (:func:`vibid.not_done.not_done_lines`)."""
    pl = report.get("plausibility") or {}
    return (
        [f"NOT PHYSICAL: {v}" for v in pl.get("violations", [])]
        + [f"implausible: {v}" for v in pl.get("outside_handbook", [])]
        + ([report["reference"]["note"]] if "reference" in report else [])
        + not_done_lines(report)
    )
