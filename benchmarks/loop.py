"""The closed loop on sessions with an undeclared effect: found or not, the error before and
after, and what the loop costs beside the declared fit alone.

    python benchmarks/loop.py [--json OUT.json] [--cases delay,clamp|strip|beam|table2|all]
                              [--steps 200] [--cold] [--warm] [--busy] [--profile]

Cases (``benchmarks/loop_cases.py``):

* the eight strip cases (``--cases strip``): a session of the paper's strip on the virtual
  stand (the full FE model on the "fine" mesh, `vibid simulate`'s code) with one or two
  effects that the declared setup does not name;
* the beam cases (``--cases beam``): the exact beam of ``tests/beam_reference.py`` (a model
  vibid did not write), clean, with a stand resonance, and with a stand resonance and an
  elastic clamp, every default candidate in play; and ``ritz-sensor``, the independent Ritz
  plate of ``tests/ritz_plate.py`` with its sensor 3 mm off the declared centre line;
* ``plate``: a 150 x 100 x 2 mm CFRP plate, orthotropic in the data (E1/E2 = 5), declared
  isotropic, 120 steps to 800 Hz; the loop should add ``anisotropy``;
* ``titanium``: the real AFC of ``../shared/data/real-titanium`` (11 960 points), read as
  ``vibid identify --afc afc.csv --setup setup.json`` reads it; no truth: the row shows the
  effects found, chi2_red and E, nu before and after ("ok" = the loop finished). The
  costly one: 17.2 s declared and 54 s of loop, four effects (BENCHMARKS.md, "The loop on
  the real strips");
  ``steel``: the steel strip of the same stand (``examples/real-steel``, 9 503 points),
  read the same way, 17.5 s and 53 s before the loop kept its gain (`62bcbe4`; 148 s
  through `vibid identify` since, 59 s once its first resonance's top, which depends on
  its amplitude, is left out: `8bccaf7`);
* ``table2`` (``table2-<noise>-<f_max>`` one row): the 12 rows of the paper's Table 2 as
  ``benchmarks/paper_table.py`` defines them; nothing to find (the noiseless rows have no
  std, so the loop cannot test them and returns at once). About 3 min of declared fits for
  the 12 rows (paper_table.py's figures) plus each f_max's forward model, built once.

``--cases all`` (the default) runs all of them, one after the other.

For each case the data are made first (not timed: the stand's part), then three stages are
timed side by side in one run, each with :func:`vibid.identify.engine.profile.recording` (wall
seconds, JAX compilations and their seconds): the signal stage (a session's harmonic fits;
for the titanium CSV, reading the AFC and its setup as ``vibid identify`` does; none for a
Table 2 row, whose data and forward model are built beforehand as paper_table.py does),
the declared identification (``identify``), and the loop from it (its scoring and refits
only). "s declared" is the signal stage plus the declared identification (the issue's
figure); "s signal" is printed on its own too. One row per case: the effects found, the
declared parameters' relative error before and after, reduced chi2 before and after, the
seconds and the JAX compilations of the declared fit and of the loop.

``--cold`` runs each case's stages in a fresh Python process with an empty JAX compilation
cache (``VIBID_JAX_CACHE`` set to a new temporary folder): a lab's first run of the day.
``--warm`` runs them once more in a fresh process against the same, now filled, folder (a
cold run comes first to fill it, printed only with ``--cold``). The data are made once, in
this process, so both runs read the same files. Without either flag everything runs in
this process, with the usual cache (``~/.cache/vibid/jax``), and a case reuses what the
cases before it compiled. ``--busy`` runs one CPU-bound process beside the whole run
(paper_table.py's). The JSON rows hold every figure, ``prof.as_dict()`` of each stage and,
with ``--cold``/``--warm``, each run's row and its process's wall seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vibid.identify.engine.runtime import configure  # noqa: E402

# No configure() (JAX, scipy) at import: the session reader's probe process (a fork-server
# child) imports this script as its __main__, once per session read, which would add about
# 3 s of imports to every signal stage that `vibid identify` does not pay. main() and
# analyse() configure (64-bit JAX, the compilation cache, one BLAS thread), as the CLI does.

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from loop_cases import (  # noqa: E402,F401
    CASES,
    MATERIAL,
    TRUTH,
    Case,
    expand,
    get_case,
    prepare,
    signal_stage,
    table2_data,
)


# -- one case's timed stages --------------------------------------------------------------------
def _combined(*profiles) -> dict:
    """Wall seconds, compilations and compile seconds of consecutive stages together."""
    ps = [p for p in profiles if p is not None]
    return {
        "wall_s": sum(p.wall_seconds for p in ps),
        "compilations": sum(p.compilations for p in ps),
        "compile_cache_hits": sum(p.cache_hits for p in ps),
        "compile_s": sum(p.compile_seconds for p in ps),
    }


def _engineering(res, setup) -> dict:
    from vibid.identify.assess.engineering import engineering_constants

    model = getattr(getattr(res, "plate_model", None), "model", None) or res.model
    sp = setup.specimen
    block = engineering_constants(
        model,
        res.parameter_names,
        res.values,
        res.covariance,
        sp.thickness_m,
        sp.thickness_std_m or 0.0,
    )
    return {k: v["value"] for k, v in block.items()}


def analyse(case: Case, source: dict, seed: int) -> dict:
    """The timed stages of one case on its prepared data (:func:`loop_cases.prepare`): the
    signal stage, the declared fit, the loop; the row of the table and the JSON."""
    from vibid.identify.engine.profile import recording
    from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify
    from vibid.identify.loop import close_loop
    from vibid.pipeline import fit_points

    configure()
    seed = case.seed if case.seed is not None else seed
    fm = data = sig = None
    if case.kind == "table2":  # paper_table.py's data and forward model, shared per f_max
        with recording() as data:
            setup, afc, fm = table2_data(case)
    else:
        with recording() as sig:
            setup, afc = signal_stage(case, source)
    used = fit_points(afc)[0]  # as `vibid identify`: a top that slips is left out
    with recording() as ident:
        declared = identify(
            setup,
            Measurement(afc.frequency_hz, afc.H, afc.std, used=used),
            ModelChoice(forward_model=fm),
            SearchOptions(seed=seed),
        )
    with recording() as lp:
        loop = close_loop(
            setup, afc.frequency_hz, afc.H, afc.std, used=used, declared=declared, seed=seed
        )
    final = loop.final
    truth = case.truth_material

    def err(res):
        # relative; absolute for a truth of 0 (the beam's nu)
        return {
            n: res.parameters[n] / v - 1 if v else res.parameters[n]
            for n, v in truth.items()
            if n in res.parameters
        }

    def z(res):
        return {
            n: (res.parameters[n] - v) / res.parameter_std[n]
            if res.parameter_std[n]
            else float("nan")
            for n, v in truth.items()
            if n in res.parameters
        }

    decl = _combined(sig, ident)
    found = list(loop.effects)
    return {
        "case": case.name,
        "kind": case.kind,
        "effects_in_data": case.effects_in_data,
        "expected": None if case.expected is None else list(case.expected),
        "found": found,
        "ok": True if case.expected is None else sorted(found) == sorted(case.expected),
        "unexplained_residual": bool(loop.unexplained_residual),
        "rel_err_before": err(declared),
        "rel_err_after": err(final),
        "z_after": z(final),
        "chi2_red_before": float(declared.chi2_reduced_reported),
        "chi2_red_after": float(final.chi2_reduced_reported),
        "seconds_signal": sig.wall_seconds if sig else 0.0,
        "seconds_identify": ident.wall_seconds,
        "seconds_declared": decl["wall_s"],
        "seconds_loop": lp.wall_seconds,
        "compilations_declared": decl["compilations"],
        "compile_s_declared": decl["compile_s"],
        "compilations_loop": lp.compilations,
        "compile_s_loop": lp.compile_seconds,
        "seconds_data": data.wall_seconds if data else None,
        "profile": {
            "signal": sig.as_dict() if sig else None,
            "identify": ident.as_dict(),
            "loop": lp.as_dict(),
            "data": data.as_dict() if data else None,
        },
        "profile_tables": {
            k: p.table()
            for k, p in (("signal", sig), ("identify", ident), ("loop", lp), ("data", data))
            if p is not None
        },
        "n_points": int(np.asarray(afc.frequency_hz).size),
        "truth": case.truth,
        "params_before": declared.parameters,
        "params_after": final.parameters,
        "engineering_before": _engineering(declared, setup),
        "engineering_after": _engineering(final, setup),
        "declared_message": declared.message,
        "loop_warnings": list(loop.warnings),
    }


def run_case(name: str, steps: int, seed: int) -> dict:
    """One case in this process: its data, then :func:`analyse`."""
    case = get_case(name)
    with tempfile.TemporaryDirectory() as tmp:
        source = prepare(case, tmp, steps, seed)
        return analyse(case, source, seed)


# -- a case in a fresh process (--cold, --warm) -------------------------------------------------
def run_in_process(
    case: Case, source: dict, seed: int, cache_dir: str, workdir: str, label: str
) -> dict:
    """:func:`analyse` in a fresh Python process whose JAX compilation cache is
    ``cache_dir``; its row, plus the process's wall seconds."""
    out = os.path.join(workdir, f"{case.name}-{label}.json")
    log = os.path.join(workdir, f"{case.name}-{label}.log")
    env = dict(os.environ, VIBID_JAX_CACHE=cache_dir)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)  # runtime.py would keep a folder given to JAX
    spec = json.dumps({"case": case.name, "source": source, "seed": seed, "out": out})
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        rc = subprocess.call(
            [sys.executable, os.path.abspath(__file__), "--child", spec],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=fh,
            stderr=fh,
        )
    wall = time.perf_counter() - t0
    if rc != 0 or not os.path.exists(out):
        with open(log) as fh:
            tail = fh.read()[-2000:]
        raise RuntimeError(f"{label} run exited with {rc}:\n{tail}")
    with open(out) as fh:
        row = json.load(fh)
    row["process_s"] = wall
    row["cache_files_after"] = sum(len(fs) for _, _, fs in os.walk(cache_dir))
    return row


