"""Soak: a day at the simulated stand, adaptive campaigns through faults at random steps (#28, part 4).

    python benchmarks/soak.py [--campaigns 8] [--faults 1] [--seed 0] [--noise 0.03]
                              [--target D=0.0003% nu=0.003%] [--max-stand-time 600]
                              [--batch 8] [--uniform --steps 300] [--json OUT.json]

The paper's steel strip (``examples/strip_setup.json``: 18.75-1500 Hz) on clean virtual
specimens (no undeclared effect). An adaptive campaign on it puts its steps on the
resonances and is done in 20-40 steps, so the long soak is a day's work: ``--campaigns``
adaptive campaigns (``vibid campaign --adaptive``, batches of ``--batch``) one after the
other, each on its own specimen (D, nu, beta drawn 10 % around the example stand's, its own
noise seed) at ``--noise`` per channel, each struck by ``--faults`` of each kind at random
steps of its coarse sweep and first batches (steps 1-19, drawn from the seed:
:func:`vibid.soak.fault_plan`): a generator that stops answering
(``no_reply``), a dropped serial link (``drop``), a knock on the table that overloads the
response channel (``overload``), and SIGKILL of the campaign process (``kill``: ``vibid
campaign --adaptive`` runs as a process, its Prefect flow and all, is killed at a random
instant after it reported the step, and resumed). A fault that ends a run is retried as a
resume, as the campaign flow does. Each soaked session and an uninterrupted run of the same
campaign are identified with the closed loop. ``--uniform`` soaks one long stepped sine of
the setup instead: ``--steps`` frequencies evenly from 18.75 to 1500 Hz, ``--faults`` of
each kind over all of it (``vibid campaign --record-only`` processes).

Prints each run, then per campaign and in total: the faults survived, the steps (in the
file, duplicates), the orphaned processes a killed flow left (removed), the stand time,
chi2/dof, ``unexplained_residual`` and |error|/std of each parameter against the truth for
the soaked and the uninterrupted session. Exit 1 when a check fails
(:class:`vibid.soak.SoakError`) or a fault was not survived.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--campaigns", type=int, default=8, help="adaptive campaigns (default 8)")
    p.add_argument(
        "--faults", type=int, default=1, help="faults of each kind per campaign (default 1)"
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--noise",
        type=float,
        default=None,
        help="each channel's noise relative to the base (default 0.03 adaptive, 4e-4 uniform)",
    )
    p.add_argument("--target", nargs="+", default=["D=0.0003%", "nu=0.003%"])
    p.add_argument("--max-stand-time", type=float, default=600.0)
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--uniform", action="store_true", help="soak one long stepped sine instead")
    p.add_argument("--steps", type=int, default=300, help="--uniform: steps (default 300)")
    p.add_argument("--restarts", type=int, default=2, help="the identification's global restarts")
    p.add_argument("--json", metavar="OUT.json")
    args = p.parse_args(argv)

    logging.getLogger("vibid.acquisition.generator").setLevel(logging.ERROR)  # the lost links
    from vibid.session import load_setup
    from vibid.soak import KINDS, SoakError, SoakOptions, fault_plan, soak

    setup = load_setup(EXAMPLES / "strip_setup.json")
    noise = args.noise if args.noise is not None else (4e-4 if args.uniform else 0.03)
    kinds = [k for k in KINDS if k != "error"]
    base = json.loads((EXAMPLES / "simulated_stand.json").read_text())
    rng = np.random.default_rng(args.seed)
    log = lambda line: print(line, flush=True)  # noqa: E731
    results, t0 = [], time.perf_counter()
    for c in range(1 if args.uniform else args.campaigns):
        doc = json.loads(json.dumps(base))
        params = {
            k: float(v * (1 + 0.1 * rng.uniform(-1, 1)))
            for k, v in doc["simulated"]["params"].items()
        }
        doc["simulated"].update(effects={}, noise=noise, seed=args.seed + c, params=params)
        from vibid.acquisition.stand_config import StandConfig

        config = StandConfig.from_dict(doc)
        adaptive = None
        if args.uniform:
            freqs = tuple(float(f) for f in np.linspace(18.75, 1500.0, args.steps))
            setup = dataclasses.replace(
                setup, excitation=dataclasses.replace(setup.excitation, frequencies_hz=freqs)
            )
            plan = fault_plan(args.steps, {k: args.faults for k in kinds}, seed=args.seed)
        else:
            from vibid.planner.adaptive import AdaptiveOptions
            from vibid.planner.prior import parse_targets

            adaptive = AdaptiveOptions(
                parse_targets(args.target, ("D", "nu", "beta")),
                (18.75, 1500.0),
                args.max_stand_time,
                args.batch,
                seed=args.seed + c,
            )
            plan = fault_plan(24, {k: args.faults for k in kinds}, seed=args.seed + c)
        print(
            f"\n== campaign {c + 1}: {'uniform' if args.uniform else 'adaptive'}, "
            + ", ".join(f"{k} {v:.5g}" for k, v in params.items())
            + f", noise {noise:g}; faults at steps "
            + ", ".join(f"{f.kind}@{f.index}" for f in plan),
            flush=True,
        )
        with tempfile.TemporaryDirectory(prefix="vibid-soak-") as folder:
            try:
                result = soak(
                    setup,
                    config,
                    Path(folder) / "soak.h5",
                    plan,
                    SoakOptions(
                        seed=args.seed + c,
                        reference=True,
                        restarts=args.restarts,
                        log=log,
                        adaptive=adaptive,
                    ),
                )
            except SoakError as exc:
                print(f"soak failed: {exc}", file=sys.stderr)
                return 1
        print(result.summary(), flush=True)
        results.append((plan, result))
    faults = sum(len(p) for p, _ in results)
    survived = sum(r.survived for _, r in results)
    worst = max(
        max(i.error_std().values())
        for _, r in results
        for i in (r.identification, r.reference)
        if i is not None
    )
    print(
        f"\nin all: {len(results)} campaign(s), {sum(r.n_steps for _, r in results)} steps, "
        f"faults survived {survived} of {faults}, duplicates "
        f"{sum(r.duplicates for _, r in results)}, orphaned processes removed "
        f"{sum(r.orphans for _, r in results)}, stand time "
        f"{sum(r.stand_time_s or 0 for _, r in results):.0f} s (without faults "
        f"{sum(r.reference_stand_time_s or 0 for _, r in results):.0f} s), unexplained "
        f"{sum(r.identification.unexplained for _, r in results)} soaked / "
        f"{sum(r.reference.unexplained for _, r in results)} without faults, worst |error|/std "
        f"{worst:.2f}; {time.perf_counter() - t0:.0f} s"
    )
    if args.json:
        out = [
            {
                "faults": [dataclasses.asdict(o) for o in r.outcomes],
                "survived": r.survived,
                "n_steps": r.n_steps,
                "duplicates": r.duplicates,
                "runs": r.runs,
                "orphans": r.orphans,
                "stand_time_s": r.stand_time_s,
                "reference_stand_time_s": r.reference_stand_time_s,
                **{
                    label: {
                        "chi2_dof": i.chi2_dof,
                        "unexplained": i.unexplained,
                        "effects": list(i.effects),
                        "error_std": i.error_std(),
                    }
                    for label, i in (("soaked", r.identification), ("reference", r.reference))
                },
            }
            for _, r in results
        ]
        Path(args.json).write_text(json.dumps(out, indent=1, default=str) + "\n")
    return 0 if survived == faults else 1


if __name__ == "__main__":
    sys.exit(main())
