"""An AFC read from a file, and what every reader of one (CSV, UFF58) checks before a fit.

:class:`ImportedAfc` is what :mod:`vibid.signal.imported` and :mod:`vibid.signal.uff` return;
:func:`checked_afc` is the one gate both pass their values through (order, repeated
frequencies, values, signal: :mod:`vibid.signal.imported`'s docstring lists each rule), and
:func:`refuse_beyond_nyquist` the check where the AFC meets its setup.
"""

from __future__ import annotations

import hashlib
import math
import uuid
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibid.errors import VibidError

#: The largest |re|, |im| and std of an AFC (dimensionless). H is a ratio of two
#: accelerations, the plate's over the table's: a resonance amplifies the table's motion by
#: its quality factor, at most ~1e5 for the least damped metal (loss factor 1e-5), and no
#: accelerometer pair spans more than ~120 dB (1e6) between the channels. Beyond this a
#: number is not a measurement (a unit mix-up, a file of another quantity, an overflow).
MAX_ABS_H = 1e6
#: The smallest largest-|H| of an AFC: a response 120 dB below the table's at every
#: frequency is under the noise floor of a 24-bit DAQ (6e-8 of full scale), i.e. no
#: response was measured (below its first mode a clamped plate moves with the table,
#: |H| ≈ 1).
MIN_PEAK_H = 1e-6
#: The smallest std, relative to the AFC's largest |H|: a 24-bit ADC resolves 6e-8 of full
#: scale, and no record averages that down by another 1e4; a std below this is not an
#: uncertainty of a measurement, and its weight 1/std² would swamp every other point.
MIN_REL_STD = 1e-12
#: With a std, some point of the AFC must stand above its own noise: |H|/std at least this.
MIN_SNR = 1.0


@dataclass(frozen=True)
class ImportedAfc:
    """frequency_hz (n,) Hz, increasing, distinct; H (n,) complex; std (n,) per real and
    imaginary part, or None; session_id: derived from the file's content; ``rows`` (n,)
    the row of the file each point comes from (a CSV's line, a UFF record's point number),
    ``unit`` the words naming one and two of them (:meth:`where`)."""

    frequency_hz: np.ndarray
    H: np.ndarray
    std: np.ndarray | None
    session_id: str
    rows: np.ndarray | None = None
    unit: tuple[str, str] = ("line", "lines")

    @property
    def used(self) -> np.ndarray:
        return np.ones(self.frequency_hz.size, bool)

    def where(self, k: int) -> str:
        """Where point ``k`` comes from in the file, e.g. ``line 12``."""
        return f"{self.unit[0]} {k + 1 if self.rows is None else int(self.rows[k])}"

    def to_report_block(self) -> dict[str, Any]:
        return {
            "frequency_hz": self.frequency_hz.tolist(),
            "re": self.H.real.tolist(),
            "im": self.H.imag.tolist(),
            "std": [None] * self.H.size if self.std is None else self.std.tolist(),
        }


def content_session_id(raw: bytes) -> str:
    """The session id of an imported AFC: a UUID made of the SHA-256 of the file's bytes."""
    return str(uuid.UUID(hashlib.sha256(raw).hexdigest()[:32]))


def checked_afc(
    path, frequency_hz, H, std, rows, unit: tuple[str, str], session_id: str
) -> ImportedAfc:
    """The :class:`ImportedAfc` of the points read from ``path`` in file order (``rows``:
    each one's row, named by ``unit``), checked, sorted by frequency, repeated rows merged
    (module docstring); one-line VibidError naming the row otherwise."""
    f = np.asarray(frequency_hz, float)
    h = np.asarray(H, complex)
    s = None if std is None else np.asarray(std, float)
    rows = np.asarray(rows, int)

    def say(k):
        return f"{path}: {unit[0]} {int(rows[k])}: "

    _refuse_bad_values(say, f, h, s)
    order = np.argsort(f, kind="stable")
    f, h, rows = f[order], h[order], rows[order]
    s = None if s is None else s[order]
    f, h, s, rows = _merged_repeats(path, unit, f, h, s, rows)
    if f.size < 2:
        raise VibidError(f"{path}: fewer than two AFC points")
    _refuse_no_signal(path, say, h, s)
    return ImportedAfc(f, h, s, session_id, rows, unit)


def _first_bad(checks) -> tuple[int, str] | None:
    """Of ``[(mask, describe)]``, the first point any mask marks (file order) and what the
    first check marking it says of it (``describe(k)``); None if none."""
    best = None
    for mask, describe in checks:
        bad = np.flatnonzero(mask)
        if bad.size and (best is None or bad[0] < best[0]):
            best = (int(bad[0]), describe)
    return None if best is None else (best[0], best[1](best[0]))


