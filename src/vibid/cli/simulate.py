"""`vibid simulate SETUP.json --out S.h5 [--params D=17.97 nu=0.286 beta=0.003]
[--effect channel_delay:tau_s=2e-5 ...] [--noise 0.003] [--seed N]`: a whole session from
the virtual stand. ``--effect stand_resonance:f_hz=660,q=30,theta_rad_per_m=0.3`` given
twice puts two resonances of the stand into the data.

The virtual specimen is the full FE model of the declared plate plus any effect of the
library (:mod:`vibid.identify.effects`), which goes into the data and nowhere into the
file's declared setup; the truth goes to a sidecar ``S.truth.json``. ``--noise`` is each
channel's noise standard deviation relative to the base acceleration amplitude. No
real-time waiting.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path

from vibid.errors import VibidError


def add_parser(sub):
    p = sub.add_parser(
        "simulate",
        help="record a session on the virtual stand",
        description=__doc__.split("\n\n")[1],
    )
    p.add_argument("setup", metavar="SETUP.json", help="the declared setup (with excitation)")
    p.add_argument("--out", required=True, metavar="S.h5", help="the session file to write")
    p.add_argument(
        "--params",
        nargs="+",
        metavar="NAME=VALUE",
        help="the plate's true material parameters (default: the middle of the setup's bounds)",
    )
    p.add_argument(
        "--effect",
        nargs="+",
        default=[],
        metavar="NAME:PARAM=VALUE",
        help="effects in the data, e.g. channel_delay:tau_s=2e-5 or "
        "transverse_shear (an effect without parameters)",
    )
    p.add_argument(
        "--noise",
        type=float,
        default=0.0004,
        help="noise std of each channel relative to the base amplitude (default 0.0004)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the noise")
    p.set_defaults(run=run)


def _effects(items, scale=None) -> tuple[dict[str, float], tuple[str, ...]]:
    """The effects' parameter values, and every effect's name (a bare name for an effect
    without parameters, e.g. ``transverse_shear``). An effect that may occur more than once
    (``stand_resonance``) takes one item per instance, its parameters unsuffixed; the k-th
    item's become ``f_hz_k``, ... (report format). Each value is checked against its
    parameter's rule and, with ``scale`` (:func:`vibid.parameters.specimen_scale`), its
    physical limit; every error names ``--effect`` and the effect."""
    from vibid.cli.options import check_values, parse_values
    from vibid.identify.effects import EFFECTS
    from vibid.parameters import flat_values

    given: dict[str, list[dict]] = {}
    for item in items:
        name, sep, rest = item.partition(":")
        if name not in EFFECTS:
            raise VibidError(
                f"--effect: unknown effect {name!r}, expected one of {', '.join(EFFECTS)}"
            )
        option = f"--effect {name}"
        values = parse_values(rest.split(","), option) if sep else {}
        check_values(values, option, scale)
        given.setdefault(name, []).append(values)
    out = {}
    for name, instances in given.items():
        try:
            out |= flat_values(name, instances)
        except ValueError as exc:
            raise VibidError(f"--effect {name}: {exc}") from None
    return out, tuple(given)


def run(args) -> int:
    from vibid.cli.modes import load_setup
    from vibid.cli.options import check_values, parse_values
    from vibid.cli.paths import check_output_file
    from vibid.hardware_mocks.simulated_session import StandConditions, simulate_session
    from vibid.identify import configure
    from vibid.identify.model.plate import plate_model_for
    from vibid.parameters import specimen_scale

    if not (math.isfinite(args.noise) and args.noise >= 0):
        raise VibidError("--noise must be zero or positive")
    out = Path(args.out)
    sidecar = out.with_name(out.stem + ".truth.json")
    check_output_file(args.out, overwrite=False)  # before the FE model is built and solved
    check_output_file(sidecar, overwrite=True)
    setup = load_setup(args.setup)
    if setup.excitation is None:
        raise VibidError(f"{args.setup}: the setup has no excitation to play")
    scale = specimen_scale(setup)
    if args.params:
        params = parse_values(args.params, "--params")
        check_values(params, "--params", scale)
    else:
        params = {
            n: math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
            for n, (lo, hi) in setup.identification.bounds.items()
            if n in setup.identification.parameter_names
        }
    values, effects = _effects(args.effect, scale)
    if twice := sorted(set(params) & set(values)):
        raise VibidError(
            f"{', '.join(twice)}: given by --params and by --effect; give each value once"
        )
    truth = params | values
    plate_model_for(truth, effects)  # every name known, one-line error otherwise
    configure()
    base = StandConditions()
    conditions = dataclasses.replace(
        base, noise_std_m_s2=(args.noise * base.base_amplitude_m_s2,) * 2
    )
    from vibid.cli.progress import search_progress

    with search_progress(sys.stderr.isatty()) as progress:
        simulate_session(
            out,
            setup,
            truth,
            conditions=conditions,
            seed=args.seed,
            effects=effects,
            progress=progress,
        )
    sidecar.write_text(
        json.dumps(
            {"parameters": truth, "effects": list(effects), "noise": args.noise, "seed": args.seed},
            indent=1,
        )
        + "\n"
    )
    print(f"{out}: {len(setup.excitation.frequencies_hz)} steps; truth in {sidecar}")
    return 0
