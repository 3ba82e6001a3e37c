"""The edge where a damaged session file meets the HDF5 library.

Every read of a session file's contents goes through :func:`reading` (or
:func:`read_samples`), so that whatever the library raises on a damaged file (``OSError``,
``RuntimeError``, ``KeyError``, ``ValueError`` ... with its C error stack in the text) becomes
one :class:`SessionFileError` naming the file and the path inside it, e.g.
``S.h5: /steps/000012/response: checksum mismatch (the file is damaged)``.

Damage the library does not report by itself is checked here too:

- a record whose chunk index lost an entry or an address reads back as the fill value,
  silently; :func:`storage_problem` refuses a dataset whose stored chunks do not cover its
  shape, and :func:`read_samples` one that reads as nothing but vibid's NaN fill value;
- a zeroed object header inside a global heap collection (where variable-length strings
  live) sends the library into an endless loop (HDF5 <= 2.0: an entry of index 0 and size 0
  never advances the parser); :func:`heap_problem` finds such a collection before the
  library is asked to read the file;
- a damaged object header of the old layout (no metadata checksums) can crash the library
  (a segmentation fault) or hang it in ways no check here foresees; :func:`survives` reads
  the file's structure in a child process first, so that a crash or a hang there becomes one
  line instead of the end of the program. Samples are protected by their own checksums
  (``fletcher32``), so reading them afterwards in-process is safe.
"""

from __future__ import annotations

import math
import mmap
import multiprocessing
import os
import struct
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from vibid.errors import VibidError

DAMAGED = "the file is damaged"

#: What the HDF5 library (through h5py) raises when a file's bytes are not what it expects.
LIBRARY_ERRORS = (
    OSError,
    RuntimeError,
    KeyError,
    ValueError,
    TypeError,
    IndexError,
    UnicodeDecodeError,
    OverflowError,
    MemoryError,
)


@dataclass(frozen=True)
class Problem:
    """One way a file breaks the format: the path inside it (``@name`` for an attribute) and what."""

    location: str
    message: str

    def __str__(self) -> str:
        return f"{self.location}: {self.message}"


class SessionFileError(VibidError):
    """A session file that breaks the format or is damaged; ``problems`` lists every reason found."""

    def __init__(self, path: str, problems: list[Problem]):
        self.path = path
        self.problems = problems
        first = problems[0]
        more = f" (and {len(problems) - 1} more problems)" if len(problems) > 1 else ""
        super().__init__(f"{path}: {first}{more}")


def damage_reason(exc: BaseException) -> str:
    """What an exception of the HDF5 library says about the file, in a few words."""
    text = " ".join(str(exc).split()).strip("'\"")
    # h5py puts the innermost reason in parentheses: "Can't synchronously read data (wrong B-tree signature)"
    detail = text[text.rfind("(") + 1 :].rstrip(")") if "(" in text else text
    low = text.lower()
    if "filter returned failure" in low or "checksum" in low:
        return f"checksum mismatch ({DAMAGED})"
    if "truncated" in low or "eoa" in low or "eof" in low or "addr overflow" in low:
        return f"truncated: data lie beyond the end of the file ({DAMAGED})"
    if isinstance(exc, MemoryError):
        return f"declares a size that cannot be held in memory ({DAMAGED})"
    if isinstance(exc, UnicodeDecodeError):
        return f"text that is not UTF-8 ({DAMAGED})"
    return f"cannot be read: {detail or type(exc).__name__} ({DAMAGED})"


@contextmanager
def reading(path: str, where: str) -> Iterator[None]:
    """Run reads of ``where`` (a path inside session file ``path``): a failure of the library
    becomes :class:`SessionFileError` naming both. A :class:`SessionFileError` raised inside
    (a more precise location) passes through unchanged."""
    try:
        yield
    except VibidError:  # SessionFileError with a more precise location, or vibid's own
        raise
    except LIBRARY_ERRORS as exc:
        raise SessionFileError(path, [Problem(where, damage_reason(exc))]) from None


def close_quietly(f) -> None:
    """Close a file opened read-only; a damaged file may fail even that, with nothing to lose."""
    try:
        f.close()
    except LIBRARY_ERRORS:
        pass


def storage_problem(ds) -> str | None:
    """Why dataset ``ds`` (h5py) would read back other than as written, or None.

    A chunked record must have every chunk stored (a lost index entry reads as zeros); a
    contiguous one must have storage for all its bytes.
    """
    n_values = math.prod(ds.shape)
    if n_values == 0:
        return None
    if ds.chunks is not None:
        expected = math.prod(math.ceil(n / c) for n, c in zip(ds.shape, ds.chunks))
        stored = ds.id.get_num_chunks()
        if stored < expected:
            return f"{expected - stored} of {expected} chunks of samples are missing ({DAMAGED})"
        file_size = ds.file.id.get_filesize()
        for i in range(stored):  # a zeroed chunk address reads as the fill value too
            info = ds.id.get_chunk_info(i)
            if not info.byte_offset or info.byte_offset + info.size > file_size:
                return f"chunk {i} of the samples points outside the file ({DAMAGED})"
        return None
    if ds.id.get_storage_size() < n_values * ds.dtype.itemsize:
        return f"samples are missing: storage is shorter than the record ({DAMAGED})"
    return None


