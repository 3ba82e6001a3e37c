"""Cold start of the local run: a fresh process, with and without the compilation cache.

    python benchmarks/cold_start.py [--repeat 2]

The paper's local run (trust-region Newton with the exact Hessian from the paper's start,
noiseless 0-600 Hz data of the strip, as in ``paper_table.py``) in a new Python process,
three ways, side by side: JAX's compilation cache off, on but empty (the first run on a
machine: it compiles and writes), and on and filled (every later run). Prints, per way,
the seconds of the first loss, gradient and Hessian calls (tracing and compiling, or
loading), of the run itself, and their total; the forward model's build (the same in all
three) is printed apart.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

CHILD = r"""
import json, sys, time
sys.path.insert(0, {bench!r})
from paper_table import TRUE, paper_start_problem
from vibid.identify.fit.trust_region import trust_region

t = time.perf_counter()
problem, u0 = paper_start_problem()
build = time.perf_counter() - t
t = time.perf_counter()
problem.chi2(u0); problem.value_and_grad(u0); problem.hessian(u0)
first = time.perf_counter() - t
t = time.perf_counter()
r = trust_region(problem, u0)
run = time.perf_counter() - t
err = max(abs(v / TRUE[k] - 1) for k, v in problem.space.as_dict(r.theta).items())
print(json.dumps({{"build": build, "first_calls": first, "run": run, "max_rel_err": err}}))
"""


def child(cache: str) -> dict:
    env = dict(os.environ, VIBID_JAX_CACHE=cache)
    code = CHILD.format(bench=os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="rounds of the three ways")
    args = ap.parse_args(argv)
    print(
        f"{'way':>18} | {'first calls s':>13} {'run s':>6} {'total s':>7} | "
        f"{'build s':>7} {'max rel err':>11}"
    )
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory() as cache:
            for way, c in (("cache off", "off"), ("cache empty", cache), ("cache filled", cache)):
                r = child(c)
                print(
                    f"{way:>18} | {r['first_calls']:13.2f} {r['run']:6.2f} "
                    f"{r['first_calls'] + r['run']:7.2f} | {r['build']:7.1f} "
                    f"{r['max_rel_err']:11.1e}",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
