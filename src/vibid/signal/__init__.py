"""Signal stage: each step's two accelerometer records → one complex AFC point with its
standard uncertainty and quality flags.

* :mod:`~vibid.signal.basis` — the sampled model columns on a centred time axis;
* :mod:`~vibid.signal.harmonic` — joint fit of both channels, shared refined frequency;
* :mod:`~vibid.signal.ratio` — ``H = X_response / X_base`` and its delta-method covariance;
* :mod:`~vibid.signal.flags` — quality flags;
* :mod:`~vibid.signal.afc` — a session's steps → :class:`AfcTable`.

Pure numerics on arrays; no I/O (the ``vibid afc`` command lives in :mod:`vibid.cli.afc`).
"""

from vibid.signal.afc import AfcPoint, AfcTable, StepRecord, afc_from_records, afc_from_session
from vibid.signal.basis import Layout
from vibid.signal.flags import FLAG_NAMES, Flag, FlagThresholds
from vibid.signal.harmonic import HarmonicFit, fit_harmonics
from vibid.signal.ratio import phasor_ratio

__all__ = [
    "FLAG_NAMES",
    "AfcPoint",
    "AfcTable",
    "Flag",
    "FlagThresholds",
    "HarmonicFit",
    "Layout",
    "StepRecord",
    "afc_from_records",
    "afc_from_session",
    "fit_harmonics",
    "phasor_ratio",
]