def _refuse_bad_values(say, f, h, s) -> None:
    """Non-finite numbers, non-positive frequencies or std, magnitudes beyond
    :data:`MAX_ABS_H`: a VibidError naming the first such row in the file."""
    limit = f"beyond ±{MAX_ABS_H:g}: an AFC is a ratio of accelerations, not a measurement"
    checks = [
        (~np.isfinite(f), lambda k: f"frequency_hz is {float(f[k])!r}, not a finite number"),
        (np.isfinite(f) & (f <= 0), lambda k: f"frequency_hz {float(f[k])!r} Hz is not positive"),
        (~np.isfinite(h.real), lambda k: f"re is {float(h[k].real)!r}, not a finite number"),
        (~np.isfinite(h.imag), lambda k: f"im is {float(h[k].imag)!r}, not a finite number"),
        (
            np.isfinite(h.real) & (np.abs(h.real) > MAX_ABS_H),
            lambda k: f"re {float(h[k].real)!r} is {limit}",
        ),
        (
            np.isfinite(h.imag) & (np.abs(h.imag) > MAX_ABS_H),
            lambda k: f"im {float(h[k].imag)!r} is {limit}",
        ),
    ]
    if s is not None:
        checks += [
            (~np.isfinite(s), lambda k: f"std is {float(s[k])!r}, not a finite number"),
            (np.isfinite(s) & (s <= 0), lambda k: f"std {float(s[k])!r} must be positive"),
            (np.isfinite(s) & (s > MAX_ABS_H), lambda k: f"std {float(s[k])!r} is {limit}"),
        ]
    bad = _first_bad(checks)
    if bad is not None:
        raise VibidError(say(bad[0]) + bad[1])


def _merged_repeats(path, unit, f, h, s, rows):
    """Sorted points with each run of equal frequencies merged into its first row when the
    rows agree in every value; a VibidError naming two rows that disagree."""
    same = f[1:] == f[:-1]
    if not same.any():
        return f, h, s, rows
    agree = (h[1:] == h[:-1]) & (True if s is None else s[1:] == s[:-1])
    clash = np.flatnonzero(same & ~agree)
    if clash.size:
        k = clash[np.argmin(np.minimum(rows[clash], rows[clash + 1]))]
        a, b = sorted((int(rows[k]), int(rows[k + 1])))
        raise VibidError(
            f"{path}: {unit[1]} {a} and {b} both give {float(f[k])!r} Hz, with "
            "different values: keep one of them, or average them"
        )
    keep = np.concatenate([[True], ~same])
    return f[keep], h[keep], None if s is None else s[keep], rows[keep]


def _refuse_no_signal(path, say, h, s) -> None:
    """An AFC without a measured response (:data:`MIN_PEAK_H`, :data:`MIN_SNR`) or with a
    std finer than any measurement (:data:`MIN_REL_STD`)."""
    size = np.abs(h)
    peak = float(size.max())
    if peak == 0.0:
        raise VibidError(
            f"{path}: every H is 0: no response measured (is the response channel connected?)"
        )
    if peak < MIN_PEAK_H:
        raise VibidError(
            f"{path}: the largest |H| is {peak:.3g}, below {MIN_PEAK_H:g} (120 dB "
            "under the table's motion at every frequency): no response measured"
        )
    if s is None:
        return
    k = int(np.argmin(s))
    if s[k] < MIN_REL_STD * peak:
        raise VibidError(
            say(k) + f"std {float(s[k])!r} is below {MIN_REL_STD:g} of the "
            f"largest |H| ({peak:.6g}): finer than any DAQ resolves"
        )
    snr = float(np.max(size / s))
    if snr < MIN_SNR:
        raise VibidError(
            f"{path}: no point of the AFC stands above its std (the largest "
            f"|H|/std is {snr:.3g}): no response measured"
        )


def refuse_beyond_nyquist(afc: ImportedAfc, sample_rate_hz: float, *, shown) -> None:
    """Refuse an AFC (read from ``shown``) with a frequency at or above the Nyquist
    frequency ``sample_rate_hz / 2`` (Hz) of the setup's DAQ: no sampled record holds it
    (one line naming the first such row in the file). A sample rate that is not a positive
    number is the setup's own problem (its validation says so), and checks nothing here."""
    rate = float(sample_rate_hz)
    if not (math.isfinite(rate) and rate > 0):
        return
    nyquist = rate / 2
    above = np.flatnonzero(np.asarray(afc.frequency_hz) >= nyquist)
    if not above.size:
        return
    k = int(above[0] if afc.rows is None else above[np.argmin(afc.rows[above])])
    more = f" (and {above.size - 1} more points)" if above.size > 1 else ""
    raise VibidError(
        f"{shown}: {afc.where(k)}: {float(afc.frequency_hz[k])!r} Hz is not below "
        f"the Nyquist frequency {nyquist!r} Hz of the setup's DAQ "
        f"(daq.sample_rate_hz {rate!r}){more}"
    )
