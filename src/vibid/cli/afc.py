"""`vibid afc` (placeholder until its issue lands)."""

from vibid.errors import VibidError


def add_parser(sub):
    p = sub.add_parser("afc", help="(not yet available)")
    p.set_defaults(run=run)


def run(args) -> int:
    raise VibidError("'vibid afc' is not implemented yet")
