"""The JAX settings vibid relies on, switched on explicitly by the program's entry points.

64-bit: the AFC near a resonance of a lightly damped plate (beta ~ 1e-3) needs double
precision. Importing vibid changes nothing in the process: the command line, the flows and
the test suite call :func:`configure`; every function that needs 64 bits calls
:func:`require_x64`, which raises a clear error instead of computing silently in 32 bits
(a Dask worker or a script that forgot the set-up fails loudly).

One BLAS thread: JAX's LAPACK kernels (the Cholesky and eigh of every reduced-model
evaluation) call scipy's OpenBLAS, whose default two threads on two cores stall whenever
another process holds a core. A lab PC runs other programs beside vibid: with one other
CPU-bound process, a row of the paper's Table 2 took 40-240 s on two threads and 12-15 s
on one (BENCHMARKS.md). The matrices are small (16-140 unknowns), so one thread loses
nothing on an idle machine either.

No batched LAPACK calls: a population (the global search's) is evaluated in a loop,
:func:`over_population`, not vmapped; jaxlib splits a batched LAPACK call over XLA's
two-thread pool and waits for it, and two such calls at once hung the test suite for good
(the XLA flag ``--xla_cpu_multi_thread_eigen=false`` did not prevent it). The reduced
model's direct path solves its frequencies in a loop too
(:meth:`~vibid.identify.model.reduced.ReducedKernel._direct`). The forward-mode
derivatives batch their 4 or 8 tangents into extra right-hand sides of one matrix, which
runs inline; ``tests/test_no_batched_lapack.py`` reads the compiled code of every function
of the fit for a LAPACK call on more than one matrix.

Compilation cache: every vibid process compiles the same few functions (the model's AFC,
chi2, its gradient and Hessian, the batched chi2 of the global search), which takes a few
seconds for seconds of work. JAX's persistent cache keeps the compiled code on disk, so a
second ``vibid identify`` of a session of the same shape starts at once. The folder is
``$VIBID_JAX_CACHE`` if set (``off`` disables the cache), else
``$XDG_CACHE_HOME/vibid/jax`` (``~/.cache/vibid/jax``); a cache folder the user already
gave JAX (``JAX_COMPILATION_CACHE_DIR``) is kept. A cache that cannot be read or written
only costs the compilation (JAX turns such errors into warnings).

The cache is shared by every vibid process of the machine (the test suite's workers, a
batch's Dask workers, a replay beside a campaign), and JAX writes an entry in place: without
a size limit it takes no lock, and a process that finds an entry another is still writing
reads it truncated and dies in XLA's deserialisation (a segmentation fault in a fresh
clone's suite, in one worker's test while the other compiled the same function:
BENCHMARKS.md).
With a size limit (:data:`MAX_CACHE_BYTES`) JAX reads and writes under a file lock
(``filelock``), and evicts the least recently used entries beyond it. Before it writes an
entry it reads every entry's access time, and an entry written without a limit (by vibid
before the limit, or by JAX left to itself) has none: the read fails, the new entry is not
written, and every later process compiles it again (a warning per compilation). So the
entries without one are given their file's time first (:func:`stamp_entries`).
"""

from __future__ import annotations

import os

from vibid.errors import VibidError

#: Functions that compile faster than this are not worth a disk entry.
MIN_COMPILE_S = 0.2
#: The compilation cache's size limit, bytes: a limit makes JAX lock the cache (module doc);
#: a day of vibid's work fills about 50 MB.
MAX_CACHE_BYTES = 1 << 30


def cache_dir() -> str | None:
    """The compilation cache folder vibid uses, or None if disabled."""
    env = os.environ.get("VIBID_JAX_CACHE")
    if env is not None:
        return None if env.strip().lower() in ("", "0", "off", "no", "none") else env
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "vibid", "jax")


def enable_compilation_cache() -> str | None:
    """Turn on JAX's persistent compilation cache (see the module doc); returns the folder."""
    import jax

    if jax.config.jax_compilation_cache_max_size < 0:  # no limit: no lock (module doc)
        jax.config.update("jax_compilation_cache_max_size", MAX_CACHE_BYTES)
    current = jax.config.jax_compilation_cache_dir
    if current:
        stamp_entries(current)
        return current
    path = cache_dir()
    if path is None:
        return None
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    stamp_entries(path)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_S)
    return path


