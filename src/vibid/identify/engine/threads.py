"""Independent work on the machine's second core, one compiled JAX program at a time.

A closed-loop round scores every candidate and refits several, each from the same frozen
state: none depends on another. :func:`in_order` runs the next ones on threads while the
round takes their results one after the other, in its own order, and stops where its rules
say, so what it decides does not depend on how many ran at once.

**One JAX turn.** Two threads executing compiled JAX code at once can deadlock on this
jaxlib: a fresh clone's test suite hung with both threads in XLA's ``Execute`` waiting on
results while XLA's pool threads sat idle (BENCHMARKS.md, "Tried on `50a3b71`"). So
compiled code runs only on the thread that holds the *turn* (:func:`jax_turn`), and what
overlaps is the work that holds no JAX at all: the sparse matrices' assembly, the reduced
bases (ARPACK, SuperLU), the full model's checks. Those functions are marked
:func:`numpy_only`; inside them a thread lends its turn to the others. Of a refit on a
real strip those take about half the time (BENCHMARKS.md: the profile's "matrices",
"reduced bases" and "full-model checks"). XLA's compilation of a program, which runs none,
lends it too (:func:`compiled`).

Who holds the turn: work started by :func:`in_order` (each item on its worker thread, the
consuming thread between items), and the pipeline's stages that run the model
(:func:`vibid.pipeline.identify_afc`: a batch's sessions on Prefect's thread runner take
turns the same way). Where no thread holds it (a script on one thread) the marks cost one
attribute look-up, and everything runs as it did before there were threads.

:func:`threads`: ``VIBID_THREADS`` if set, else the cores this process may use, at most
:data:`MAX_THREADS`; 1 runs everything on the calling thread, one after the other.
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor

from vibid.errors import VibidError

#: Threads at most by default: with one JAX turn a third thread could only wait for it.
MAX_THREADS = 2

_TURN = threading.Lock()  # the right to run compiled JAX code (module doc)
_held = threading.local()  # .depth: how many jax_turn() this thread is inside; .worker


def threads() -> int:
    """How many independent pieces of work run at once (module doc)."""
    env = os.environ.get("VIBID_THREADS")
    if env is not None:
        try:
            n = int(env)
        except ValueError:
            raise VibidError(
                f"VIBID_THREADS must be a whole number of threads, got {env!r}"
            ) from None
        if n < 1:
            raise VibidError(f"VIBID_THREADS must be 1 or more, got {n}")
        return n
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cores))


def holds_turn() -> bool:
    """Whether the calling thread holds the JAX turn."""
    return getattr(_held, "depth", 0) > 0


@contextlib.contextmanager
def jax_turn():
    """Hold the JAX turn inside the block (re-entrant on one thread; module doc)."""
    depth = getattr(_held, "depth", 0)
    if depth == 0:
        _TURN.acquire()
    _held.depth = depth + 1
    try:
        yield
    finally:
        _held.depth = depth
        if depth == 0:
            _TURN.release()


@contextlib.contextmanager
def lent_turn():
    """Inside the block the calling thread runs no compiled program (it works without
    JAX, compiles, or waits): its turn (if it holds it) is lent to the other threads and
    taken back after."""
    depth = getattr(_held, "depth", 0)
    if depth == 0:
        yield
        return
    _held.depth = 0
    _TURN.release()
    try:
        yield
    finally:
        _TURN.acquire()
        _held.depth = depth


def numpy_only(fn: Callable) -> Callable:
    """Mark ``fn`` as running no JAX code (numpy, scipy, scikit-fem only): while it runs,
    its thread lends the JAX turn to the others (module doc). Put it outside a profile's
    ``timed``: the section then counts the work, not the wait for the turn back."""

    @functools.wraps(fn)
    def lending(*args, **kwargs):
        with numpy_section():
            return fn(*args, **kwargs)

    return lending


@contextlib.contextmanager
def holding(lock):
    """Hold ``lock``; waiting for it, the turn is lent (its holder may need the turn to
    finish what it holds the lock for)."""
    if not lock.acquire(blocking=False):
        with lent_turn():
            lock.acquire()
    try:
        yield
    finally:
        lock.release()


#: What :func:`numpy_only` functions run inside (a test watches these sections for JAX).
numpy_section = lent_turn


def compiled(jitted, args):
    """``jitted.lower(*args).compile()``: traced and lowered under the turn, compiled by XLA
    (or read from the compilation cache) with the turn lent, beside another thread's
    compiled code; compiling runs no program. A cold plate loop compiles about 25
    functions, 19 s."""
    lowered = jitted.lower(*args)
    with lent_turn():
        return lowered.compile()


def in_order(fn: Callable, items: Iterable, workers: int | None = None) -> Iterator:
    """``fn(item)`` for each item, yielded in the items' order, with up to ``workers``
    (default :func:`threads`) computed at once: the ones after the item being consumed
    start early. The items and the consuming thread take turns at JAX (module doc).
    Closing the generator (``contextlib.closing``, or leaving a ``for`` over it whose
    generator is then dropped) cancels the items not yet started and waits for the running
    ones, whose results are dropped. An exception of ``fn`` is raised where its item is
    consumed."""
    items = list(items)
    n = threads() if workers is None else workers
    if n <= 1 or len(items) <= 1 or getattr(_held, "worker", False):  # not nested in one
        for item in items:
            yield fn(item)
        return

    def taking_turns(item):
        _held.worker = True  # an in_order inside this item runs on this thread
        with jax_turn():
            return fn(item)

    pending = iter(items)
    pool = ThreadPoolExecutor(n, thread_name_prefix="vibid")
    with jax_turn():
        running = deque(pool.submit(taking_turns, item) for _, item in zip(range(n), pending))
        try:
            while running:
                with lent_turn():
                    result = running.popleft().result()
                following = next(pending, _END)
                if following is not _END:
                    running.append(pool.submit(taking_turns, following))
                yield result
        finally:
            for future in running:
                future.cancel()
            with lent_turn():
                pool.shutdown(wait=True)


_END = object()
