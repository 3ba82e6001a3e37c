"""Stand time for the same certainty: the setup's uniform sweep, the planned test and the
adaptive campaign, side by side (issue #28).

    python benchmarks/stand_time.py [--out DIR]

On the simulated stand (the paper's strip, D 17.97 N·m, ν 0.286, β 0.003, 0.3 % noise per
channel, no undeclared effect): a uniform 120-step sweep 12.5–1500 Hz (settle 0.5 s); then
`vibid plan` told only a prior 10–20 % off the truth (D 20 ± 30 %, ν 0.33 ± 0.05,
β 0.0035 ± 50 %) and, as its targets, the standard uncertainties the uniform sweep reached;
then `vibid campaign --adaptive` with the same targets (no prior: it starts from the setup's
box). The uniform and planned campaigns are recorded (`vibid campaign --record-only`), the
adaptive one runs its flow (`--no-loop`: no undeclared effect here); each session is
identified the same way (`vibid identify --no-loop`). Prints, side by side: steps, stand
time (the session's ``stand_time_s``: settle and record, re-records included), std of D, ν,
β reached, |error| against the truth in std; the wall time of each campaign (the adaptive
one's includes its fits between batches, which are not stand time).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import h5py
import numpy as np

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
PRIOR = ["D=20±30%", "nu=0.33±0.05", "beta=0.0035±50%"]
HERE = os.path.dirname(os.path.abspath(__file__))
VIBID = [sys.executable, "-m", "vibid"]


def _run(args, **kw):
    subprocess.run(VIBID + args, check=True, timeout=1800, **kw)


def _campaign(setup, stand, out, adaptive=None):
    t = time.perf_counter()
    if adaptive is None:
        _run(
            [
                "campaign",
                setup,
                "--stand",
                "simulated",
                "--stand-config",
                stand,
                "--out",
                out + ".h5",
                "--record-only",
            ],
            stdout=subprocess.DEVNULL,
        )
    else:
        _run(
            [
                "campaign",
                setup,
                "--stand",
                "simulated",
                "--stand-config",
                stand,
                "--out",
                out + ".h5",
                "--report",
                out + "-report",
                "--adaptive",
                "--target",
                *adaptive,
                "--no-loop",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    campaign_s = time.perf_counter() - t
    _run(
        ["identify", out + ".h5", "--no-loop", "--no-progress", "--json", out + ".json"],
        stdout=subprocess.DEVNULL,
    )
    report = json.load(open(out + ".json"))
    ident = report["identification"]
    with h5py.File(out + ".h5") as f:
        stand_s, steps = float(f.attrs["stand_time_s"]), len(f["steps"])
    names = ident["parameter_names"]
    return {
        "steps": steps,
        "stand_s": stand_s,
        "names": names,
        "std": np.array([report["parameters"][n]["std"] for n in names]),
        "value": [report["parameters"][n]["value"] for n in names],
        "chi2": ident.get("chi2_reduced_data_weights"),
        "wall_s": campaign_s,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    d = args.out or tempfile.mkdtemp(prefix="stand_time_")
    os.makedirs(d, exist_ok=True)
    setup = json.load(open(os.path.join(HERE, "..", "examples", "strip_setup.json")))
    setup["excitation"] = {"frequencies_hz": [12.5 * k for k in range(1, 121)], "settle_s": 0.5}
    stand = json.load(open(os.path.join(HERE, "..", "examples", "simulated_stand.json")))
    stand["simulated"].update(params=TRUTH, effects={}, noise=0.003)
    paths = {k: os.path.join(d, k + ".json") for k in ("setup", "stand", "planned")}
    json.dump(setup, open(paths["setup"], "w"))
    json.dump(stand, open(paths["stand"], "w"))

    rows = {
        "uniform 120 steps": _campaign(
            paths["setup"], paths["stand"], os.path.join(d, "uniform-run")
        )
    }
    u = rows["uniform 120 steps"]
    targets = [f"{n}={s:.6g}" for n, s in zip(u["names"], u["std"])]
    t = time.perf_counter()
    _run(
        [
            "plan",
            paths["setup"],
            "--target",
            *targets,
            "--prior",
            *PRIOR,
            "--stand-config",
            paths["stand"],
            "--out",
            paths["planned"],
        ]
    )
    plan_s = time.perf_counter() - t
    rows["planned"] = _campaign(paths["planned"], paths["stand"], os.path.join(d, "planned-run"))
    rows["adaptive"] = _campaign(
        paths["setup"], paths["stand"], os.path.join(d, "adaptive-run"), adaptive=targets
    )

    print(f"\ntargets (the uniform sweep's std): {' '.join(targets)}; planning took {plan_s:.1f} s")
    print(
        f"{'':20}{'steps':>6}{'stand time':>12}"
        + "".join(f"{'std ' + n:>12}{'|err|/std':>10}" for n in u["names"])
        + f"{'chi2/dof':>10}{'campaign':>10}"
    )
    for label, r in rows.items():
        cells = ""
        for j, n in enumerate(r["names"]):
            err = abs(r["value"][j] - TRUTH[n]) / r["std"][j]
            cells += f"{r['std'][j]:>12.3g}{err:>10.2f}"
        print(
            f"{label:20}{r['steps']:>6}{r['stand_s']:>10.1f} s{cells}"
            f"{r['chi2'] or float('nan'):>10.3g}{r['wall_s']:>8.1f} s"
        )
    for label in ("planned", "adaptive"):
        ratio = rows[label]["stand_s"] / u["stand_s"]
        worst = max(rows[label]["std"] / u["std"])
        print(f"{label} / uniform: stand time {ratio:.2f}, worst std ratio {worst:.2f}")
    print(f"(files in {d})")


if __name__ == "__main__":
    main()
