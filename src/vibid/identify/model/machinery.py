"""What the model needs from the machinery that runs it: handed in, not imported.

The physics in this package does not know how its functions are compiled and cached, how
they share the machine's cores, or how their time is counted; that is the engine's
(:mod:`vibid.identify.engine`). The model asks for four things, through this module:

* ``compile(kernel)``: the compiled evaluations of a reduced model's kernel (``afc``,
  ``afc_batch``, ``modes_batch``, ``modes_afc_batch``, each ``f(arrays, theta or thetas)``);
* ``numpy_section()``: a context the model's numpy/scipy-only work runs in (the engine lends
  its JAX turn to the other threads there);
* ``section(name)``: a context that counts the time of a named step (a profile);
* ``require_x64()``: raise unless JAX computes in 64 bits.

:mod:`vibid.identify` hands the engine's in on import (:func:`hand`), so any use of the
model, which imports that package first, finds them. A test of the physics may hand its own.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable
from dataclasses import dataclass

from vibid.errors import VibidError


@dataclass(frozen=True)
class Machinery:
    """The four functions the model is handed (module doc)."""

    compile: Callable
    numpy_section: Callable[[], contextlib.AbstractContextManager]
    section: Callable[[str], contextlib.AbstractContextManager]
    require_x64: Callable[[], None]


_handed: Machinery | None = None


def hand(machinery: Machinery) -> None:
    """Give the model the machinery it runs on (done once, by :mod:`vibid.identify`)."""
    global _handed
    _handed = machinery


def handed() -> Machinery:
    """The machinery handed to the model; a clear error when there is none."""
    if _handed is None:
        raise VibidError(
            "the plate model was handed no engine: import vibid.identify (it hands the "
            "engine's compiled functions to the model) before using vibid.identify.model"
        )
    return _handed


def numpy_only(fn: Callable) -> Callable:
    """Mark ``fn`` as running no JAX code: each call runs inside the handed
    ``numpy_section()``. Put it outside :func:`timed`, so the time counts the work, not
    the wait after it."""

    @functools.wraps(fn)
    def lending(*args, **kwargs):
        with handed().numpy_section():
            return fn(*args, **kwargs)

    return lending


def timed(name: str) -> Callable:
    """Decorator: each call of the function runs inside the handed ``section(name)``."""

    def wrap(fn):
        @functools.wraps(fn)
        def inner(*args, **kwargs):
            with handed().section(name):
                return fn(*args, **kwargs)

        return inner

    return wrap
