"""Independent work on the machine's second core: :func:`in_order`.

A closed-loop round scores every candidate and refits several, each from the same frozen
state: none depends on another. The round still takes their results one after the other,
in its own order, and stops where its rules say (a refit that fits the noise ends the
refits), so what it decides does not depend on how many ran at once; the next few only
start early. A global search's generation is a population of independent evaluations,
split the same way.

They run on threads, not processes: the numerical work (JAX's compiled code, SuperLU,
ARPACK, BLAS) runs without Python's lock, and threads share the process's compiled
programs and reduced bases, which a new process would load or build again. On the
titanium AFC six refits took 7.3 s on two threads against 10.8 s one after the other,
with the same results to the last digit (BENCHMARKS.md). JAX's compiled code runs on the
calling thread (:func:`vibid.identify.runtime.configure`), so a thread here is never one
of XLA's own pool waiting on work queued behind it. State kept on a shared object between
calls is guarded where it lives (the plate element's monomials, the reduced bases' cache).

:func:`threads`: ``VIBID_THREADS`` if set, else the cores this process may use, at most
:data:`MAX_THREADS`; 1 runs everything on the calling thread, one after the other.
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor

from vibid.errors import VibidError

#: Threads at most by default: the trust region's small steps hold Python's lock between
#: compiled calls, so a third thread gains little, and each holds its own problems.
MAX_THREADS = 2


def threads() -> int:
    """How many independent pieces of work run at once (module doc)."""
    env = os.environ.get("VIBID_THREADS")
    if env is not None:
        try:
            n = int(env)
        except ValueError:
            raise VibidError(f"VIBID_THREADS must be a whole number of threads, got "
                             f"{env!r}") from None
        if n < 1:
            raise VibidError(f"VIBID_THREADS must be 1 or more, got {n}")
        return n
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(MAX_THREADS, cores))


def in_order(fn: Callable, items: Iterable, workers: int | None = None) -> Iterator:
    """``fn(item)`` for each item, yielded in the items' order, with up to ``workers``
    (default :func:`threads`) computed at once: the ones after the item being consumed
    start early. Closing the generator (``contextlib.closing``, or leaving a ``for`` over
    it whose generator is then dropped) cancels the items not yet started and waits for
    the running ones, whose results are dropped. An exception of ``fn`` is raised where
    its item is consumed."""
    items = list(items)
    n = threads() if workers is None else workers
    if n <= 1 or len(items) <= 1:
        for item in items:
            yield fn(item)
        return
    pending = iter(items)
    with ThreadPoolExecutor(n, thread_name_prefix="vibid") as pool:
        running = deque(pool.submit(fn, item) for _, item in zip(range(n), pending))
        try:
            while running:
                result = running.popleft().result()
                following = next(pending, _END)
                if following is not _END:
                    running.append(pool.submit(fn, following))
                yield result
        finally:
            for future in running:
                future.cancel()


_END = object()
