"""Every rule of the session format, checked on an open HDF5 file.

Problems are ``(location, message)`` pairs. A location is the path inside the file, with
``@name`` for an attribute: ``/@format_version``, ``/steps/000003@status``,
``/steps/000003/response``. :func:`file_problems` also covers files that are not HDF5 at all,
and damaged ones: whatever the HDF5 library raises becomes a problem at the path being read
(:mod:`vibid.session.hdf5io`), after which checking stops.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass

import h5py
import numpy as np

from vibid.session import format as fmt
from vibid.session.hdf5io import (
    LIBRARY_ERRORS,
    Problem,
    SessionFileError,
    close_quietly,
    heap_problem,
    reading,
    storage_problem,
    survives,
)
from vibid.setup_model import SetupError, parse_setup


def file_problems(path: str | os.PathLike, *, check_samples: bool = True) -> list[Problem]:
    """Open ``path`` and list every way it breaks the format (empty list: valid)."""
    opened = open_hdf5(path)
    if isinstance(opened, Problem):
        return [opened]
    try:
        return list(hdf5_problems(opened, check_samples=check_samples))
    finally:
        close_quietly(opened)


@dataclass(frozen=True)
class NoFile(Problem):
    """A path with no file to check (missing, or a folder): nothing inside it to locate, so
    it reads as its message alone (``S.h5: no such file``, not ``S.h5: /: no such file``)."""

    def __str__(self) -> str:
        return self.message


def no_file(path: str | os.PathLike) -> NoFile | None:
    """Why there is no file at ``path`` to read (missing, a folder), or None."""
    path = os.fspath(path)
    if not os.path.exists(path):
        return NoFile("/", "no such file")
    if os.path.isdir(path):
        return NoFile("/", "is a directory, not a session file")
    return None


def open_hdf5(path: str | os.PathLike) -> h5py.File | Problem:
    """Open read-only without taking a lock (a live writer must never be blocked), or say why not."""
    path = os.fspath(path)
    if (missing := no_file(path)) is not None:
        return missing
    size = os.path.getsize(path)
    if size == 0:
        return Problem("/", "empty file (0 bytes), not an HDF5 session")
    try:
        is_hdf5 = h5py.is_hdf5(path)
    except OSError as exc:
        return Problem("/", f"cannot be read ({exc.strerror or exc})")
    if not is_hdf5:
        return Problem("/", "not an HDF5 file (no HDF5 signature)")
    try:
        damaged_heap = heap_problem(path)
    except OSError as exc:
        return Problem("/", f"cannot be read ({exc.strerror or exc})")
    if damaged_heap is not None:
        return damaged_heap
    crashed = survives(read_structure, path)
    if crashed is not None:
        return crashed
    try:
        return h5py.File(path, "r", locking=False)
    except LIBRARY_ERRORS as exc:
        reason = str(exc).split("(")[0].strip().rstrip(":") or "unreadable"
        return Problem("/", f"HDF5 file is truncated or corrupted ({reason}, {size} bytes)")


def hdf5_problems(f: h5py.File, *, check_samples: bool = True) -> Iterator[Problem]:
    """Rules of the root, the setup and every step; samples are read only if ``check_samples``.

    A part of the file the library cannot read ends the list with one problem at that path.
    """
    try:
        root_ok = True
        with reading(f.filename, "/"):
            for p in _root_problems(f):
                root_ok = False
                yield p
        if not root_ok:
            return  # without a readable header, step problems would only add noise
        for (
            name
        ) in f.attrs:  # vibid's own and the optional ones are read too: they must be readable
            with reading(f.filename, f"/@{name}"):
                f.attrs[name]
        yield from steps_problems(f, check_samples=check_samples)
    except SessionFileError as exc:
        yield from exc.problems


def read_structure(path: str) -> None:
    """Read everything of a session file but its samples: attributes, groups, dataset headers
    and chunk indexes (what :func:`hdf5_problems` and the reader touch). Run in a child process
    by :func:`open_hdf5`, where a crash of the library costs nothing."""
    with h5py.File(path, "r", locking=False) as f:
        list(hdf5_problems(f, check_samples=False))
        steps = f.get(fmt.STEPS_GROUP)
        for name in list(steps) if isinstance(steps, h5py.Group) else ():
            try:
                group = steps[name]
                for key in group.attrs:
                    group.attrs[key]
                for key in fmt.STEP_DATASETS:
                    storage_problem(group[key])
            except LIBRARY_ERRORS:
                continue


def _root_problems(f: h5py.File) -> Iterator[Problem]:
    attrs = f.attrs
    for name in fmt.ROOT_ATTRIBUTES:
        if name not in attrs:
            yield Problem(f"/@{name}", "missing root attribute")
    if "format" in attrs:
        value = _as_str(attrs["format"])
        if value is None:
            yield Problem("/@format", f"must be a string, got {_describe(attrs['format'])}")
        elif value != fmt.FORMAT:
            yield Problem("/@format", f"is {value!r}, expected {fmt.FORMAT!r}")
    if "format_version" in attrs:
        version = _as_int(attrs["format_version"])
        readable = ", ".join(str(v) for v in fmt.READABLE_VERSIONS)
        if version is None:
            yield Problem(
                "/@format_version", f"must be an integer, got {_describe(attrs['format_version'])}"
            )
        elif version not in fmt.READABLE_VERSIONS:
            yield Problem(
                "/@format_version",
                f"version {version} is not supported; this vibid reads version {readable}",
            )
    for name in ("created_utc", "session_id", "software"):
        if name in attrs:
            value = _as_str(attrs[name])
            if value is None:
                yield Problem(f"/@{name}", f"must be a string, got {_describe(attrs[name])}")
            elif not value.strip():
                yield Problem(f"/@{name}", "is empty")
            elif name == "created_utc" and not _is_iso_time(value):
                yield Problem("/@created_utc", f"{value!r} is not an ISO 8601 time")
    if "setup" in attrs:
        yield from _setup_digest_problems(attrs)
        yield from _setup_problems(attrs["setup"])
    yield from _optional_root_problems(attrs)


def _optional_root_problems(attrs) -> Iterator[Problem]:
    """``run_status``, ``run_status_reason``, ``operator``, ``notes``: strings when present;
    ``stand_time_s`` a number >= 0; ``adaptive`` a JSON object."""
    for name in (fmt.RUN_STATUS, fmt.RUN_STATUS_REASON, *fmt.OPTIONAL_TEXT_ATTRIBUTES):
        if name in attrs and _as_str(attrs[name]) is None:
            yield Problem(f"/@{name}", f"must be a string, got {_describe(attrs[name])}")
    if fmt.RUN_STATUS in attrs:
        value = _as_str(attrs[fmt.RUN_STATUS])
        if value is not None and value not in fmt.RUN_STATUSES:
            yield Problem(
                f"/@{fmt.RUN_STATUS}",
                f"unknown run status {value!r}, expected one of {', '.join(fmt.RUN_STATUSES)}",
            )
    if fmt.ADAPTIVE in attrs:
        try:
            fmt.adaptive_document(attrs)
        except (ValueError, TypeError) as exc:
            yield Problem(f"/@{fmt.ADAPTIVE}", f"not a JSON object ({exc})")
    if fmt.STAND_TIME_S in attrs:
        value = _as_float(attrs[fmt.STAND_TIME_S])
        if value is None or not (np.isfinite(value) and value >= 0):
            yield Problem(
                f"/@{fmt.STAND_TIME_S}",
                f"must be a finite number >= 0, got {_describe(attrs[fmt.STAND_TIME_S])}",
            )


def _setup_digest_problems(attrs) -> Iterator[Problem]:
    why = fmt.setup_digest_problem(attrs)
    if why:
        yield Problem("/@setup", why)


def _setup_problems(raw) -> Iterator[Problem]:
    text = _as_str(raw)
    if text is None:
        yield Problem("/@setup", f"must be a JSON string, got {_describe(raw)}")
        return
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        yield Problem(
            "/@setup", f"not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})"
        )
        return
    try:
        setup = parse_setup(doc)
    except SetupError as exc:
        for problem in exc.problems:
            yield Problem(f"/@{problem.split(': ', 1)[0]}", problem.split(": ", 1)[1])
        return
    if setup.excitation is None:  # only an imported AFC's setup may leave it out
        yield Problem("/@setup.excitation", "missing: a session file records a stepped sine")


def steps_problems(f: h5py.File, *, check_samples: bool = True) -> Iterator[Problem]:
    with reading(f.filename, f"/{fmt.STEPS_GROUP}"):
        if fmt.STEPS_GROUP not in f:
            yield Problem(f"/{fmt.STEPS_GROUP}", "missing group")
            return
        steps = f[fmt.STEPS_GROUP]
        if not isinstance(steps, h5py.Group):
            yield Problem(f"/{fmt.STEPS_GROUP}", "must be a group, found a dataset")
            return
        names = sorted(steps.keys())
    for name in names:
        if not fmt.is_step_name(name):
            yield Problem(f"/{fmt.STEPS_GROUP}/{name}", "step group name is not six digits")
    for expected, name in enumerate(n for n in names if fmt.is_step_name(n)):
        where = f"/{fmt.STEPS_GROUP}/{name}"
        if name != fmt.step_name(expected):
            yield Problem(
                where, f"step out of sequence: {fmt.step_name(expected)} is missing before it"
            )
            return  # every later name is off by the same gap; one line says it
        with reading(f.filename, where):
            step = steps[name]
            if not isinstance(step, h5py.Group):
                yield Problem(where, "must be a group, found a dataset")
                continue
            yield from step_problems(step, where, check_samples=check_samples)


def step_problems(step: h5py.Group, where: str, *, check_samples: bool = True) -> Iterator[Problem]:
    attrs = step.attrs
    for name in fmt.STEP_ATTRIBUTES:
        if name not in attrs:
            yield Problem(f"{where}@{name}", "missing step attribute")
    rates = {}
    for name in ("frequency_hz", "sample_rate_hz"):
        if name in attrs:
            value = _as_float(attrs[name])
            if value is None:
                yield Problem(f"{where}@{name}", f"must be a number, got {_describe(attrs[name])}")
            elif not (np.isfinite(value) and value > 0):
                yield Problem(f"{where}@{name}", f"must be a positive finite number, got {value!r}")
            else:
                rates[name] = value
    if len(rates) == 2 and rates["frequency_hz"] >= rates["sample_rate_hz"] / 2:
        yield Problem(
            f"{where}@frequency_hz",
            f"{rates['frequency_hz']!r} Hz is not below the Nyquist frequency "
            f"{rates['sample_rate_hz'] / 2!r} Hz",
        )
    if "t0_utc" in attrs:
        value = _as_str(attrs["t0_utc"])
        if value is None:
            yield Problem(f"{where}@t0_utc", f"must be a string, got {_describe(attrs['t0_utc'])}")
        elif not _is_iso_time(value):
            yield Problem(f"{where}@t0_utc", f"{value!r} is not an ISO 8601 time")
    if "status" in attrs:
        value = _as_str(attrs["status"])
        if value is None:
            yield Problem(f"{where}@status", f"must be a string, got {_describe(attrs['status'])}")
        elif value not in fmt.STEP_STATUSES:
            yield Problem(
                f"{where}@status",
                f"unknown status {value!r}, expected one of {', '.join(fmt.STEP_STATUSES)}",
            )

    if "temperature_c" in attrs:
        value = _as_float(attrs["temperature_c"])
        if value is None or not np.isfinite(value):
            yield Problem(
                f"{where}@temperature_c",
                f"must be a finite number, got {_describe(attrs['temperature_c'])}",
            )
    if fmt.SETTLE_S in attrs:
        value = _as_float(attrs[fmt.SETTLE_S])
        if value is None or not (np.isfinite(value) and value >= 0):
            yield Problem(
                f"{where}@{fmt.SETTLE_S}",
                f"must be a finite number >= 0, got {_describe(attrs[fmt.SETTLE_S])}",
            )

    lengths = {}
    for name in fmt.STEP_DATASETS:
        path = f"{where}/{name}"
        with reading(step.file.filename, path):
            yield from _dataset_problems(step, name, path, lengths, check_samples)
    if len(lengths) == 2 and lengths["response"] != lengths["base"]:
        yield Problem(
            f"{where}/response", f"length {lengths['response']} differs from base {lengths['base']}"
        )


def _dataset_problems(
    step: h5py.Group, name: str, path: str, lengths: dict, check_samples: bool
) -> Iterator[Problem]:
    if name not in step:
        yield Problem(path, "missing dataset")
        return
    ds = step[name]
    if not isinstance(ds, h5py.Dataset):
        yield Problem(path, "must be a dataset, found a group")
    elif ds.ndim != 1:
        yield Problem(path, f"must be 1-D, has shape {ds.shape}")
    elif ds.dtype not in (np.float32, np.float64):
        yield Problem(path, f"must be float32 or float64, is {ds.dtype}")
    elif ds.shape[0] == 0:
        yield Problem(path, "is empty")
    else:
        lengths[name] = ds.shape[0]
        if check_samples:
            missing = storage_problem(ds)
            if missing is not None:
                yield Problem(path, missing)
                return
            bad = _count_non_finite(ds)
            if bad == ds.shape[0] and np.isnan(ds.fillvalue):  # vibid's writer fills with NaN
                yield Problem(path, "no samples stored (the file is damaged)")
            elif bad:
                yield Problem(path, f"{bad} sample{'s are' if bad > 1 else ' is'} NaN or infinite")


def _count_non_finite(ds: h5py.Dataset, chunk: int = 1 << 22) -> int:
    return int(
        sum(np.count_nonzero(~np.isfinite(ds[i : i + chunk])) for i in range(0, ds.shape[0], chunk))
    )


# -- attribute types -------------------------------------------------------------------
def _as_str(value) -> str | None:
    if isinstance(value, str):
        return value
    if isinstance(value, (bytes, np.bytes_)):
        try:
            return bytes(value).decode("utf-8")
        except UnicodeDecodeError:
            return None
    return None


def _as_int(value) -> int | None:
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, np.integer)):
        return int(value)
    return None


def _as_float(value) -> float | None:
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value)
    return None


def _describe(value) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    if isinstance(value, (str, bytes, np.bytes_)):
        return f"the string {_as_str(value)!r}"
    if isinstance(value, (bool, np.bool_)):
        return f"the boolean {bool(value)}"
    if isinstance(value, (np.integer, np.floating, int, float)):
        return f"{value!r} ({type(value).__name__})"
    return type(value).__name__


def _is_iso_time(text: str) -> bool:
    try:
        fmt.parse_utc(text)
    except ValueError:
        return False
    return True
