"""The population benchmark's scores, from each case's truth.json and vibid's report.json.

Per half: recall (the true library effects named), false additions (the share of cases
with at least one effect added that is neither required nor tolerated), coverage (the
truth within 2 reported std, per identified constant), clean cases untouched (no effect
added), out-of-library cases honest (``loop.unexplained_residual`` true, D within 1 % and
nu within 5 %), and the time per case; where the report has them, ``loop.criterion`` and
``loop.stages[].alternatives`` are collected.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter

#: How the named effects are counted against the truth (also written into population.json).
EQUIVALENCES = [
    (
        "clamp_loss (a clamp whose spring dissipates otherwise than the plate) counts as named "
        "only when clamp_compliance and clamp_loss were both added; clamp_compliance counts as "
        "named whether or not clamp_loss came with it"
    ),
    (
        "clamp_loss is tolerated (no false addition) wherever the truth has a clamp spring: its "
        "null is the plate's beta, and a lossless clamp (beta_clamp = 0) that the data cannot "
        "tell from a clamp of the plate's loss names it optional"
    ),
    ("anisotropy counts as named when the report's final model is orthotropic"),
    (
        "stand_resonance and fixture_resonance count per instance (a second instance where the "
        "truth has one is a false addition)"
    ),
    (
        "free_length and clamp_compliance are NOT equivalent, nor added_mass and sensor_inertia, "
        "nor sensor_gain and channel_delay"
    ),
]

#: How much better, in BIC (chi2 + p ln 2N), the oracle fit (:mod:`oracle`: vibid's model
#: with the truth's effects, fitted from the truth) must be than the loop's final model for
#: a wrong case to count as the loop's search missing a better explanation: "strong" on
#: Kass & Raftery's (1995) scale; short of it the data do not prefer the truth.
STRONG_BIC = 6.0

#: nu's tolerance for an out-of-library case: 5 % of the truth's nu
NU_REL = 0.05
D_REL = 0.01


def added_effects(report) -> list[str]:
    names = [e["name"] for e in report.get("effects", [])]
    if (
        report.get("model") == "orthotropic"
        and report.get("declared_model") == "isotropic"
        and "anisotropy" not in names
    ):
        names.append("anisotropy")
    return names


def _param(report, name):
    p = report.get("parameters", {}).get(name)
    if p is None:
        p = report.get("engineering", {}).get(name)
    if p is None or p.get("value") is None:
        return None, None
    return p["value"], p.get("std")


def coverage(truth, report) -> dict:
    """Per constant of the truth's material model: True/False (within 2 std) or None (the
    report has no such constant: a model that is not the truth's)."""
    mat, eng = truth["material"], truth["engineering"]
    want = dict(mat) | {k: v for k, v in eng.items() if k.endswith("_Pa")}
    out = {}
    for k, v in want.items():
        val, sd = _param(report, k)
        if val is None or sd is None or not math.isfinite(sd):
            out[k] = None
            continue
        out[k] = bool(abs(val - v) <= 2 * sd)
    return out


def miss_kind(truth, report, oracle) -> str | None:
    """Why a wrong library case is wrong (:data:`STRONG_BIC`): ``"search"`` (the oracle
    fits strongly better: the library held a better explanation the loop did not reach)
    or ``"data"`` (it does not: the data do not prefer the truth over the loop's answer);
    None without an oracle fit or a final stage."""
    stages = report.get("loop", {}).get("stages", [])
    if not oracle or not stages or not math.isfinite(oracle.get("chi2_reduced", math.nan)):
        return None
    n = 2 * truth["n_points"]
    p_loop = len(report.get("parameters", {}))
    p_oracle = len(oracle["parameters"])
    bic_loop = stages[-1]["chi2_reduced"] * (n - p_loop) + p_loop * math.log(n)
    bic_oracle = oracle["chi2_reduced"] * (n - p_oracle) + p_oracle * math.log(n)
    return "search" if bic_loop - bic_oracle > STRONG_BIC else "data"


