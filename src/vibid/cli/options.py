"""Options shared by the commands: the identification's (``identify``, ``replay``,
``campaign``), and the readers of ``NAME=VALUE`` lists and plain numbers, which refuse in
one line (:class:`~vibid.errors.VibidError`) whatever is not what it says: a value that is
not a finite number, a name given twice, a value no specimen can have."""

from __future__ import annotations

import contextlib
import math
import re

from vibid.errors import VibidError

#: A parameter's name in ``NAME=VALUE``: letters, digits and underscores.
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def parse_number(text: str, what: str) -> float:
    """``text`` as a finite number (``what`` names it in the one-line error): no nan, no
    inf, no overflow to inf (``1e999``)."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise VibidError(f"{what} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise VibidError(f"{what} must be a finite number, got {text!r}")
    return value


def parse_values(items, option: str) -> dict[str, float]:
    """``["D=17.97", "nu=0.3"]`` -> ``{"D": 17.97, "nu": 0.3}``; one-line errors naming
    ``option`` (e.g. ``"--params"``) for an item that is not ``NAME=VALUE``, a value that is
    not a finite number and a name given twice (never the last one silently)."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not _NAME.fullmatch(name):
            raise VibidError(f"{option}: expected NAME=VALUE, got {item!r}")
        if name in out:
            raise VibidError(f"{option}: {name} is given twice")
        out[name] = parse_number(value, f"{option}: {name}")
    return out


def check_values(values: dict[str, float], option: str, scale=None) -> None:
    """Refuse, naming ``option``, a value its parameter cannot take (the catalogue's rule
    and, with ``scale`` from :func:`vibid.parameters.specimen_scale`, its physical limit:
    :meth:`vibid.parameters.Parameter.value_problem`); names not in the catalogue are left
    to the model, which says which it does not know."""
    from vibid.parameters import known_parameter

    for name, x in values.items():
        q = known_parameter(name)
        if q is not None and (problem := q.value_problem(x, scale)):
            raise VibidError(f"{option}: {problem}")


def add_identification_options(p, *, methods: bool = True) -> None:
    """The closed loop's switches and the global search's settings; with ``methods`` also
    the choice of search and local method."""
    p.add_argument(
        "--no-loop",
        action="store_true",
        help="fit the declared model only (no search for missing effects)",
    )
    p.add_argument(
        "--candidates",
        metavar="A,B",
        help="limit the closed loop's candidates (effect names, anisotropy)",
    )
    p.add_argument(
        "--magnitude-only",
        action="store_true",
        help="identify from |H| alone (channels not synchronised, or a phase not "
        "trusted): weights from each point's std, chi2 on n - p degrees of "
        "freedom; the loop tries only what |H| can see (no channel delay) and the "
        "report gives how much each std grows against the complex fit",
    )
    if methods:
        p.add_argument(
            "--method",
            choices=("global", "local"),
            default="global",
            help="global search then polish (default), or a local run from the box centre",
        )
        p.add_argument(
            "--local",
            choices=("newton", "bfgs", "lm"),
            default="newton",
            help="local method (default: trust-region Newton, exact Hessian)",
        )
    p.add_argument("--restarts", type=int, default=5, help="restarts of the global search")
    p.add_argument("--seed", type=int, default=0, help="seed of the global search")
    p.add_argument(
        "--profile",
        action="store_true",
        help="print where the time went: compiling, reduced bases, searches, "
        "refits, the signal stage",
    )


def add_reference_options(p) -> None:
    """``--reference-E`` and its std: the specimen is a reference of known modulus, and the
    report gives the clamp's effective free length (:mod:`vibid.identify.assess.reference`)."""
    p.add_argument(
        "--reference-E",
        metavar="PA",
        type=float,
        help="the specimen is a reference of known modulus along its length (E, "
        "or E1 of an orthotropic plate; Pa): the report gives the clamp's effective "
        "free length, to declare for the specimens measured in this clamp",
    )
    p.add_argument(
        "--reference-E-std",
        metavar="PA",
        type=float,
        default=0.0,
        help="the reference modulus's standard uncertainty (Pa; default 0)",
    )


def reference_of(args):
    """The :class:`~vibid.identify.assess.reference.Reference` of ``--reference-E`` (None without
    it); checked before the identification's minutes (a bad one: a one-line error)."""
    from vibid.identify.assess.reference import reference_from

    return reference_from(
        args.reference_E, args.reference_E_std, names=("--reference-E", "--reference-E-std")
    )


@contextlib.contextmanager
def profiled(on: bool):
    """With ``on`` (``--profile``), print where the time went when the block ends
    (:mod:`vibid.identify.engine.profile`)."""
    if not on:
        yield
        return
    from vibid.identify.engine.profile import recording

    with recording() as prof:
        yield
    print(prof.table())
