"""The ``vibid`` command line.

Each sub-command lives in its own module of this package with two functions:
``add_parser(subparsers)`` declares its arguments (cheaply: no heavy imports), and
``run(args) -> int`` does the work. Exit codes: 0 success, 1 bad input or a failed job,
2 usage error (argparse's own). A :class:`~vibid.errors.VibidError` becomes one line on
stderr; any other exception too (``--debug`` shows the traceback instead).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import sys

# Small dense problems (the reduced plate model) run far faster on one BLAS thread than on
# threads fighting over two shared cores; set before numpy loads. A user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from vibid import __version__, heartbeat
from vibid.errors import VibidError

#: Sub-command modules, in the order ``vibid --help`` lists them.
COMMANDS = (
    "plan",
    "campaign",
    "simulate",
    "validate",
    "afc",
    "modes",
    "identify",
    "replay",
    "devices",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="vibid",
        description="Stepped-sine vibration tests of thin plates: record, fit the AFC, "
        "identify the bending stiffness.",
    )
    parser.add_argument("--version", action="version", version=f"vibid {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    parser.add_argument(
        "--stall-timeout",
        metavar="S",
        default=None,
        help="end the command, with every thread's Python stack written "
        "beside the report, when its computation makes no progress for S "
        f"seconds (default $VIBID_STALL_TIMEOUT_S or "
        f"{heartbeat.DEFAULT_LIMIT_S:g}; 0: never)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"vibid.cli.{name}").add_parser(sub)
    return parser


#: Commands that only compute: the whole command is one stage of the watchdog's. A campaign
#: is not (its acquisition has the instruments' own time-outs, and its generator must be
#: switched off by its own code), only its identification's stages are.
COMPUTING = ("plan", "afc", "modes", "identify", "replay")


def stall_folder(args) -> str:
    """Where the watchdog writes the stacks: the command's report folder, else its JSON
    report's or output's folder, else the working folder."""
    for name in ("report", "json", "out"):
        value = getattr(args, name, None)
        if value:
            return str(value) if name == "report" else os.path.dirname(str(value)) or "."
    return "."


def one_line(text: object) -> str:
    """``text`` on one line: its lines (every break ``str.splitlines`` knows, ``\\r`` and
    ``\\u2028`` too) joined by ``"; "``, blank ones dropped. The backstop of the rule that an
    error is one line, whatever message an exception carries."""
    return "; ".join(part.strip() for part in str(text).splitlines() if part.strip())


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        limit = heartbeat.limit_from(args.stall_timeout)
    except ValueError as exc:
        parser.error(f"--stall-timeout: {exc}")
    watchdog = heartbeat.Watchdog(limit, lambda: stall_folder(args), f"vibid {args.command}")
    try:
        with (
            watchdog,
            (
                heartbeat.stage(args.command)
                if args.command in COMPUTING
                else contextlib.nullcontext()
            ),
        ):
            return int(args.run(args) or 0)
    except VibidError as exc:
        if args.debug:
            raise
        print(f"vibid {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"vibid {args.command}: interrupted", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - the contract is: never a traceback
        if args.debug:
            raise
        print(
            f"vibid {args.command}: internal error: {type(exc).__name__}: {one_line(exc)} "
            "(run with --debug for the traceback)",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