def score_case(truth, report, meta, oracle=None) -> dict:
    row = {
        "case": truth["name"],
        "kind": truth["kind"],
        "grid": truth["grid"],
        "status": meta["status"],
        "seconds": meta["seconds"],
        "required": truth["required"],
        "optional": truth["optional"],
        "out_of_library": sorted(truth.get("out_of_library", {})),
        "clean": not truth["required"] and not truth.get("out_of_library"),
    }
    if report is None:
        row.update(
            added=None,
            named=[],
            missed=list(truth["required"]),
            false=None,
            coverage={},
            honest=None,
        )
        return row
    added = added_effects(report)
    req = Counter(truth["required"])
    got = Counter(added)
    named, missed = [], []
    for name, n in req.items():
        k = got[name]
        if name == "clamp_loss":
            k = min(k, got["clamp_compliance"])
        named += [name] * min(n, k)
        missed += [name] * max(0, n - k)
    tolerated = set(truth["optional"])
    extra = got - req
    false = sorted(n for n in extra.elements() if n not in tolerated)
    loop = report.get("loop", {})
    row.update(
        added=added,
        named=named,
        missed=missed,
        false=false,
        unexplained_residual=loop.get("unexplained_residual"),
        oracle_chi2_reduced=(oracle or {}).get("chi2_reduced"),
        miss_kind=(
            miss_kind(truth, report, oracle)
            if (missed or false) and not truth.get("out_of_library")
            else None
        ),
        chi2_reduced=[s.get("chi2_reduced") for s in loop.get("stages", [])],
        coverage=coverage(truth, report),
        values={k: _param(report, k)[0] for k in truth["material"]},
        stds={k: _param(report, k)[1] for k in truth["material"]},
    )
    if loop.get("criterion"):
        crit = loop["criterion"]
        row["criterion"] = crit.get("name") if isinstance(crit, dict) else str(crit)
    alts = [s.get("alternatives") for s in loop.get("stages", []) if s.get("alternatives")]
    if alts:
        row["alternatives"] = alts
    if row["out_of_library"]:
        mat = truth["material"]
        dname = "D" if "D" in mat else "D11"
        d, _ = _param(report, dname)
        nu, _ = _param(report, "nu")
        ok_d = d is not None and abs(d / mat[dname] - 1) <= D_REL
        ok_nu = "nu" not in mat or (nu is not None and abs(nu - mat["nu"]) <= NU_REL * mat["nu"])
        row["honest"] = bool(loop.get("unexplained_residual")) and ok_d and ok_nu
        row["honest_parts"] = {
            "unexplained_residual": loop.get("unexplained_residual"),
            "D_within_1pct": ok_d,
            "nu_within_5pct": ok_nu,
        }
    else:
        row["honest"] = None
    return row


def _share(xs):
    xs = [x for x in xs if x is not None]
    return (sum(map(bool, xs)) / len(xs), len(xs)) if xs else (None, 0)


def summarise(rows) -> dict:
    done = [r for r in rows if r["status"] == "ok"]
    lib = [r for r in done if r["required"]]
    n_req = sum(len(r["required"]) for r in lib)
    n_named = sum(len(r["named"]) for r in lib)
    per_effect = {}
    for r in lib:
        for n in r["required"]:
            per_effect.setdefault(n, [0, 0])[1] += 1
        for n in r["named"]:
            per_effect[n][0] += 1
    cov = {}
    for r in done:
        if r["out_of_library"]:
            continue
        for k, v in r["coverage"].items():
            cov.setdefault(k, []).append(v)
    secs = [r["seconds"] for r in rows if r["seconds"] is not None]
    clean = [r for r in done if r["clean"]]
    ool = [r for r in done if r["out_of_library"]]
    return {
        "cases": len(rows),
        "ran": len(done),
        "failures": {s: sum(r["status"] == s for r in rows) for s in ("failed", "timeout")},
        "recall": None if not n_req else n_named / n_req,
        "recall_counts": [n_named, n_req],
        "recall_per_effect": {k: f"{a}/{b}" for k, (a, b) in sorted(per_effect.items())},
        "false_additions": _share([bool(r["false"]) for r in done])[0],
        "false_addition_cases": sum(bool(r["false"]) for r in done),
        "coverage": {
            k: {"share": _share(v)[0], "n": _share(v)[1], "missing": sum(x is None for x in v)}
            for k, v in sorted(cov.items())
        },
        "clean_untouched": _share([not r["added"] for r in clean])[0],
        "clean_counts": [sum(not r["added"] for r in clean), len(clean)],
        "out_of_library_honest": _share([r["honest"] for r in ool])[0],
        "out_of_library_counts": [sum(bool(r["honest"]) for r in ool), len(ool)],
        "seconds_median": statistics.median(secs) if secs else None,
        "seconds_max": max(secs) if secs else None,
        "criterion": sorted({r["criterion"] for r in done if r.get("criterion")}),
        "cases_with_alternatives": sum("alternatives" in r for r in done),
        "wrong_cases_by_kind": dict(
            Counter(r.get("miss_kind") or "no oracle" for r in lib if r["missed"] or r["false"])
        ),
    }