def _child(spec: str) -> int:
    s = json.loads(spec)
    row = analyse(get_case(s["case"]), s["source"], s["seed"])
    with open(s["out"], "w") as fh:
        json.dump(row, fh)
    return 0


# -- the table ------------------------------------------------------------------------------------
def _fmt_run(r: dict | None) -> str:
    """A fresh process's seconds (declared + loop) and compilations / of them from disk."""
    if r is None:
        return f"{'-':>8} {'-':>9}"
    p = [r["profile"][k] for k in ("signal", "identify", "loop") if r["profile"][k]]
    comp = f"{sum(x['compilations'] for x in p)}/{sum(x['compile_cache_hits'] for x in p)}"
    return f"{r['seconds_declared'] + r['seconds_loop']:8.1f} {comp:>9}"


def print_row(row: dict, columns: tuple[str, ...], profile: bool) -> None:
    name = row["case"]
    if "error" in row:
        print(f"{name:<16} ERROR: {row['error']}", flush=True)
        return
    b, a = row["rel_err_before"], row["rel_err_after"]
    first = "D" if "D" in a else "D11"
    runs = row.get("runs", {})
    extra = "".join("  " + _fmt_run(runs.get(c)) for c in columns)
    print(
        f"{name:<16} {','.join(row['found']) or '-':<36} {'yes' if row['ok'] else 'NO ':<3} "
        f"{b.get('D', np.nan):12.2e} {a.get(first, np.nan):9.2e} "
        f"{b.get('nu', np.nan):10.2e} {a.get('nu', a.get('D22', np.nan)):9.2e}  "
        f"{row['chi2_red_before']:12.4g} {row['chi2_red_after']:6.3g} "
        f"{row['seconds_declared']:10.1f} {row['seconds_loop']:7.1f} "
        f"{row['seconds_signal']:8.1f} {row['compilations_declared']:9d} "
        f"{row['compilations_loop']:9d}{extra}",
        flush=True,
    )
    if row["kind"] in ("real", "plate"):
        before, after = row["engineering_before"], row["engineering_after"]
        print(f"{'':<16} engineering, declared: {_eng(before)}; final: {_eng(after)}")
    if row["kind"] != "strip":
        for w in row["loop_warnings"]:
            print(f"{'':<16} loop: {w}")
    if profile:
        for stage, table in row["profile_tables"].items():
            print(f"{'':<16} [{stage}] " + table.replace("\n", f"\n{'':<16} "))