def stamp_entries(path: str) -> int:
    """Give each entry of the cache folder ``path`` that has no access time (``<key>-atime``,
    JAX's eviction reads it: module doc) its file's modification time; returns how many.
    Under the cache's lock, as JAX writes; a folder that cannot be read is left as it is."""
    import filelock

    try:
        with filelock.FileLock(os.path.join(path, ".lockfile"), timeout=10):
            names = set(os.listdir(path))
            keys = {n.removesuffix("-cache") for n in names if n.endswith("-cache")}
            bare = [k for k in keys if k + "-atime" not in names]
            for key in bare:
                stamp = os.stat(os.path.join(path, key + "-cache")).st_mtime_ns
                with open(os.path.join(path, key + "-atime"), "wb") as fh:
                    fh.write(stamp.to_bytes(8, "little"))
    except (OSError, filelock.Timeout):
        return 0
    return len(bare)


def limit_blas_threads(threads: int = 1) -> None:
    """Limit the BLAS libraries loaded in this process (numpy's, scipy's, which JAX's
    LAPACK kernels use) to ``threads`` threads each."""
    import scipy.linalg  # noqa: F401  (load scipy's OpenBLAS, so that the limit reaches it)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=int(threads), user_api="blas")


#: XLA flags vibid compiles with. XLA's older CPU code generators for fusions (its newer
#: MLIR emitters off): the reduced model's Hessian compiles in 1.7-1.9 s instead of
#: 2.6-2.8 s, its gradient in 0.6 instead of 1.0-1.2 s, and with 6 parameters they run
#: 15-20 % faster, to the same digits (BENCHMARKS.md). The closed loop on a plate compiles
#: about 30 functions cold.
XLA_CPU_FLAGS = ("--xla_cpu_use_fusion_emitters=false",)


def use_xla_flags(flags) -> None:
    """Add ``flags`` (``--name=value``) to ``XLA_FLAGS``, each unless the user's
    ``XLA_FLAGS`` already sets it; XLA reads them when it first compiles."""
    current = os.environ.get("XLA_FLAGS", "")
    given = {f.split("=", 1)[0] for f in current.split()}
    added = [f for f in flags if f.split("=", 1)[0] not in given]
    if added:
        os.environ["XLA_FLAGS"] = " ".join([current, *added]).strip()


def configure(*, cache: bool = True, blas_threads: int | None = 1) -> str | None:
    """What an entry point calls once: 64-bit JAX, the compilation cache unless ``cache``
    is False, and ``blas_threads`` BLAS threads (None leaves them as they are). Returns the
    cache folder (None if off).

    Compiled code runs on the calling thread, not dispatched to XLA's intra-op pool: a
    batched LAPACK call (a solve per frequency under a Hessian's batched tangents) splits
    its batch over that pool and waits; run from a pool thread, on two cores, it can wait
    for work queued behind itself for good (``jax::ParallelBatchMap`` in
    ``lapack_ztrsm_ffi``, under ``ThreadPoolAsyncWorkRunner``: the Monte Carlo test hung in
    2 runs of 5 and in a fresh clone's suite; 10 of 10 passed at the same speed with the
    dispatch off). vibid waits for every result it asks for, so it loses nothing.

    XLA's compiler flags :data:`XLA_CPU_FLAGS` are added to ``XLA_FLAGS`` (a flag the user
    set there is kept); they act on the compilations after the call."""
    use_xla_flags(XLA_CPU_FLAGS)
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_cpu_enable_async_dispatch", False)
    if blas_threads is not None:
        limit_blas_threads(blas_threads)
    return enable_compilation_cache() if cache else None


def over_population(f):
    """``f(arrays, theta)`` mapped over a population ``thetas`` (first axis) as a loop
    (``jax.lax.map``), not ``jax.vmap``. Vmapped, every LAPACK call of the reduced model
    (Cholesky, triangular solves, eigh) becomes a batched one, which jaxlib splits over
    XLA's intra-op thread pool and waits for; when two such calls run at once on a
    two-thread pool, each waits for work queued behind the other and the process hangs
    for good (every thread in a futex wait: ``jax::ParallelBatchMap`` in
    ``lapack_dtrsm_ffi``, seen in the test suite's orthotropic search). In a loop each call
    has one matrix, done where it is called."""
    import jax

    def mapped(arrays, thetas):
        return jax.lax.map(lambda theta: f(arrays, theta), thetas)

    return mapped


def require_x64() -> None:
    """Raise :class:`VibidError` unless JAX computes in 64 bits."""
    import jax

    if not jax.config.jax_enable_x64:
        raise VibidError(
            "vibid's plate model needs 64-bit JAX: call "
            "vibid.identify.engine.runtime.configure() (or set JAX_ENABLE_X64=1) "
            "before using it"
        )
