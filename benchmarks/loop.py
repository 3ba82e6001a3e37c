"""The closed loop on sessions with an undeclared effect: found or not, the error before and
after, and what the loop costs beside the declared fit alone.

    python benchmarks/loop.py [--json OUT.json] [--cases delay,clamp] [--steps 200]

Each case records a session of the paper's strip on the virtual stand (the full FE model on
the "fine" mesh, `vibid simulate`'s code) with one or two effects that the declared setup
does not name, runs the signal stage, then the declared fit alone and the loop from it
(timed side by side in one run), and prints one row per case: the effects found, the
declared parameters' relative error before and after, reduced chi2 before and after, and
the seconds of the declared fit and of the loop (the loop's scoring and refits only).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from vibid.identify.runtime import configure  # noqa: E402
from vibid.setup_model import example_setup  # noqa: E402

configure()

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
#: case -> (effects in the data, what the loop should add)
CASES = {
    "clean": ({}, ()),
    "delay": ({"tau_s": 2e-5}, ("channel_delay",)),
    "gain": ({"gain": 1.02}, ("sensor_gain",)),
    "clamp": ({"k_theta_N_per_rad": 1.6e4}, ("clamp_compliance",)),
    "mass": ({"mass_kg": 3e-4}, ("added_mass",)),
    "alpha": ({"alpha": 0.3}, ("frequency_dependent_loss",)),
    "delay+clamp": ({"tau_s": 2e-5, "k_theta_N_per_rad": 1.6e4},
                    ("channel_delay", "clamp_compliance")),
    # an orthotropic strip, D11 / D22 = 10, declared isotropic
    "anisotropy": ({"D11": 17.97, "D12": 0.54, "D22": 1.797, "D66": 1.2}, ("anisotropy",)),
}
MATERIAL = ("D", "nu", "D11", "D12", "D22", "D66")


def run_case(name: str, steps: int, seed: int) -> dict:
    from vibid.hardware_mocks.simulated_session import simulate_session
    from vibid.identify.fit import identify
    from vibid.identify.loop import close_loop
    from vibid.session import read_session
    from vibid.signal import afc_from_session

    effects, expected = CASES[name]
    s = example_setup()
    freqs = tuple(np.linspace(1500.0 / steps, 1500.0, steps))
    setup = dataclasses.replace(s, excitation=dataclasses.replace(s.excitation,
                                                                  frequencies_hz=freqs))
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "s.h5")
        truth = ({k: v for k, v in TRUTH.items() if k not in ("D", "nu")} if "D11" in effects
                 else dict(TRUTH)) | effects
        simulate_session(path, setup, truth, seed=seed)
        with read_session(path) as r:
            afc = afc_from_session(r)
    t0 = time.perf_counter()
    declared = identify(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used, seed=seed)
    t1 = time.perf_counter()
    loop = close_loop(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                      declared=declared, seed=seed)
    t2 = time.perf_counter()
    final = loop.final

    truth_material = {k: v for k, v in truth.items() if k in MATERIAL or k == "beta"}

    def err(res):
        return {n: res.parameters[n] / v - 1 for n, v in truth_material.items()
                if n in res.parameters}

    def z(res):
        return {n: (res.parameters[n] - v) / res.parameter_std[n]
                for n, v in truth_material.items() if n in res.parameters}

    return {"case": name, "effects_in_data": effects, "expected": list(expected),
            "found": list(loop.effects), "ok": sorted(loop.effects) == sorted(expected),
            "unexplained_residual": loop.unexplained_residual,
            "rel_err_before": err(declared), "rel_err_after": err(final),
            "z_after": z(final), "chi2_red_before": declared.chi2_reduced,
            "chi2_red_after": final.chi2_reduced, "seconds_declared": t1 - t0,
            "seconds_loop": t2 - t1}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", help="write the rows here")
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    rows = []
    print(f"{'case':<12} {'found':<36} ok  {'D err before':>12} {'after':>9} {'nu before':>10} "
          f"{'after':>9}  chi2r before  after   s declared  s loop")
    for name in args.cases.split(","):
        row = run_case(name, args.steps, args.seed)
        rows.append(row)
        b, a = row["rel_err_before"], row["rel_err_after"]
        first = "D" if "D" in a else "D11"
        print(f"{name:<12} {','.join(row['found']) or '-':<36} {'yes' if row['ok'] else 'NO ':<3} "
              f"{b.get('D', np.nan):12.2e} {a.get(first, np.nan):9.2e} "
              f"{b.get('nu', np.nan):10.2e} {a.get('nu', a.get('D22', np.nan)):9.2e}  "
              f"{row['chi2_red_before']:12.4g} {row['chi2_red_after']:6.3g} "
              f"{row['seconds_declared']:10.1f} {row['seconds_loop']:7.1f}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"steps": args.steps, "seed": args.seed, "rows": rows}, fh, indent=1)
    return 0 if all(r["ok"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