def read_samples(path: str, where: str, ds) -> np.ndarray:
    """All samples of a 1-D record as float64, or :class:`SessionFileError` if they cannot be
    trusted (missing storage, checksum mismatch, unreadable)."""
    with reading(path, where):
        problem = storage_problem(ds)
        if problem is not None:
            raise SessionFileError(path, [Problem(where, problem)])
        samples = np.asarray(ds[()], dtype=np.float64)
        if np.isnan(ds.fillvalue) and samples.size and np.isnan(samples).all():
            # vibid's writer fills with NaN: storage the library lost track of reads as the fill
            raise SessionFileError(path, [Problem(where, f"no samples stored ({DAMAGED})")])
        return samples


# -- the global heap guard -----------------------------------------------------------------------
_GCOL = b"GCOL"
_HEADER = struct.Struct("<4sB3xQ")  # signature, version, reserved, collection size (8-byte lengths)
_OBJECT = struct.Struct("<HH4xQ")  # heap index, reference count, reserved, object size


def heap_problem(path: str | os.PathLike) -> Problem | None:
    """A global heap collection that the HDF5 library would parse forever, or None.

    Scans the file once for collection signatures (fast: one pass through the page cache)
    and walks each collection's entries as the library does.
    """
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size < _HEADER.size:
            return None
        with mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            at = mm.find(_GCOL)
            while at >= 0:
                if _collection_loops(mm, at, size):
                    return Problem(
                        "/", f"global heap collection at byte {at} is corrupted ({DAMAGED})"
                    )
                at = mm.find(_GCOL, at + 1)
    return None


def _collection_loops(mm, at: int, file_size: int) -> bool:
    if at + _HEADER.size > file_size:
        return False
    _, version, length = _HEADER.unpack_from(mm, at)
    end = at + length
    if version != 1 or length < _HEADER.size or end > file_size:
        return False  # the library refuses such a collection with an error
    p = at + _HEADER.size
    while p < end:
        if p + _OBJECT.size > end:
            return False  # the tail is free space
        index, _, obj_size = _OBJECT.unpack_from(mm, p)
        need = _OBJECT.size + (obj_size + 7) // 8 * 8 if index > 0 else obj_size
        if need == 0:
            return True  # a free-space entry of size 0: the parser never moves on
        p += need
    return False


# -- a child process reads first ------------------------------------------------------------------
#: How long the child may take to read a file's structure (attributes, groups, chunk indexes), s.
PROBE_TIMEOUT_S = 120.0


def survives(
    read: Callable[[str], object], path: str, *, timeout_s: float | None = None
) -> Problem | None:
    """Run ``read(path)`` in a child process; None if it finished, else why it did not
    (within ``timeout_s``, default :data:`PROBE_TIMEOUT_S`).

    ``read`` should touch what the caller will then read in-process (its own errors are
    ignored here: the caller meets them again, converted, in-process); it is pickled, so a
    module-level function. Where no child process can be started (e.g. inside a daemonic
    process), the check is skipped.
    """
    timeout_s = PROBE_TIMEOUT_S if timeout_s is None else timeout_s
    try:
        ctx = _context()
        child = ctx.Process(target=_probe, args=(read, path), daemon=True)
        child.start()
    except (OSError, AssertionError, ValueError):  # daemonic parent, no fork, ...
        return None
    child.join(timeout_s)
    if child.exitcode is None:
        child.kill()
        child.join()
        return Problem(
            "/",
            f"the HDF5 library did not finish reading the file's structure in "
            f"{timeout_s:g} s ({DAMAGED})",
        )
    if child.exitcode != 0:
        how = f"signal {-child.exitcode}" if child.exitcode < 0 else f"exit code {child.exitcode}"
        return Problem(
            "/", f"the HDF5 library crashed reading the file's structure ({how}; {DAMAGED})"
        )
    return None


def _context():
    """A fork server where there is one (a clean single-threaded parent for every child, started
    once per process, with h5py already imported: a plain fork of a process running JAX's
    threads may deadlock), else spawn (Windows)."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["vibid.session.validate"])
        return ctx
    return multiprocessing.get_context("spawn")


def _probe(read: Callable[[str], object], path: str) -> None:
    import faulthandler

    faulthandler.disable()  # the parent reports a crash in one line; no dump of the child's stack
    try:
        read(path)
    except BaseException:  # noqa: BLE001 - only a crash or a hang counts here
        pass
    os._exit(0)  # no atexit handlers, no flushing of the parent's copied buffers
