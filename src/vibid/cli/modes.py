"""`vibid modes`: natural frequencies and decay factors of the declared plate.

    vibid modes SETUP.json|SESSION.h5 --params D=17.97 nu=0.286 beta=0.003 [--n 6]
                [--accuracy default] [--json OUT.json]

The material model follows from the parameter names (``D nu beta``: isotropic;
``D11 D12 D22 D66 beta``: orthotropic; plus ``D16 D26``: monoclinic; ``beta11`` ... for one
loss factor per modulus); any effect's parameters add that effect (e.g.
``k_theta_N_per_rad=16000``: an elastic clamp). Prints a table; ``--json`` writes
``{"frequency_hz": [...], "decay_1_per_s": [...]}``.
"""

from __future__ import annotations

import json
from pathlib import Path

from vibid.errors import VibidError


def add_parser(sub):
    p = sub.add_parser(
        "modes",
        help="natural frequencies and decay factors of the plate",
        description="Natural frequencies and decay factors of the declared "
        "plate with its sensor (full FE model, complex eigenproblem).",
    )
    p.add_argument(
        "source", metavar="SETUP.json|SESSION.h5", help="a setup JSON document or a session file"
    )
    p.add_argument(
        "--params",
        nargs="+",
        required=True,
        metavar="NAME=VALUE",
        help="model parameters, e.g. D=17.97 nu=0.286 beta=0.003 (D in N·m); an "
        "effect's parameters add it, e.g. k_theta_N_per_rad=16000",
    )
    p.add_argument("--n", type=int, default=6, help="number of modes (default 6)")
    p.add_argument(
        "--accuracy",
        default="default",
        choices=("fast", "default", "fine"),
        help="discretisation preset (default: default)",
    )
    p.add_argument("--json", metavar="OUT.json", help="also write the results as JSON")
    p.set_defaults(run=run)


def load_setup(path: str):
    """The declared setup of a setup JSON file or a session file."""
    from vibid.setup_model import parse_setup

    p = Path(path)
    if not p.is_file():
        raise VibidError(f"{path}: no such file")
    if p.suffix.lower() in (".h5", ".hdf5"):
        try:
            from vibid.session import read_session
        except ImportError:
            raise VibidError(
                "reading session files needs vibid.session, which is not available"
            ) from None
        with read_session(p) as s:
            return s.setup
    try:
        return parse_setup(p.read_text())
    except UnicodeDecodeError:
        raise VibidError(f"{path}: not a text file (a setup JSON or a .h5 session)") from None


def run(args) -> int:
    if args.n < 1:
        raise VibidError("--n must be at least 1")
    from vibid.cli.options import check_values, parse_values
    from vibid.parameters import specimen_scale

    # the readers `vibid simulate` uses: a name given twice, a value that is no finite
    # number, one its parameter's rule or the declared specimen rules out: one line each
    params = parse_values(args.params, "--params")
    setup = load_setup(args.source)
    check_values(params, "--params", specimen_scale(setup))
    from vibid.identify import configure
    from vibid.identify.model.plate import natural_frequencies, plate_model_for

    plate_model_for(params)  # every name known and the model complete, one line otherwise
    configure()
    freq, decay = natural_frequencies(setup, params, args.n, accuracy=args.accuracy)
    print(f"{'mode':>4}  {'frequency_hz':>14}  {'decay_1_per_s':>14}")
    for k, (f, g) in enumerate(zip(freq, decay), start=1):
        print(f"{k:>4}  {f:>14.4f}  {g:>14.6f}")
    if args.json:
        doc = {"frequency_hz": [float(f) for f in freq], "decay_1_per_s": [float(g) for g in decay]}
        try:
            Path(args.json).write_text(json.dumps(doc, indent=2) + "\n")
        except OSError as exc:
            raise VibidError(f"{args.json}: cannot write ({exc.strerror})") from None
    return 0
