"""Stress: whole `vibid identify` runs of the closed loop on sessions that take the reduced
model's direct path (a lossy clamp, a stand resonance), both thread settings, beside a
CPU-bound process; hangs counted.

Issue 62: 3 loop runs in about 25 hung for good inside jaxlib (two batched complex
triangular solves side by side on XLA's two-thread pool). This runs fresh processes, as a
lab does, alternating ``VIBID_THREADS=1`` and ``2``, each on its own simulated session
(its own seed and effects), with a busy loop holding one core throughout. A run counts as
hung when the watchdog ends it (``--stall-timeout``, its stacks kept) or when it passes
the benchmark's own limit; the rounds and refits of each run's loop are counted from the
loop's result (a wrapper in the child process, nothing changed in vibid).

    python benchmarks/stress_hang.py --out /tmp/stress   # 20 runs and 200 rounds at least

It prints one line per run and a table (runs, rounds, refits, hangs, median and longest
wall time) for BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: Effects of the sessions, in turn: each takes the direct path (clamp_loss) or rocks the
#: base (stand_resonance), with the paper strip's sizes the examples use.
CLAMP = ["clamp_compliance:k_theta_N_per_rad=16000", "clamp_loss:beta_clamp=0.05"]
STAND = ["stand_resonance:f_hz=660,q=30,theta_rad_per_m=0.3"]
CASES = [STAND + CLAMP, CLAMP + ["channel_delay:tau_s=2e-5"], CLAMP]
#: The loop scores these (every round refits each): the sessions' effects and one that is
#: not in them, so that a round both finds and rejects; the others cost time, not paths.
CANDIDATES = "clamp_compliance,clamp_loss,stand_resonance,channel_delay,sensor_gain"

#: The child: vibid's own entry point, with the loop's result counted on the side.
CHILD = """
import json, sys
import vibid.identify.loop as loop
close_loop = loop.close_loop

def counted(*args, **kwargs):
    result = close_loop(*args, **kwargs)
    with open(sys.argv[1], "w") as f:
        json.dump({"rounds": len(result.rounds),
                   "refits": sum(len(r) for r in result.rounds),
                   "found": list(result.effects)}, f)
    return result

loop.close_loop = counted
from vibid.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _busy(stop):
    """A CPU-bound process beside vibid, as on a lab PC."""
    while not stop.is_set():
        sum(i * i for i in range(10000))


def _setup(folder: Path, steps: int) -> Path:
    setup = json.loads((REPO / "examples/strip_setup.json").read_text())
    f = setup["excitation"]["frequencies_hz"]
    setup["excitation"]["frequencies_hz"] = f[:: max(1, len(f) // steps)]
    path = folder / "setup.json"
    path.write_text(json.dumps(setup))
    return path


def one_run(
    i: int, folder: Path, setup: Path, threads: str, stall_s: float, limit_s: float, candidates: str
) -> dict:
    effects = CASES[i % len(CASES)]
    session = folder / f"s{i:03d}.h5"
    env = dict(os.environ, VIBID_THREADS=threads)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "vibid",
            "simulate",
            str(setup),
            "--out",
            str(session),
            "--effect",
            *effects,
            "--seed",
            str(i),
        ],
        check=True,
        capture_output=True,
        env=env,
        timeout=limit_s,
    )
    counts = folder / f"s{i:03d}.loop.json"
    report = folder / f"s{i:03d}-report"
    cmd = [
        sys.executable,
        "-c",
        CHILD,
        str(counts),
        "--stall-timeout",
        str(stall_s),
        "identify",
        str(session),
        "--json",
        str(folder / f"s{i:03d}.json"),
        "--report",
        str(report),
        "--candidates",
        candidates,
    ]
    t0 = time.monotonic()
    try:
        done = subprocess.run(
            cmd, capture_output=True, text=True, env=env, timeout=limit_s, check=False
        )
        rc, err = done.returncode, done.stderr
    except subprocess.TimeoutExpired:
        rc, err = "timeout", ""
    wall = time.monotonic() - t0
    hung = rc == "timeout" or "no progress for" in err
    row = {
        "run": i,
        "threads": threads,
        "effects": [e.split(":")[0] for e in effects],
        "rc": rc,
        "hung": hung,
        "wall_s": round(wall, 1),
    }
    if counts.exists():
        row.update(json.loads(counts.read_text()))
    if rc not in (0, "timeout") and not hung:
        row["error"] = err.strip().splitlines()[-1][:200] if err.strip() else ""
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20, help="at least this many runs")
    ap.add_argument(
        "--rounds",
        type=int,
        default=200,
        help="and on until the loops have played this many rounds",
    )
    ap.add_argument("--steps", type=int, default=20, help="steps of each session")
    ap.add_argument(
        "--candidates",
        default=CANDIDATES,
        help="the loop's candidates (default: the effects of the sessions and the sensor's gain)",
    )
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--stall-timeout", type=float, default=300.0)
    ap.add_argument("--limit", type=float, default=1800.0, help="seconds a run may take")
    ap.add_argument("--no-busy", action="store_true", help="no CPU-bound process beside")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    setup = _setup(args.out, args.steps)
    stop = multiprocessing.Event()
    busy = None if args.no_busy else multiprocessing.Process(target=_busy, args=(stop,))
    if busy is not None:
        busy.start()
    rows = []
    try:
        i = 0
        while i < args.runs or sum(r.get("rounds", 0) for r in rows) < args.rounds:
            row = one_run(
                i,
                args.out,
                setup,
                "1" if i % 2 else "2",
                args.stall_timeout,
                args.limit,
                args.candidates,
            )
            i += 1
            rows.append(row)
            print(json.dumps(row), flush=True)
            with open(args.out / "runs.jsonl", "a") as f:
                f.write(json.dumps(row) + "\n")
    finally:
        stop.set()
        if busy is not None:
            busy.join(5)
    walls = [r["wall_s"] for r in rows]
    summary = {
        "runs": len(rows),
        "rounds": sum(r.get("rounds", 0) for r in rows),
        "refits": sum(r.get("refits", 0) for r in rows),
        "hangs": sum(r["hung"] for r in rows),
        "failed": sum(1 for r in rows if r["rc"] not in (0,) and not r["hung"]),
        "median_s": statistics.median(walls),
        "longest_s": max(walls),
        "busy_process": busy is not None,
    }
    print(json.dumps(summary))
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    return 0 if summary["hangs"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