def _eng(block: dict) -> str:
    return ", ".join(
        f"{k[:-3]} {v / 1e9:.3g} GPa" if k.endswith("_Pa") else f"{k} {v:.3g}"
        for k, v in block.items()
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", help="write the rows here")
    ap.add_argument(
        "--cases", default="all", help="comma-separated case names or groups (strip, table2, all)"
    )
    ap.add_argument("--steps", type=int, default=200, help="steps of the strip cases' sessions")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--cold",
        action="store_true",
        help="each case in a fresh process with an empty JAX compilation cache",
    )
    ap.add_argument(
        "--warm",
        action="store_true",
        help="each case again in a fresh process with the cache the cold run filled",
    )
    ap.add_argument(
        "--busy",
        action="store_true",
        help="run one CPU-bound process beside the benchmark (killed at the end)",
    )
    ap.add_argument("--profile", action="store_true", help="print each stage's profile table")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    configure()
    if args.child:
        return _child(args.child)
    try:
        names = expand(args.cases)
    except KeyError as exc:
        ap.error(exc.args[0])
    from paper_table import busy_cpu

    with busy_cpu(args.busy):
        return run(args, names)


def run(args, names) -> int:
    columns = tuple(c for c in ("cold", "warm") if getattr(args, c))
    rows = []
    print(
        f"{'case':<16} {'found':<36} ok  {'D err before':>12} {'after':>9} {'nu before':>10} "
        f"{'after':>9}  chi2r before  after   s declared  s loop  s signal  comp decl  comp loop"
        + "".join(f"  {c + ' s':>8} {'comp/disk':>9}" for c in columns),
        flush=True,
    )
    with tempfile.TemporaryDirectory(prefix="vibid-loop-") as work:
        for name in names:
            case, source = get_case(name), {}
            try:
                source = prepare(
                    case, work, args.steps, args.seed, say=lambda s: print(f"  ({s})", flush=True)
                )
                if not columns:
                    row = analyse(case, source, args.seed)
                else:
                    cache = tempfile.mkdtemp(prefix="vibid-jax-cold-")
                    try:
                        runs = {
                            "cold": run_in_process(case, source, args.seed, cache, work, "cold")
                        }
                        if args.warm:
                            runs["warm"] = run_in_process(
                                case, source, args.seed, cache, work, "warm"
                            )
                    finally:
                        shutil.rmtree(cache, ignore_errors=True)
                    row = dict(runs[columns[0]]) | {"runs": runs}
            except Exception as exc:  # one failed case does not end the benchmark
                row = {
                    "case": name,
                    "kind": case.kind,
                    "ok": False,
                    "error": f"{type(exc).__name__}: {exc}",
                }
            if "session" in source:
                _remove(source["session"])
            rows.append(row)
            print_row(row, columns, args.profile)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(
                {
                    "steps": args.steps,
                    "seed": args.seed,
                    "busy": args.busy,
                    "mode": "+".join(columns) or "in-process",
                    "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
                    "rows": rows,
                },
                fh,
                indent=1,
            )
    return 0 if all(r["ok"] for r in rows) else 1


def _remove(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass


if __name__ == "__main__":
    sys.exit(main())
