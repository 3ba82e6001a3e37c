"""Traced programs kept on disk, so that a new process does not trace them again.

JAX's persistent compilation cache (:mod:`vibid.identify.engine.runtime`) spares a new process
XLA's compilation, not the work before it: every process traces each function again in
Python and lowers it to StableHLO, only to find the compiled code under that program's
hash. For the reduced model's Hessian that is 0.3 s of the 0.5 s its first call takes with
the cache filled, and an identification of a real strip's AFC calls about 55 such functions.

A :class:`Persisted` function keeps each program it traces as a :mod:`jax.export` artefact
(serialised StableHLO, tens of kB) in a folder within the compilation cache's. A later process
that calls it with arguments of the same shapes reads the artefact and calls it (a small
wrapper to trace; its compiled code is found in the compilation cache as before). The
artefact's name is a hash of everything the program depends on: the function's identity
(what it computes, for which model structure), the arguments' tree, shapes and dtypes,
64-bit JAX or not, the versions of JAX and jaxlib and the source of the vibid package, so
that no edit of vibid can load an older program. A function whose identity is not fully known from vibid's own
code (a model with a test's own term, :func:`identity_of`) is not persisted, nor a call
inside a transformation (a derivative taken of the AFC): a kept program has no derivative
rule.

Anything that goes wrong (no ``flatbuffers``, a folder that cannot be written, an artefact
cut short) only costs the tracing: the function is then traced as usual.
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import tempfile
import threading
from pathlib import Path

import jax

from vibid.heartbeat import stage
from vibid.identify.engine.threads import compiled, holding

log = logging.getLogger(__name__)

#: Artefacts kept at most; beyond it the least recently used are removed (about 50 kB each).
MAX_ARTEFACTS = 2000


def folder() -> str | None:
    """The artefacts' folder: ``exported`` in JAX's compilation cache folder (JAX reads and
    evicts only its own ``*-cache`` files there); None while the compilation cache is off
    (the program would be compiled anyway)."""
    cache = jax.config.jax_compilation_cache_dir
    return os.path.join(cache, "exported") if cache else None


@functools.lru_cache(maxsize=1)
def code_digest() -> str | None:
    """A hash of the versions of JAX and jaxlib and of every source file of vibid; None
    where vibid's source files cannot be read (an installation in a zip archive): then
    nothing is persisted, since no edit could be told apart."""
    import jaxlib

    import vibid

    h = hashlib.sha256(f"{jax.__version__} {jaxlib.__version__}".encode())
    root = Path(vibid.__file__).parent
    sources = sorted(root.rglob("*.py"))
    if not sources:
        return None
    for path in sources:
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def identity_of(obj) -> str | None:
    """A string that names what ``obj`` (a kernel: a model structure) makes a function
    compute, or None where vibid's source does not determine it: an object of a class
    outside vibid, or one whose text holds a memory address (a function, a lambda)."""
    text = repr(obj)
    if " at 0x" in text or not _made_by_vibid(obj):
        return None
    return f"{type(obj).__module__}.{type(obj).__qualname__}:{text}"


def _made_by_vibid(obj, depth: int = 0) -> bool:
    if depth > 6:
        return False
    if isinstance(obj, (str, int, float, bool, type(None))):
        return True
    if isinstance(obj, (tuple, list, frozenset)):
        return all(_made_by_vibid(x, depth + 1) for x in obj)
    if not type(obj).__module__.startswith("vibid."):
        return False
    fields = getattr(obj, "__dataclass_fields__", None)
    if fields is None:
        return False
    return all(_made_by_vibid(getattr(obj, name), depth + 1) for name in fields)


class Persisted:
    """``fn`` (a ``jax.jit`` function) whose traced programs are kept on disk as ``name``
    (``"problem.hessian"``) of ``identity`` (:func:`identity_of` its model structure; module
    doc); called like ``fn``. Without an identity, for arguments that are not all arrays,
    or inside a transformation (``jax.jacfwd`` of it), it is ``fn``."""

    def __init__(self, fn, name: str, identity: str | None):
        self.fn, self.name, self.identity = fn, name, identity
        self._calls = {}  # argument signature -> the callable for it
        self._loading = threading.Lock()  # one thread loads and compiles, the others wait

    def __call__(self, *args):
        # every compiled call is a stage of the watchdog's (vibid.heartbeat): a native call
        # that never returns (issue 62's deadlock) ends the command with its name
        with stage(self.name):
            return self._call(*args)

    def _call(self, *args):
        # on every call (a Hessian's or a gradient's, thousands in a loop): kept cheap
        if self.identity is None:
            return self.fn(*args)
        leaves, tree = jax.tree_util.tree_flatten(args)
        try:
            signature = (
                tree,
                tuple([(x.shape, x.dtype, getattr(x, "weak_type", False)) for x in leaves]),
            )
        except AttributeError:  # a Python number among the arguments
            return self.fn(*args)
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            return self.fn(*args)  # inside a transformation: a kept program has no
            # derivative rule, traced as usual
        call = self._calls.get(signature)
        if call is not None:
            return call(*args)
        with holding(self._loading):  # two polishes' first Hessians: compiled once
            call = self._calls.get(signature)
            if call is None:
                call = self._calls[signature] = self._load(args, signature)
        if call is self.fn:
            return call(*args)
        try:
            return call(*args)
        except Exception as exc:  # noqa: BLE001 - a kept program JAX will not run: trace
            log.debug("persist: %s is traced as usual (%s)", self.name, exc)
            self._calls[signature] = self.fn
            return self.fn(*args)

    def _load(self, args, signature):
        where, code = folder(), code_digest()
        if where is None or code is None:
            return self.fn
        x64 = jax.config.jax_enable_x64  # the dtypes a program makes inside
        key = hashlib.sha256(f"{code}|{x64}|{self.name}|{self.identity}|{signature}".encode())
        path = os.path.join(where, key.hexdigest()[:40] + ".jaxexport")
        try:
            from jax import export

            exported = _read(path)
            if exported is None:
                exported = export.export(self.fn)(*args)
                _write(where, path, exported.serialize())
            return compiled(jax.jit(_named(exported.call, self.name)), args)
        except Exception as exc:  # noqa: BLE001 - persisting only saves time
            log.debug("persist: %s is traced as usual (%s)", self.name, exc)
            return self.fn


def _named(call, name: str):
    """``call`` under ``name`` (JAX's logs and profiles name a function by it)."""

    def kept(*args):
        return call(*args)

    kept.__name__ = kept.__qualname__ = name.replace(".", "_")
    return kept


def _read(path: str):
    """The artefact at ``path`` (its time touched: the least recently used go first), or
    None where there is none or it cannot be read."""
    from jax import export

    try:
        with open(path, "rb") as fh:
            blob = fh.read()
        exported = export.deserialize(bytearray(blob))
    except FileNotFoundError:
        return None
    except Exception as exc:  # noqa: BLE001 - a damaged artefact is written again
        log.debug("persist: %s could not be read (%s)", path, exc)
        return None
    try:
        os.utime(path)
    except OSError:
        pass
    return exported


def _write(where: str, path: str, blob: bytes) -> None:
    """Write ``blob`` at ``path`` whole or not at all (a reader in another process never
    sees it cut short), then keep the folder within :data:`MAX_ARTEFACTS`."""
    os.makedirs(where, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=where, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(blob)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _evict(where)


def _evict(where: str, keep: int = MAX_ARTEFACTS) -> None:
    try:
        entries = [e for e in os.scandir(where) if e.name.endswith(".jaxexport")]
        if len(entries) <= keep:
            return
        entries.sort(key=lambda e: e.stat().st_mtime)
        for e in entries[: len(entries) - keep]:
            Path(e.path).unlink(missing_ok=True)
    except OSError:
        pass
