"""`vibid identify` (placeholder until its issue lands)."""

from vibid.errors import VibidError


def add_parser(sub):
    p = sub.add_parser("identify", help="(not yet available)")
    p.set_defaults(run=run)


def run(args) -> int:
    raise VibidError("'vibid identify' is not implemented yet")
