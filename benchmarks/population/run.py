"""Run the population (benchmarks/population/cases/) through ``vibid identify`` and score it.

    python -m benchmarks.population.run [--half calibration|measured|all]
        [--cases N | --cases NAME,NAME,...] [--timeout S] [--rescore]

Each case runs as ``vibid identify --afc afc.csv --setup setup.json --json report.json
--no-progress`` in its own subprocess (own process group) with a time-out (default 900 s;
a time-out is a recorded failure, its process group killed, never a hang). Every run's
report and a ``run.json`` (status, seconds, return code, stderr tail, the case's digest)
are cached under ``benchmarks/population/results/<case>/`` (gitignored): a rerun resumes,
skipping the cases whose cached run matches the case's digest and vibid's source. The scores
(:mod:`benchmarks.population.score`) go to ``benchmarks/population.json`` and, as a
markdown table, to stdout. ``--rescore`` scores the cache without running anything.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

from benchmarks.population import cases as C
from benchmarks.population import score as S

HERE = pathlib.Path(__file__).resolve().parent
RESULTS = HERE / "results"
OUT_JSON = HERE.parent / "population.json"


def vibid_command():
    exe = pathlib.Path(sys.executable).with_name("vibid")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("vibid")
    return [found] if found else [sys.executable, "-m", "vibid.cli"]


def code_digest() -> str:
    """A hash of every source file of the vibid that runs the cases (found without
    importing it): a cached run of other code is no run of this one."""
    import hashlib
    import importlib.util

    root = pathlib.Path(importlib.util.find_spec("vibid").origin).parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def run_case(name, timeout):
    """Run one case (or take its cached run of the same code); returns its run.json dict."""
    d = C.CASES_DIR / name
    out = RESULTS / name
    out.mkdir(parents=True, exist_ok=True)
    meta_path = out / "run.json"
    digest = C.digest(name)
    code = code_digest()
    if meta_path.exists():
        meta = json.loads(meta_path.read_text())
        done = meta.get("status") in ("ok", "failed") or (
            meta.get("status") == "timeout" and meta.get("timeout_s", 0) >= timeout
        )
        if meta.get("digest") == digest and meta.get("code") == code and done:
            meta["cached"] = True
            return meta
    report = out / "report.json"
    if report.exists():
        report.unlink()
    cmd = vibid_command() + [
        "identify",
        "--afc",
        str(d / "afc.csv"),
        "--setup",
        str(d / "setup.json"),
        "--json",
        str(report),
        "--no-progress",
    ]
    t0 = time.monotonic()
    with open(out / "stdout.txt", "w") as so, open(out / "stderr.txt", "w") as se:
        proc = subprocess.Popen(cmd, stdout=so, stderr=se, start_new_session=True)
        try:
            rc = proc.wait(timeout=timeout)
            status = "ok" if rc == 0 and report.exists() else "failed"
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the case's own process group only
            proc.wait()
            rc, status = None, "timeout"
    seconds = time.monotonic() - t0
    tail = (out / "stderr.txt").read_text()[-2000:]
    meta = {
        "case": name,
        "status": status,
        "returncode": rc,
        "seconds": round(seconds, 2),
        "timeout_s": timeout,
        "digest": digest,
        "code": code,
        "command": cmd,
        "stderr_tail": tail,
    }
    meta_path.write_text(json.dumps(meta, indent=1) + "\n")
    return meta


def select(half, cases_arg):
    split = json.loads((HERE / "split.json").read_text())
    names = (split["calibration"] + split["measured"]) if half == "all" else split[half]
    names = sorted(names)
    if cases_arg:
        if cases_arg.isdigit():
            names = names[: int(cases_arg)]
        else:
            want = cases_arg.split(",")
            names = [n for n in names if n in want or any(n.startswith(w) for w in want)]
    return split, names


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--half", choices=("calibration", "measured", "all"), default="all")
    ap.add_argument("--cases", help="the first N cases of the half, or names (prefixes)")
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--rescore", action="store_true", help="score the cache, run nothing")
    args = ap.parse_args(argv)
    from benchmarks.population.oracle import cached_oracle  # (oracle imports this module)

    split, names = select(args.half, args.cases)
    rows = []
    for i, name in enumerate(names):
        if args.rescore:
            p = RESULTS / name / "run.json"
            if not p.exists():
                continue
            meta = json.loads(p.read_text())
        else:
            meta = run_case(name, args.timeout)
            print(
                f"[{i + 1}/{len(names)}] {name}: {meta['status']} {meta['seconds']:.0f} s"
                + (" (cached)" if meta.get("cached") else ""),
                file=sys.stderr,
                flush=True,
            )
        truth = json.loads((C.CASES_DIR / name / "truth.json").read_text())
        rp = RESULTS / name / "report.json"
        report = json.loads(rp.read_text()) if meta["status"] == "ok" and rp.exists() else None
        rows.append(S.score_case(truth, report, meta, cached_oracle(name)))
    halves = {
        h: [r for r in rows if r["case"] in set(split[h])] for h in ("calibration", "measured")
    }
    summary = {h: S.summarise(rs) for h, rs in halves.items() if rs}
    if args.half == "all":
        summary["all"] = S.summarise(rows)
    doc = {
        "format": "vibid.population_benchmark",
        "version": 1,
        "equivalences": S.EQUIVALENCES,
        "summary": summary,
        "cases": rows,
    }
    OUT_JSON.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    print(S.markdown(summary, rows))


if __name__ == "__main__":
    main()
