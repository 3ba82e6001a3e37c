"""What the session file must hold after each campaign run and at the end: every step
reported done, each once, in the expected order; ``complete`` at the end."""

from __future__ import annotations

import os

import numpy as np

from vibid.errors import VibidError


class SoakError(VibidError):
    """A soak check failed (one line: which, at which step)."""


def run_status(out) -> str | None:
    """The session's ``run_status``."""
    from vibid.session import read_session

    with read_session(out) as s:
        return s.run_status


def steps_in(out, want, reported) -> int:
    """The file's step count, after checking that its steps are ``want``'s first ones (None:
    an adaptive campaign's, whatever they are) and that every step reported done is among
    them."""
    if not os.path.exists(out):
        if reported:
            raise SoakError(f"steps {sorted(set(reported))[:5]}... reported, but no session file")
        return 0
    from vibid.session import file_problems, read_session

    problems = file_problems(out)
    if problems:
        raise SoakError(f"{out}: {problems[0]}")
    with read_session(out) as s:
        got = np.asarray(s.frequencies_hz(), float)
    n = got.size
    if want is not None and (n > want.size or not np.array_equal(got, want[:n])):
        bad = next(i for i in range(n) if i >= want.size or got[i] != want[i])
        raise SoakError(
            f"step {bad} of the file is {got[bad]:g} Hz, not the setup's step "
            f"{bad} (each step once, in order)"
        )
    if reported and max(reported) >= n:
        raise SoakError(f"step {max(reported)} was reported done but the file holds {n} steps")
    return n


def final_checks(out, want, reported) -> float | None:
    """The file checked complete (every step of ``want`` where known); its stand time."""
    from vibid.session import read_session

    n = steps_in(out, want, reported)
    with read_session(out) as s:
        status, stand_time = s.run_status, s.stand_time_s
    if (want is not None and n != want.size) or status != "complete":
        raise SoakError(f"{out}: {status} with {n} of {'?' if want is None else want.size} steps")
    return stand_time
