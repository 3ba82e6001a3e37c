"""The ``vibid`` command line.

Each sub-command lives in its own module of this package with two functions:
``add_parser(subparsers)`` declares its arguments (cheaply: no heavy imports), and
``run(args) -> int`` does the work. Exit codes: 0 success, 1 bad input or a failed job,
2 usage error (argparse's own). A :class:`~vibid.errors.VibidError` becomes one line on
stderr; any other exception too (``--debug`` shows the traceback instead).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# Small dense problems (the reduced plate model) run far faster on one BLAS thread than on
# threads fighting over two shared cores; set before numpy loads. A user's own setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from vibid import __version__
from vibid.errors import VibidError

#: Sub-command modules, in the order ``vibid --help`` lists them.
COMMANDS = ("plan", "campaign", "simulate", "validate", "afc", "modes", "identify", "replay",
            "devices")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="vibid",
        description="Stepped-sine vibration tests of thin plates: record, fit the AFC, "
        "identify the bending stiffness.",
    )
    parser.add_argument("--version", action="version", version=f"vibid {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"vibid.cli.{name}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except VibidError as exc:
        if args.debug:
            raise
        print(f"vibid {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"vibid {args.command}: interrupted", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - the contract is: never a traceback
        if args.debug:
            raise
        print(
            f"vibid {args.command}: internal error: {type(exc).__name__}: {exc} "
            "(run with --debug for the traceback)",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
