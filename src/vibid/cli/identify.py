"""`vibid identify SESSION.h5 --json REPORT.json [--report DIR] [--no-loop] [--candidates A,B]
[--magnitude-only]`: signal stage, identification of the declared model, then the closed
loop (effects the residual asks for, :mod:`vibid.identify.loop`); writes the report of
shared/spec/report-format.md, and with ``--report`` a readable report.md with figures.

With ``--reference-E`` the specimen is a reference of known modulus: the report gives the
clamp's effective free length (:mod:`vibid.identify.assess.reference`).

`vibid identify --afc AFC.csv|AFC.uff --setup SETUP.json [...]` does the same on an AFC
measured by another system, CSV or UFF58 (:mod:`vibid.signal.imported`). On such an AFC's
dense grid, the top of a resonance whose response depends on its amplitude is left out of
the fit unless ``--nonlinear-tops`` (:func:`vibid.identify.assess.linearity.linear_part`)."""

from __future__ import annotations

from vibid.cli.options import (
    add_identification_options,
    add_reference_options,
    profiled,
    reference_of,
)


def add_parser(sub):
    p = sub.add_parser(
        "identify",
        help="identify the declared model's parameters from a session",
        description="Fit the AFC of every step, then identify the parameters of the declared "
        "material model (global search over setup.identification.bounds, then a local polish) "
        "with their standard deviations.",
    )
    p.add_argument("session", metavar="SESSION.h5", nargs="?", help="the session file")
    p.add_argument(
        "--afc",
        metavar="AFC.csv|AFC.uff",
        help="an AFC measured elsewhere instead of a session: AFC.csv (columns "
        "frequency_hz, re, im[, std]) or AFC.uff (UFF58; detected by content); "
        "needs --setup",
    )
    p.add_argument("--setup", metavar="SETUP.json", help="the declared setup of --afc")
    p.add_argument("--json", metavar="REPORT.json", help="write the report here")
    p.add_argument(
        "--report",
        metavar="DIR",
        help="also write a readable report.md with PNG figures (and report.json) into DIR",
    )
    add_identification_options(p)
    p.add_argument(
        "--nonlinear-tops",
        action="store_true",
        help="fit the tops of resonances whose response depends on its amplitude "
        "too (by default they are left out: the plate model is linear, and their "
        "flanks hold the structure at small motion)",
    )
    add_reference_options(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def run(args) -> int:
    from vibid.cli.paths import check_output_dir, check_output_file
    from vibid.cli.progress import search_progress
    from vibid.errors import VibidError
    from vibid.pipeline import identify_afc, parse_candidates, require_converged, write_outputs

    if args.restarts < 1:
        raise VibidError("--restarts must be at least 1")
    if args.json:
        check_output_file(args.json, overwrite=True)  # before the minutes of identification
    if args.report:
        check_output_dir(args.report)
    candidates = parse_candidates(args.candidates)
    reference = reference_of(args)
    with profiled(args.profile):
        data = _source(args)
        with search_progress(not args.no_progress) as progress:
            identified = identify_afc(
                data,
                loop=not args.no_loop,
                candidates=candidates,
                method=args.method,
                local=args.local,
                restarts=args.restarts,
                seed=args.seed,
                progress=progress,
                magnitude_only=args.magnitude_only,
                nonlinear_tops=args.nonlinear_tops,
            )
        print(identified.summary)
    from vibid.report import plausibility_lines

    report, paths = write_outputs(
        data,
        identified,
        json_path=args.json,
        report_dir=args.report,
        session_path=args.session,
        reference=reference,
    )
    for line in plausibility_lines(report):  # never silent
        print(line)
    if args.json:
        print(f"report written to {args.json}")
    if args.report:
        print(f"readable report: {paths.get('report.md', paths.get('report.json'))}")
    # the report is written (it says why); the job itself failed
    require_converged(identified)
    return 0


def _source(args):
    """The :class:`~vibid.pipeline.SessionAfc` of a session file, or of --afc and --setup."""
    from vibid.errors import VibidError
    from vibid.pipeline import session_afc

    if args.afc is None:
        if args.session is None:
            raise VibidError(
                "give a session file, or --afc AFC.csv|AFC.uff with --setup SETUP.json"
            )
        if args.setup is not None:
            raise VibidError("--setup goes with --afc; a session file holds its own setup")
        return session_afc(args.session)
    if args.session is not None:
        raise VibidError("give either a session file or --afc, not both")
    if args.setup is None:
        raise VibidError("--afc needs --setup SETUP.json (the declared specimen and sensor)")
    from vibid.pipeline import afc_file

    return afc_file(args.afc, args.setup)
