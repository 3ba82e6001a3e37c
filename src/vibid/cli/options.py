"""Options shared by the commands that identify (``identify``, ``replay``, ``campaign``)."""

from __future__ import annotations

import contextlib


def add_identification_options(p, *, methods: bool = True) -> None:
    """The closed loop's switches and the global search's settings; with ``methods`` also
    the choice of search and local method."""
    p.add_argument("--no-loop", action="store_true",
                   help="fit the declared model only (no search for missing effects)")
    p.add_argument("--candidates", metavar="A,B",
                   help="limit the closed loop's candidates (effect names, anisotropy)")
    p.add_argument("--magnitude-only", action="store_true",
                   help="identify from |H| alone (channels not synchronised, or a phase not "
                   "trusted): weights from each point's std, chi2 on n - p degrees of "
                   "freedom; the loop tries only what |H| can see (no channel delay) and the "
                   "report gives how much each std grows against the complex fit")
    if methods:
        p.add_argument("--method", choices=("global", "local"), default="global",
                       help="global search then polish (default), or a local run from the box "
                       "centre")
        p.add_argument("--local", choices=("newton", "bfgs", "lm"), default="newton",
                       help="local method (default: trust-region Newton, exact Hessian)")
    p.add_argument("--restarts", type=int, default=5, help="restarts of the global search")
    p.add_argument("--seed", type=int, default=0, help="seed of the global search")
    p.add_argument("--profile", action="store_true",
                   help="print where the time went: compiling, reduced bases, searches, "
                   "refits, the signal stage")


def add_reference_options(p) -> None:
    """``--reference-E`` and its std: the specimen is a reference of known modulus, and the
    report gives the clamp's effective free length (:mod:`vibid.identify.reference`)."""
    p.add_argument("--reference-E", metavar="PA", type=float,
                   help="the specimen is a reference of known modulus along its length (E, "
                   "or E1 of an orthotropic plate; Pa): the report gives the clamp's effective "
                   "free length, to declare for the specimens measured in this clamp")
    p.add_argument("--reference-E-std", metavar="PA", type=float, default=0.0,
                   help="the reference modulus's standard uncertainty (Pa; default 0)")


def reference_of(args):
    """The :class:`~vibid.identify.reference.Reference` of ``--reference-E`` (None without
    it); checked before the identification's minutes (a bad one: a one-line error)."""
    from vibid.identify.reference import reference_from

    return reference_from(args.reference_E, args.reference_E_std,
                          names=("--reference-E", "--reference-E-std"))


@contextlib.contextmanager
def profiled(on: bool):
    """With ``on`` (``--profile``), print where the time went when the block ends
    (:mod:`vibid.identify.profile`)."""
    if not on:
        yield
        return
    from vibid.identify.profile import recording

    with recording() as prof:
        yield
    print(prof.table())
