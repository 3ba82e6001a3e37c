"""`vibid replay SESSION.h5 [--json REPORT.json] [--report DIR] [--uff AFC.uff] [--no-loop]
[--candidates A,B] [--magnitude-only] [--reference-E PA]`:
``vibid identify`` run as a Prefect flow (:func:`vibid.flows.replay_flow`): the same options
and the same JSON report, plus in ``--report DIR`` a readable ``report.md`` with PNG figures,
and the summary as Prefect artifacts.

With no configuration the flow runs on Prefect's embedded temporary server (started for the
run); with ``PREFECT_API_URL`` set, on that server, where the run and its artifacts stay.
"""

from __future__ import annotations

from vibid.cli.options import (
    add_identification_options,
    add_reference_options,
    profiled,
    reference_of,
)


def add_parser(sub):
    p = sub.add_parser(
        "replay",
        help="identify a recorded session as a Prefect flow, with a readable report",
        description=__doc__.split("\n\n")[0].replace("`", ""),
    )
    p.add_argument("session", metavar="SESSION.h5", help="the session file")
    p.add_argument("--json", metavar="REPORT.json", help="write the JSON report here")
    p.add_argument(
        "--report",
        metavar="DIR",
        help="write report.md, report.json and the PNG figures into this folder",
    )
    p.add_argument(
        "--uff",
        metavar="AFC.uff",
        help="also write the AFC the identification uses as UFF58 (as vibid afc --uff)",
    )
    add_identification_options(p)
    add_reference_options(p)
    p.set_defaults(run=run)


def run(args) -> int:
    import os

    from vibid.errors import VibidError
    from vibid.pipeline import parse_candidates

    if args.restarts < 1:
        raise VibidError("--restarts must be at least 1")
    candidates = parse_candidates(args.candidates)
    reference_of(args)  # a bad reference: one line, before Prefect starts
    if args.uff:
        from vibid.cli.paths import check_output_file

        check_output_file(args.uff, overwrite=True)
    if not os.path.isfile(args.session):
        raise VibidError(f"{args.session}: no such file")
    from vibid.session import read_session

    with read_session(args.session):  # a file that is no session: one line, before Prefect starts
        pass
    from vibid.flows import replay_flow
    from vibid.flows.server import tie_temporary_server

    tie_temporary_server()  # a replay killed outright leaves no Prefect server behind
    with profiled(args.profile):
        report = replay_flow(
            args.session,
            json_path=args.json,
            report_dir=args.report,
            uff_path=args.uff,
            loop=not args.no_loop,
            candidates=None if candidates is None else list(candidates),
            method=args.method,
            local=args.local,
            restarts=args.restarts,
            seed=args.seed,
            magnitude_only=args.magnitude_only,
            reference_E_pa=args.reference_E,
            reference_E_std_pa=args.reference_E_std,
        )
    from vibid.report import plausibility_lines

    for line in plausibility_lines(report):  # never silent
        print(line)
    if args.json:
        print(f"report written to {args.json}")
    if args.report:
        md = os.path.join(args.report, "report.md")  # absent where it could not be made
        shown = md if os.path.exists(md) else os.path.join(args.report, "report.json")
        print(f"readable report: {shown}")
    return 0
