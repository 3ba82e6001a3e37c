"""`vibid validate SESSION.h5 ...`: check session files against the format, one line each."""

from __future__ import annotations

import sys


def add_parser(sub) -> None:
    p = sub.add_parser(
        "validate",
        help="check session files against the session format",
        description="Check session files against shared/spec/session-format.md. A valid file "
        "prints one summary line; an invalid one prints one line per problem, as "
        "'FILE: /path/in/file: what is wrong' (a path with no file: one line on stderr). "
        "Exit 0 if all are valid, 1 otherwise.",
    )
    p.add_argument("sessions", nargs="+", metavar="SESSION.h5", help="session file(s)")
    p.set_defaults(run=run)


def run(args) -> int:
    from vibid.session import file_problems, read_session
    from vibid.session.validate import no_file

    status = 0
    for path in args.sessions:
        if (missing := no_file(path)) is not None:  # bad input, not a file's problem
            status = 1
            print(f"vibid validate: {path}: {missing}", file=sys.stderr)
            continue
        problems = file_problems(path)
        if problems:
            status = 1
            for problem in problems:
                print(f"{path}: {problem}")
            continue
        with read_session(path) as s:
            print(f"{path}: {summary(s)}")
    return status


def summary(session) -> str:
    """One line: steps, their statuses, the frequency range, the declared model and how the
    run ended."""
    freqs = session.frequencies_hz()
    statuses = session.statuses()
    n = len(statuses)
    counts = ", ".join(
        f"{statuses.count(k)} {k}" for k in ("ok", "overload", "aborted") if statuses.count(k)
    )
    span = f"{freqs.min():g}-{freqs.max():g} Hz" if n else "no frequencies"
    return (
        f"valid session, {n} step{'s' if n != 1 else ''}"
        f"{' (' + counts + ')' if counts else ''}, {span}, "
        f"declared model {session.setup.identification.model}, run {session.run_status}"
        f"{' (' + session.run_status_reason + ')' if session.run_status_reason else ''}"
    )
