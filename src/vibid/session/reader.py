"""Read a session file: the declared setup at once, the steps lazily, one at a time.

Every read goes through :mod:`vibid.session.hdf5io`, so a damaged file gives one
:class:`SessionFileError` naming the file and the path inside it, whenever it is found (also
in the middle of a lazy pass over the steps), never an exception of the HDF5 library.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass

import h5py
import numpy as np

from vibid.errors import VibidError
from vibid.session import format as fmt
from vibid.session.hdf5io import Problem, SessionFileError, close_quietly, read_samples, reading
from vibid.session.validate import hdf5_problems, open_hdf5
from vibid.setup_model import Setup, SetupError, parse_setup


@dataclass(frozen=True)
class Step:
    """One frequency step as recorded: accelerations in m/s², sampled together."""

    index: int
    frequency_hz: float
    sample_rate_hz: float
    t0_utc: str
    status: str
    base: np.ndarray
    response: np.ndarray
    temperature_c: float | None = None  #: optional, °C

    @property
    def n_samples(self) -> int:
        return self.base.shape[0]


class Session:
    """An open session file. Use :func:`read_session`; close it (or use ``with``)."""

    def __init__(self, path: str, f: h5py.File):
        self.path = path
        self._file = f
        with reading(path, "/"):
            attrs = f.attrs
            if why := fmt.setup_digest_problem(attrs):
                raise SessionFileError(path, [Problem("/@setup", why)])
            self.setup: Setup = parse_setup(fmt.text(attrs["setup"]))
            self.session_id = fmt.text(attrs["session_id"])
            self.created_utc = fmt.text(attrs["created_utc"])
            self.software = fmt.text(attrs["software"])
            self.operator = fmt.text(attrs["operator"]) if "operator" in attrs else None
            self.notes = fmt.text(attrs["notes"]) if "notes" in attrs else None
            #: whether the file says how it ended (else ``run_status`` is inferred from the step count)
            self.run_status_written = fmt.RUN_STATUS in attrs
            #: seconds the specimen was driven (written when the session was closed), or None
            self.stand_time_s = (
                float(attrs[fmt.STAND_TIME_S]) if fmt.STAND_TIME_S in attrs else None
            )
            #: the ``adaptive`` document of a campaign that chose its steps as it went, or None
            self.adaptive = fmt.adaptive_document(attrs)
        with reading(path, f"/{fmt.STEPS_GROUP}"):
            self._names = sorted(k for k in f[fmt.STEPS_GROUP] if fmt.is_step_name(k))
        n_freq = len(self.setup.excitation.frequencies_hz) if self.setup.excitation else 0
        with reading(path, "/"):
            #: ``complete``, ``interrupted`` or ``aborted``, and why (empty when complete)
            self.run_status, self.run_status_reason = fmt.run_status_of(
                attrs, len(self._names), n_freq
            )

    def __len__(self) -> int:
        return len(self._names)

    def step(self, index: int) -> Step:
        """Read step ``index``; raise :class:`SessionFileError` if its samples are not finite
        or the file is damaged there."""
        name = self._names[index]
        where = f"/{fmt.STEPS_GROUP}/{name}"
        with reading(self.path, where):
            g = self._file[where]
            a = g.attrs
            frequency_hz, sample_rate_hz = float(a["frequency_hz"]), float(a["sample_rate_hz"])
            t0_utc, status = fmt.text(a["t0_utc"]), fmt.text(a["status"])
            records = {label: g[label] for label in ("base", "response")}
        base = read_samples(self.path, f"{where}/base", records["base"])
        response = read_samples(self.path, f"{where}/response", records["response"])
        for label, x in (("base", base), ("response", response)):
            bad = np.count_nonzero(~np.isfinite(x))
            if bad:
                raise SessionFileError(
                    self.path, [Problem(f"{where}/{label}", f"{bad} samples are NaN or infinite")]
                )
        temperature = None
        with reading(self.path, where):
            if "temperature_c" in a:
                temperature = float(a["temperature_c"])
        return Step(
            index, frequency_hz, sample_rate_hz, t0_utc, status, base, response, temperature
        )

    def step_attributes(self, index: int) -> dict:
        """Every attribute of step ``index`` (the format's and vibid's own), without samples."""
        where = f"/{fmt.STEPS_GROUP}/{self._names[index]}"
        with reading(self.path, where):
            g = self._file[where]
            return {
                k: (fmt.text(v) if isinstance(v, (str, bytes)) else v) for k, v in g.attrs.items()
            }

    def steps(self) -> Iterator[Step]:
        """Every step in the order acquired, read one at a time."""
        for i in range(len(self)):
            yield self.step(i)

    def driven_s(self) -> float | None:
        """Seconds the specimen was driven, summed over the step groups (each step's
        ``settle_s`` and record): the truth after a crash, when the root ``stand_time_s``
        is missing or older than the last steps. None when no step says how long it settled."""
        with reading(self.path, f"/{fmt.STEPS_GROUP}"):
            return fmt.stand_time_s(self._file)

    def frequencies_hz(self) -> np.ndarray:
        """The commanded frequency of every step, without reading any samples."""
        return np.array([float(v) for v in self._step_attribute("frequency_hz")])

    def statuses(self) -> list[str]:
        return [fmt.text(v) for v in self._step_attribute("status")]

    def _step_attribute(self, name: str) -> Iterator:
        for n in self._names:
            where = f"/{fmt.STEPS_GROUP}/{n}"
            with reading(self.path, f"{where}@{name}"):
                value = self._file[where].attrs[name]
            yield value

    def close(self) -> None:
        close_quietly(self._file)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_session(path: str | os.PathLike) -> Session:
    """Open a session for reading after checking its structure (samples are checked as read).

    Raises :class:`SessionFileError` (a :class:`~vibid.errors.VibidError`) naming the first
    problem. Opens without a file lock so that a running acquisition is never blocked.
    """
    path = os.fspath(path)
    opened = open_hdf5(path)
    if isinstance(opened, Problem):
        raise SessionFileError(path, [opened])
    try:
        problems = list(hdf5_problems(opened, check_samples=False))
        if problems:
            raise SessionFileError(path, problems)
        return Session(path, opened)
    except BaseException:
        close_quietly(opened)
        raise


def load_setup(path: str | os.PathLike) -> Setup:
    """The declared setup from a setup JSON file or a session file."""
    path = os.fspath(path)
    if path.endswith((".h5", ".hdf5")):
        with read_session(path) as s:
            return s.setup
    try:
        with open(path) as fh:
            doc = json.load(fh)
    except OSError as exc:
        raise VibidError(f"{path}: cannot read ({exc.strerror})") from None
    except json.JSONDecodeError as exc:
        raise VibidError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    try:
        return parse_setup(doc)
    except SetupError as exc:
        raise VibidError(f"{path}: {exc.problems[0]}") from None
