"""`vibid identify SESSION.h5 --json REPORT.json [--no-loop] [--candidates A,B]`: signal
stage, identification of the declared model, then the closed loop (effects the residual asks
for, :mod:`vibid.identify.loop`); writes the report of shared/spec/report-format.md.

`vibid identify --afc AFC.csv --setup SETUP.json [...]` does the same on an AFC measured by
another system (:mod:`vibid.signal.imported`)."""

from __future__ import annotations


def add_parser(sub):
    p = sub.add_parser(
        "identify",
        help="identify the declared model's parameters from a session",
        description="Fit the AFC of every step, then identify the parameters of the declared "
        "material model (global search over setup.identification.bounds, then a local polish) "
        "with their standard deviations.",
    )
    p.add_argument("session", metavar="SESSION.h5", nargs="?", help="the session file")
    p.add_argument("--afc", metavar="AFC.csv",
                   help="an AFC measured elsewhere (columns frequency_hz, re, im[, std]) "
                   "instead of a session; needs --setup")
    p.add_argument("--setup", metavar="SETUP.json", help="the declared setup of --afc")
    p.add_argument("--json", metavar="REPORT.json", help="write the report here")
    p.add_argument("--method", choices=("global", "local"), default="global",
                   help="global search then polish (default), or a local run from the box centre")
    p.add_argument("--local", choices=("newton", "bfgs", "lm"), default="newton",
                   help="local method (default: trust-region Newton, exact Hessian)")
    p.add_argument("--restarts", type=int, default=5, help="restarts of the global search")
    p.add_argument("--seed", type=int, default=0, help="seed of the global search")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-loop", action="store_true",
                   help="fit the declared model only (no search for missing effects)")
    p.add_argument("--candidates", metavar="A,B",
                   help="limit the closed loop's candidates (effect names, anisotropy)")
    p.set_defaults(run=run)


def run(args) -> int:
    from vibid.cli.paths import check_output_file
    from vibid.cli.progress import search_progress
    from vibid.errors import VibidError
    from vibid.identify import configure
    from vibid.identify.fit import identify
    from vibid.report import build_report, write_report

    if args.restarts < 1:
        raise VibidError("--restarts must be at least 1")
    if args.json:
        check_output_file(args.json, overwrite=True)  # before the minutes of identification
    setup, session_id, afc = _source(args)
    candidates = None
    if args.candidates:
        from vibid.identify.loop import all_candidates

        candidates = [c.strip() for c in args.candidates.split(",") if c.strip()]
        known = {c.name for c in all_candidates()}
        if unknown := sorted(set(candidates) - known):
            raise VibidError(f"--candidates: unknown {', '.join(unknown)}; expected some of "
                             f"{', '.join(sorted(known))}")
    configure()
    with search_progress(not args.no_progress) as progress:
        result = identify(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                          method=args.method, local=args.local, restarts=args.restarts,
                          seed=args.seed, progress=progress)
    loop = None
    if not args.no_loop and result.converged and afc.std is None:
        print("no loop: the AFC has no std column, so the residual cannot be tested against "
              "the noise")
    elif not args.no_loop and result.converged:
        from vibid.identify.loop import close_loop

        loop = close_loop(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                          candidates=candidates, local=args.local, declared=result)
        result = loop.final
        print(loop.summary())
    else:
        print(result.summary())
    if args.json:
        report = build_report(result, session_id=session_id,
                              declared_model=setup.identification.model,
                              afc=afc.to_report_block(), loop=loop, setup=setup)
        write_report(report, args.json)
        print(f"report written to {args.json}")
    if not result.converged:
        # the report is written (it says why); the job itself failed
        raise VibidError(f"the identification did not converge: {result.message}")
    return 0


def _source(args):
    """(setup, session_id, AFC) from a session file, or from --afc and --setup."""
    from vibid.errors import VibidError

    if args.afc is None:
        if args.session is None:
            raise VibidError("give a session file, or --afc AFC.csv with --setup SETUP.json")
        if args.setup is not None:
            raise VibidError("--setup goes with --afc; a session file holds its own setup")
        from vibid.session import read_session

        with read_session(args.session) as s:
            setup, session_id = s.setup, s.session_id
            afc = _signal_stage(s)
        if afc is None:
            raise VibidError("the signal stage (vibid.signal.afc_from_session) is not available")
        return setup, session_id, afc
    if args.session is not None:
        raise VibidError("give either a session file or --afc, not both")
    if args.setup is None:
        raise VibidError("--afc needs --setup SETUP.json (the declared specimen and sensor)")
    from vibid.cli.modes import load_setup
    from vibid.signal.imported import read_afc_csv

    afc = read_afc_csv(args.afc)
    return load_setup(args.setup), afc.session_id, afc


def _signal_stage(session):
    try:
        from vibid.signal import afc_from_session
    except ImportError:
        return None
    return afc_from_session(session)
