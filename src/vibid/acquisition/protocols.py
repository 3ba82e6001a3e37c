"""What the campaign needs from the stand: three small protocols and one reading.

The campaign (``acquisition/campaign.py``) talks only to these; it never imports pyserial or
nidaqmx. The drivers (``generator.py`` over pyserial, ``daq.py`` over nidaqmx) implement them
for the real stand, and ``vibid.hardware_mocks`` puts fakes *behind those same drivers* (a
pyserial URL handler, a fake nidaqmx task), so the driver code is what the tests run.

A :class:`Clock` is part of the stand so that a simulated stand can run faster than real
time: the campaign waits with ``clock.sleep(settle_s)``, and the virtual specimen reads
``clock.now_s()`` to know how long ago the frequency changed (a short settle leaves a
transient in the record).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Generator(Protocol):
    """A sine generator that drives the shaker (SCPI over a serial port).

    Attributes are properties of the instrument: setting one sends the command and checks
    the instrument's error queue; reading one queries it.
    """

    frequency_hz: float  #: output frequency, Hz
    amplitude_vpp: float  #: output amplitude, volts peak to peak
    output_enabled: bool  #: True while the output drives the shaker

    def shutdown(self) -> None:
        """Set the safe state: output off. Never raises for a closed or silent port."""

    def close(self) -> None:
        """Output off, then release the port."""


@dataclass(frozen=True)
class Reading:
    """One finite acquisition of both accelerometers (SI units).

    ``base_m_s2`` and ``response_m_s2`` are 1-D and of equal length, sampled together at
    ``sample_rate_hz`` from ``t0_utc`` (ISO 8601). ``overloaded`` names the channels whose
    input range was exceeded (empty when none was).
    """

    base_m_s2: np.ndarray
    response_m_s2: np.ndarray
    sample_rate_hz: float
    t0_utc: str
    overloaded: tuple[str, ...] = ()


@runtime_checkable
class Daq(Protocol):
    """A two-channel accelerometer acquisition (NI-DAQmx), configured when it is opened."""

    sample_rate_hz: float

    def acquire(self, n_samples: int) -> Reading:
        """Record ``n_samples`` on both channels now; block until they are read."""

    def close(self) -> None:
        """Release the task."""


@runtime_checkable
class Clock(Protocol):
    """Time as the stand sees it: wall time at a real stand, virtual time on a simulated one."""

    def now_s(self) -> float:
        """Seconds since an arbitrary origin (monotonic)."""

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds``."""


class WallClock:
    """The real stand's clock (``time.monotonic`` / ``time.sleep``)."""

    def now_s(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


@dataclass
class Stand:
    """The opened instruments of one stand. ``close()`` switches the output off first."""

    generator: Generator
    daq: Daq
    clock: Clock
    description: str = ""

    def close(self) -> None:
        try:
            self.generator.close()
        finally:
            self.daq.close()

    def __enter__(self) -> Stand:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