def _fmt(x, pct=True):
    if x is None:
        return "-"
    return f"{100 * x:.0f} %" if pct else f"{x:.0f}"


def _oracle_cell(r) -> str:
    x = r.get("oracle_chi2_reduced")
    if x is None or not math.isfinite(x):
        return "-"
    return f"{x:.3g}" + (f" ({r['miss_kind']})" if r.get("miss_kind") else "")


def markdown(summary, rows) -> str:
    halves = list(summary)
    lines = ["| | " + " | ".join(halves) + " |", "|---|" + "---|" * len(halves)]

    def line(label, fn):
        lines.append(f"| {label} | " + " | ".join(fn(summary[h]) for h in halves) + " |")

    line(
        "cases (ran / failed / timed out)",
        lambda s: (
            f"{s['ran']}/{s['failures']['failed']}/{s['failures']['timeout']} of {s['cases']}"
        ),
    )
    line(
        "recall (true effects named)",
        lambda s: f"{_fmt(s['recall'])} ({s['recall_counts'][0]}/{s['recall_counts'][1]})",
    )
    line(
        "false additions (cases)",
        lambda s: f"{_fmt(s['false_additions'])} ({s['false_addition_cases']})",
    )
    line(
        "clean untouched",
        lambda s: f"{_fmt(s['clean_untouched'])} ({s['clean_counts'][0]}/{s['clean_counts'][1]})",
    )
    line(
        "out-of-library honest",
        lambda s: (
            f"{_fmt(s['out_of_library_honest'])} "
            f"({s['out_of_library_counts'][0]}/{s['out_of_library_counts'][1]})"
        ),
    )
    keys = sorted({k for h in halves for k in summary[h]["coverage"]})
    for k in keys:
        line(
            f"coverage {k} (2 std)",
            lambda s, k=k: (
                f"{_fmt(s['coverage'][k]['share'])} (n={s['coverage'][k]['n']})"
                if k in s["coverage"]
                else "-"
            ),
        )
    line(
        "time per case median / max (s)",
        lambda s: f"{_fmt(s['seconds_median'], False)} / {_fmt(s['seconds_max'], False)}",
    )
    line("criterion", lambda s: ", ".join(s["criterion"]) or "-")
    line(
        "wrong library cases: search / data",
        lambda s: " / ".join(str(s["wrong_cases_by_kind"].get(k, 0)) for k in ("search", "data")),
    )
    out = "\n".join(lines)
    per = [
        "",
        "| case | status | s | required | added | missed | false | honest | oracle chi2_red "
        "(why wrong) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        per.append(
            f"| {r['case']} | {r['status']} | {r['seconds']:.0f} | "
            f"{','.join(r['required']) or '-'} | "
            f"{'-' if r['added'] is None else (','.join(r['added']) or 'none')} | "
            f"{','.join(r['missed']) or '-'} | "
            f"{'-' if r['false'] is None else (','.join(r['false']) or '-')} | "
            f"{'-' if r['honest'] is None else r['honest']} | "
            f"{_oracle_cell(r)} |"
        )
    return out + "\n" + "\n".join(per)
