"""`vibid identify SESSION.h5 --json REPORT.json`: signal stage, then identification of the
declared model; writes the report of shared/spec/report-format.md (one loop stage)."""

from __future__ import annotations


def add_parser(sub):
    p = sub.add_parser(
        "identify",
        help="identify the declared model's parameters from a session",
        description="Fit the AFC of every step, then identify the parameters of the declared "
        "material model (global search over setup.identification.bounds, then a local polish) "
        "with their standard deviations.",
    )
    p.add_argument("session", metavar="SESSION.h5", help="the session file")
    p.add_argument("--json", metavar="REPORT.json", help="write the report here")
    p.add_argument("--method", choices=("global", "local"), default="global",
                   help="global search then polish (default), or a local run from the box centre")
    p.add_argument("--local", choices=("newton", "bfgs", "lm"), default="newton",
                   help="local method (default: trust-region Newton, exact Hessian)")
    p.add_argument("--restarts", type=int, default=5, help="restarts of the global search")
    p.add_argument("--seed", type=int, default=0, help="seed of the global search")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=run)


def run(args) -> int:
    from vibid.cli.progress import search_progress
    from vibid.errors import VibidError
    from vibid.identify import configure
    from vibid.identify.fit import identify
    from vibid.report import build_report, write_report
    from vibid.session import read_session

    if args.restarts < 1:
        raise VibidError("--restarts must be at least 1")
    with read_session(args.session) as s:
        setup, session_id = s.setup, s.session_id
        afc = _signal_stage(s)
    if afc is None:
        raise VibidError("the signal stage (vibid.signal.afc_from_session) is not available")
    configure()
    with search_progress(not args.no_progress) as progress:
        result = identify(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                          method=args.method, local=args.local, restarts=args.restarts,
                          seed=args.seed, progress=progress)
    print(result.summary())
    if args.json:
        report = build_report(result, session_id=session_id,
                              declared_model=setup.identification.model,
                              afc=afc.to_report_block())
        write_report(report, args.json)
        print(f"report written to {args.json}")
    if not result.converged:
        # the report is written (it says why); the job itself failed
        raise VibidError(f"the identification did not converge: {result.message}")
    return 0


def _signal_stage(session):
    try:
        from vibid.signal import afc_from_session
    except ImportError:
        return None
    return afc_from_session(session)
