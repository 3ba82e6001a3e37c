"""`vibid plan`: the stepped sine that reaches target uncertainties in the least stand time.

    vibid plan SETUP.json --target D=0.1% [nu=0.002 …] [--prior D=17±30% nu=0.3±0.05 …]
               [--band 5:2000] [--stand-config STAND.json] [--noise 4e-4]
               [--max-stand-time 3600] [--magnitude-only] --out PLANNED.json

Writes ``PLANNED.json``: the setup with the planned frequencies and, per step, the settle and
minimum record times (``excitation.settle_s``, ``excitation.record_s`` as lists), which
``vibid campaign PLANNED.json`` plays as they are. Prints the predicted stand time and
standard uncertainties of the plan and of the setup's own sweep side by side
(:mod:`vibid.planner`).
"""

from __future__ import annotations

import math
import os

import numpy as np

from vibid.errors import VibidError


def add_parser(sub):
    p = sub.add_parser(
        "plan",
        help="plan a stepped sine: target uncertainty, least stand time",
        description="Choose frequencies, settle times and record lengths that "
        "reach the target standard uncertainties over the whole prior in the "
        "least stand time.",
    )
    p.add_argument("setup", metavar="SETUP.json", help="the declared setup")
    p.add_argument(
        "--target",
        nargs="+",
        required=True,
        metavar="NAME=STD[%]",
        help="standard uncertainty to reach, relative with %%, e.g. D=0.1%% nu=0.002",
    )
    p.add_argument(
        "--prior",
        nargs="+",
        default=[],
        metavar="NAME=MEAN±STD[%]",
        help="normal priors, e.g. D=17±30%% nu=0.3±0.05 (+- for ±); a parameter "
        "not named is uniform over the setup's bounds",
    )
    p.add_argument(
        "--band", metavar="LOW:HIGH", help="frequency band, Hz (default: the setup's span)"
    )
    p.add_argument(
        "--stand-config",
        metavar="STAND.json",
        help="the stand's timing (record and settle rules); default: the defaults",
    )
    p.add_argument(
        "--noise",
        type=float,
        metavar="REL",
        help="each channel's noise std relative to the base amplitude (default: "
        "the stand configuration's simulated.noise)",
    )
    p.add_argument(
        "--max-stand-time",
        type=float,
        default=3600.0,
        metavar="S",
        help="stop adding steps at this stand time, s (default 3600)",
    )
    p.add_argument("--draws", type=int, default=16, help="prior draws (default 16)")
    p.add_argument("--seed", type=int, default=0, help="seed of the prior draws")
    p.add_argument(
        "--magnitude-only", action="store_true", help="plan for an |H|-only identification"
    )
    p.add_argument(
        "--out", required=True, metavar="PLANNED.json", help="where to write the planned setup"
    )
    p.set_defaults(run=run)


def parse_band(text: str | None):
    if text is None:
        return None
    lo, sep, hi = text.partition(":")
    try:
        band = (float(lo), float(hi))
    except ValueError:
        band = None
    if not sep or band is None or not all(map(math.isfinite, band)):
        raise VibidError(f"--band {text!r}: expected LOW:HIGH in Hz, e.g. 5:2000")
    return band


def check_options(args):
    """Every option of ``vibid plan`` checked before the planning's seconds: the output
    path, the numbers, the setup and stand configuration, the targets, the priors and the
    band. Returns ``(setup, config, targets, priors, band_hz)``; one-line errors."""
    from vibid.acquisition.stand_config import load_stand_config
    from vibid.cli.paths import check_output_file
    from vibid.parameters import MODEL_PARAMETERS
    from vibid.pipeline import read_setup
    from vibid.planner.prior import (
        check_priors_in_box,
        check_stand_time_cap,
        parse_prior,
        parse_targets,
    )

    check_output_file(args.out, overwrite=True)
    if (
        os.path.exists(args.out)
        and os.path.exists(args.setup)
        and os.path.samefile(args.out, args.setup)
    ):
        raise VibidError(f"--out {args.out}: is the setup itself; write the plan to another file")
    check_stand_time_cap(args.max_stand_time)
    if args.noise is not None and not (math.isfinite(args.noise) and args.noise > 0):
        raise VibidError(f"--noise {args.noise!r}: must be a positive number")
    if not args.draws >= 2:
        raise VibidError("--draws: at least 2")
    setup = read_setup(args.setup)
    config = load_stand_config(args.stand_config)
    names = MODEL_PARAMETERS[setup.identification.model]
    targets = parse_targets(args.target, names)
    priors = parse_prior(args.prior, names)
    check_priors_in_box(priors, setup.identification.bounds)
    return setup, config, targets, priors, parse_band(args.band)


def run(args) -> int:
    from vibid.identify.engine.runtime import configure
    from vibid.planner import plan_test, planned_setup

    setup, config, targets, priors, band = check_options(args)
    configure()
    plan = plan_test(
        setup,
        config,
        targets,
        priors=priors,
        band_hz=band,
        noise=args.noise,
        n_draws=args.draws,
        seed=args.seed,
        max_stand_time_s=args.max_stand_time,
        magnitude=args.magnitude_only,
    )
    text = planned_setup(setup, plan).to_json()
    tmp = f"{args.out}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
        os.replace(tmp, args.out)
    except OSError as exc:
        raise VibidError(f"{args.out}: cannot write: {exc.strerror or exc}") from None
    print(comparison(plan))
    if plan.planned.stand_time_s > args.max_stand_time:
        print(
            f"the plan's {plan.planned.stand_time_s:.1f} s of stand time exceed "
            f"--max-stand-time {args.max_stand_time:g} s: the coarse sweep a plan starts "
            "from, and the step that crosses the cap, are kept whole"
        )
    if not plan.reached_design:
        print(
            f"the targets are not reached within {args.max_stand_time:g} s of stand time "
            "in this band: the plan is the best found"
        )
    elif not plan.reached:
        print(
            f"the plan meets the targets at the draws it was chosen on, not at "
            f"{100 * plan.quantile:g} % of others: the prior is too wide for a fixed plan to "
            "find the resonances (narrow the prior, or let `vibid campaign --adaptive` find them)"
        )
    print(
        f"{args.out}: {len(plan.frequencies_hz)} steps; play it with `vibid campaign {args.out} …`"
    )
    return 0


def comparison(plan) -> str:
    """The plan and the setup's sweep side by side: steps, stand time, the median and the
    quantile over prior draws of each parameter's relative standard uncertainty."""
    q = plan.quantile
    head = f"{'':16}{'steps':>6}{'stand time':>12}" + "".join(
        f"{'std ' + n + ' (median / ' + format(q * 100, 'g') + ' %)':>30}" for n in plan.names
    )
    rows = [head]
    for pr in (plan.planned, plan.sweep):
        if pr is None:
            continue
        cells = []
        for j in range(len(plan.names)):
            rel = pr.relative_std(j)
            cells.append(f"{_pct(np.median(rel))} / {_pct(np.quantile(rel, q))}")
        rows.append(
            f"{pr.label:16}{pr.n_steps:>6}{pr.stand_time_s:>10.1f} s"
            + "".join(f"{c:>30}" for c in cells)
        )
    targets = ", ".join(str(t) for t in plan.targets)
    rows.append(
        f"targets {targets}, over {len(plan.planned.draws)} prior draws the plan was "
        "not chosen on; predicted from the model, its error and the noise (re-records "
        "not counted)"
    )
    return "\n".join(rows)


def _pct(x: float) -> str:
    return "inf" if not np.isfinite(x) else f"{x * 100:.3g} %"
