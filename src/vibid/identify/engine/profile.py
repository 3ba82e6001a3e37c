"""Where an identification's time goes: compilation, reduced bases, searches, refits.

A :class:`Profile` records, while it is active (``with recording() as prof:``), the wall
time spent in named sections and how many functions JAX compiled (and how long that took,
from JAX's own monitoring events). The numerical code marks its expensive steps with
:func:`section`; outside a recording a section costs one attribute look-up.

    with recording() as prof:
        identify(...)
    print(prof.table())

Sections nest: the seconds of an inner section are also counted in the outer one's (a
section inside one of the same name, on the same thread, counts once). Sections that run
at once on several threads (a loop round's refits, a batch's sessions) each count
their own seconds, so a section's seconds may exceed the wall time. The
section names used by vibid are :data:`SECTIONS`; compilation is measured by JAX, not by a
section (it happens inside whatever section first calls a function).
"""

from __future__ import annotations

import contextlib
import functools
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

from vibid.heartbeat import stage

#: The sections vibid marks, in the order a report lists them.
SECTIONS = (
    "signal stage",
    "matrices",
    "reduced bases",
    "full-model checks",
    "global search",
    "local fits",
    "model error",
    "loop scoring",
    "loop refits",
)

#: JAX's monitoring events of one compilation (jax/_src/dispatch.py).
_TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"
_LOWER_EVENT = "/jax/core/compile/jaxpr_to_mlir_module_duration"
_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
_CACHE_HIT_EVENT = "/jax/compilation_cache/cache_hits"

#: The recording in progress: one per process, not per thread or context (a Prefect task's
#: worker thread and JAX's compilation callbacks must reach it too).
_active: Profile | None = None
_listening = False
#: Guards a recording's counters against two threads adding at once.
_adding = threading.Lock()


@dataclass
class Profile:
    """Seconds per section, and JAX's compilations while recording.

    Attributes
    ----------
    seconds : section name -> wall seconds (nested sections count in both).
    calls : section name -> how many times it ran.
    compilations : functions JAX compiled (a persistent-cache hit counts too: it is
        traced, lowered and loaded, only XLA's compilation is skipped).
    cache_hits : of those, how many the persistent compilation cache supplied.
    compile_seconds : tracing, lowering and XLA compilation, seconds.
    """

    seconds: Counter = field(default_factory=Counter)
    calls: Counter = field(default_factory=Counter)
    compilations: int = 0
    cache_hits: int = 0
    compile_seconds: float = 0.0
    started: float = field(default_factory=time.perf_counter)
    wall_seconds: float = 0.0
    open: set = field(default_factory=set)

    def table(self) -> str:
        """A few lines a person reads: each section's seconds and share of the wall time."""
        wall = self.wall_seconds or (time.perf_counter() - self.started)
        lines = [
            f"profile: {wall:.1f} s in all",
            f"  {'compiling (JAX)':<22} {self.compile_seconds:7.1f} s  "
            f"{self.compilations} functions ({self.cache_hits} from the disk cache)",
        ]
        names = [n for n in SECTIONS if n in self.seconds] + sorted(
            n for n in self.seconds if n not in SECTIONS
        )
        for n in names:
            lines.append(f"  {n:<22} {self.seconds[n]:7.1f} s  {self.calls[n]} x")
        if any(self.seconds[n] > wall for n in names):
            lines.append(
                "  (a section run on several threads at once counts each thread's seconds)"
            )
        return "\n".join(lines)

    def as_dict(self) -> dict:
        return {
            "wall_s": self.wall_seconds,
            "compilations": self.compilations,
            "compile_cache_hits": self.cache_hits,
            "compile_s": self.compile_seconds,
            "sections_s": dict(self.seconds),
        }


def _on_duration(event: str, duration: float, **_) -> None:
    prof = _active
    if prof is None:
        return
    with _adding:
        if event == _COMPILE_EVENT:
            prof.compilations += 1
        if event in (_TRACE_EVENT, _LOWER_EVENT, _COMPILE_EVENT):
            prof.compile_seconds += duration


def _on_event(event: str, **_) -> None:
    prof = _active
    if prof is not None and event == _CACHE_HIT_EVENT:
        with _adding:
            prof.cache_hits += 1


def _listen() -> None:
    global _listening
    if not _listening:
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(_on_duration)
        jax.monitoring.register_event_listener(_on_event)
        _listening = True


@contextlib.contextmanager
def recording():
    """Record a :class:`Profile` of everything this process runs inside (any thread)."""
    _listen()
    global _active
    prof, outer = Profile(), _active
    _active = prof
    try:
        yield prof
    finally:
        prof.wall_seconds = time.perf_counter() - prof.started
        _active = outer


@contextlib.contextmanager
def section(name: str):
    """Count the time inside as ``name`` in the active recording (if any); a stage of the
    watchdog's (:func:`vibid.heartbeat.stage`) either way."""
    with stage(name):  # the watchdog's stage too (vibid.heartbeat)
        prof = _active
        key = (threading.get_ident(), name)
        if prof is None or key in prof.open:  # a section inside itself counts once
            yield
            return
        t0 = time.perf_counter()
        prof.open.add(key)
        try:
            yield
        finally:
            with _adding:
                prof.open.discard(key)
                prof.seconds[name] += time.perf_counter() - t0
                prof.calls[name] += 1


def timed(name: str):
    """Decorator: every call of the function is a :func:`section` ``name``."""

    def wrap(fn):
        @functools.wraps(fn)
        def inner(*args, **kwargs):
            with section(name):
                return fn(*args, **kwargs)

        return inner

    return wrap
