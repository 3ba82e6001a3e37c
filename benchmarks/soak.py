"""Soak: a long campaign on the simulated stand through faults at random steps (#28, part 4).

    python benchmarks/soak.py [--steps 300] [--faults 5] [--seed 0] [--noise 0.0004]
                              [--runner vibid.acquisition.campaign:run_campaign]
                              [--cli "campaign --record-only"] [--json OUT.json]

The paper's steel strip (``examples/strip_setup.json``'s specimen and sensors) stepped through
``--steps`` frequencies evenly from 18.75 to 1500 Hz, on a clean virtual specimen (the true
D, nu, beta of ``examples/simulated_stand.json``, no undeclared effect) at ``--noise`` (the
stand configuration's default), with the example stand's drive and settle cap. ``--faults``
of each kind strike at random steps drawn from ``--seed``
(:func:`vibid.hardware_mocks.soak.fault_plan`): a generator that stops answering
(``no_reply``), a dropped serial link (``drop``), a knock on the table that overloads the
response channel (``overload``), and SIGKILL of the campaign process (``kill``: the campaign
runs as ``python -m vibid campaign ... --record-only`` and is killed at a random instant
after it reported the step, then resumed). A fault that ends a run is retried as a resume,
as the campaign flow does. Then the same campaign without faults (the reference), and both
sessions identified with the closed loop.

Prints each run, the faults survived, the steps (in the file, duplicates), the stand time,
chi2/dof, ``unexplained_residual``, |error|/std of each parameter against the truth, for
the soaked and the reference session, and the run time. Exit 1 when a check fails
(:class:`vibid.hardware_mocks.soak.SoakError`) or a fault was not survived.

``--runner`` / ``--cli`` point the soak at another campaign (an adaptive one): the
in-process runner as ``module:function`` with ``run_campaign``'s signature, and the CLI
command and options the killed processes run.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import logging
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _runner(spec: str):
    module, _, name = spec.partition(":")
    return getattr(importlib.import_module(module), name)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--faults", type=int, default=5, help="faults of each kind (default 5)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--noise", type=float, default=4e-4)
    p.add_argument("--restarts", type=int, default=2, help="the identification's global restarts")
    p.add_argument("--runner", default="vibid.acquisition.campaign:run_campaign")
    p.add_argument("--cli", default="campaign --record-only")
    p.add_argument("--json", metavar="OUT.json")
    args = p.parse_args(argv)

    logging.getLogger("vibid.acquisition.generator").setLevel(logging.ERROR)  # the lost links
    from vibid.acquisition.stand_config import StandConfig
    from vibid.hardware_mocks.soak import KINDS, SoakError, fault_plan, soak
    from vibid.session import load_setup

    setup = load_setup(EXAMPLES / "strip_setup.json")
    freqs = tuple(float(f) for f in np.linspace(18.75, 1500.0, args.steps))
    setup = dataclasses.replace(setup, excitation=dataclasses.replace(setup.excitation, frequencies_hz=freqs))
    doc = json.loads((EXAMPLES / "simulated_stand.json").read_text())
    doc["simulated"].update(effects={}, noise=args.noise, seed=args.seed)
    config = StandConfig.from_dict(doc)
    kinds = [k for k in KINDS if k != "error"]
    plan = fault_plan(args.steps, {k: args.faults for k in kinds}, seed=args.seed)
    print(f"{args.steps} steps, 18.75-1500 Hz, noise {args.noise:g}; faults at steps "
          + ", ".join(f"{f.kind}@{f.index}" for f in plan), flush=True)
    with tempfile.TemporaryDirectory(prefix="vibid-soak-") as folder:
        try:
            result = soak(setup, config, Path(folder) / "soak.h5", plan, runner=_runner(args.runner),
                          cli=tuple(args.cli.split()), seed=args.seed, reference=True,
                          restarts=args.restarts, log=lambda line: print(line, flush=True))
        except SoakError as exc:
            print(f"soak failed: {exc}", file=sys.stderr)
            return 1
    print(result.summary())
    if args.json:
        out = {"steps": args.steps, "noise": args.noise, "seed": args.seed,
               "faults": [dataclasses.asdict(o) for o in result.outcomes],
               "survived": result.survived, "n_steps": result.n_steps,
               "duplicates": result.duplicates, "runs": result.runs,
               "stand_time_s": result.stand_time_s,
               "reference_stand_time_s": result.reference_stand_time_s,
               "seconds": result.seconds}
        for label, ident in (("soaked", result.identification), ("reference", result.reference)):
            out[label] = {"chi2_dof": ident.chi2_dof, "unexplained": ident.unexplained,
                          "effects": list(ident.effects), "error_std": ident.error_std(),
                          "seconds": ident.seconds}
        Path(args.json).write_text(json.dumps(out, indent=1, default=str) + "\n")
    return 0 if result.survived == len(plan) else 1


if __name__ == "__main__":
    sys.exit(main())
