"""A fake ``nidaqmx.Task`` that the real DAQ driver (:mod:`vibid.acquisition.daq`) drives.

:class:`FakeTask` accepts exactly the calls the driver makes — ``ai_channels.
add_ai_accel_chan(...)``, ``timing.cfg_samp_clk_timing(...)``, ``start()``, ``read(...)``,
``in_stream.overloaded_chans_exist`` / ``overloaded_chans``, ``stop()``, ``close()``, the
context manager — records the configuration it was given (:attr:`FakeTask.channels`,
:attr:`FakeTask.timing`), and enforces the limits of a 4-channel IEPE module (NI 9234-like,
:class:`DeviceLimits`), raising ``nidaqmx.errors.DaqError`` with a DAQmx error code as the
real task does.

Samples come from a ``source`` (the virtual stand): ``source.record(n, fs)`` returns both
channels in m/s² as played *now* by the simulated generator through the virtual specimen;
the task returns them in g (``AccelUnits.G``), clipped at each channel's range, and reports
the clipped channels as overloaded. Reading takes ``n / fs`` on the stand's clock (on a wall
clock, the time the source took to compute the samples counts towards it).

Notes (where this differs from a real task): only accelerometer channels in g, finite
acquisitions and the on-board clock; the clipping level is the channel's configured range
(a real module clips at its hardware range, ±5 V, and may report overload only beyond it);
no ADC quantisation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from nidaqmx.constants import AccelSensitivityUnits, AccelUnits, AcquisitionType, ExcitationSource
from nidaqmx.errors import DaqError

G_M_S2 = 9.80665
#: DAQmx error codes the fake raises (nidaqmx.error_codes.DAQmxErrors)
INVALID_ATTRIBUTE_VALUE = -200077
PHYSICAL_CHANNEL_DOES_NOT_EXIST = -200170
INVALID_TASK = -200088


@dataclass(frozen=True)
class DeviceLimits:
    """What the simulated module accepts (an NI 9234: 4 IEPE inputs, ±5 V, 51.2 kS/s)."""

    device: str = "Dev1"
    n_channels: int = 4
    max_input_v: float = 5.0
    rate_limits_hz: tuple[float, float] = (1652.0, 51200.0)
    iepe_currents_a: tuple[float, ...] = (0.0, 0.002, 0.004)


@dataclass
class _Channels:
    task: FakeTask

    def add_ai_accel_chan(
        self,
        physical_channel,
        name_to_assign_to_channel="",
        terminal_config=None,
        min_val=-5.0,
        max_val=5.0,
        units=AccelUnits.G,
        sensitivity=1000.0,
        sensitivity_units=AccelSensitivityUnits.MILLIVOLTS_PER_G,
        current_excit_source=ExcitationSource.INTERNAL,
        current_excit_val=0.004,
        custom_scale_name="",
    ):
        t = self.task
        t._check_open()
        lim = t.limits
        names = [f"{lim.device}/ai{k}" for k in range(lim.n_channels)]
        if physical_channel not in names:
            raise DaqError(
                f"Physical channel specified does not exist on this device.\n"
                f"Physical Channel Name: {physical_channel}",
                PHYSICAL_CHANNEL_DOES_NOT_EXIST,
            )
        if (
            units is not AccelUnits.G
            or sensitivity_units is not AccelSensitivityUnits.MILLIVOLTS_PER_G
        ):
            raise DaqError(
                "Requested value is not a supported value for this property "
                "(the fake supports units g and mV/g).",
                INVALID_ATTRIBUTE_VALUE,
            )
        if not (sensitivity > 0 and min_val < max_val):
            raise DaqError(
                f"Requested value is not a supported value for this property.\n"
                f"sensitivity {sensitivity}, range [{min_val}, {max_val}]",
                INVALID_ATTRIBUTE_VALUE,
            )
        volts = max(abs(min_val), abs(max_val)) * sensitivity * 1e-3
        if volts > lim.max_input_v * (1 + 1e-9):
            raise DaqError(
                f"Requested value is not a supported value for this property.\n"
                f"Range ±{max(abs(min_val), abs(max_val))} g at {sensitivity} mV/g "
                f"needs ±{volts:g} V; the device accepts ±{lim.max_input_v:g} V",
                INVALID_ATTRIBUTE_VALUE,
            )
        iepe = current_excit_val if current_excit_source is ExcitationSource.INTERNAL else 0.0
        if not any(abs(iepe - c) < 1e-9 for c in lim.iepe_currents_a):
            raise DaqError(
                f"Requested value is not a supported value for this property.\n"
                f"Excitation current {iepe} A; supported: {lim.iepe_currents_a}",
                INVALID_ATTRIBUTE_VALUE,
            )
        t.channels.append(
            dict(
                physical_channel=physical_channel,
                name=name_to_assign_to_channel or physical_channel,
                min_val=float(min_val),
                max_val=float(max_val),
                units=units,
                sensitivity=float(sensitivity),
                sensitivity_units=sensitivity_units,
                current_excit_source=current_excit_source,
                current_excit_val=float(current_excit_val),
            )
        )


@dataclass
class _Timing:
    task: FakeTask
    rate: float | None = None
    sample_mode: Any = None
    samps_per_chan: int | None = None

    def cfg_samp_clk_timing(
        self,
        rate,
        source="",
        active_edge=None,
        sample_mode=AcquisitionType.FINITE,
        samps_per_chan=1000,
    ):
        t = self.task
        t._check_open()
        if t.running:
            raise DaqError("The task is running; stop it before changing its timing.", INVALID_TASK)
        lo, hi = t.limits.rate_limits_hz
        if not lo <= rate <= hi:
            raise DaqError(
                f"Requested value is not a supported value for this property.\n"
                f"Sample clock rate {rate} S/s; supported [{lo:g}, {hi:g}]",
                INVALID_ATTRIBUTE_VALUE,
            )
        if sample_mode is not AcquisitionType.FINITE or int(samps_per_chan) < 2:
            raise DaqError(
                "The fake task acquires finite records of at least 2 samples.",
                INVALID_ATTRIBUTE_VALUE,
            )
        self.rate, self.sample_mode, self.samps_per_chan = (
            float(rate),
            sample_mode,
            int(samps_per_chan),
        )


@dataclass
class _InStream:
    task: FakeTask
    _overloaded: tuple[str, ...] = ()
    _asked: bool = False

    @property
    def overloaded_chans_exist(self) -> bool:
        """Reading it clears the overload status (as DAQmx does)."""
        self._asked = True
        return bool(self._overloaded)

    @property
    def overloaded_chans(self) -> list[str]:
        if not self._asked:
            raise DaqError("Read overloaded_chans_exist before overloaded_chans.", INVALID_TASK)
        out, self._overloaded, self._asked = list(self._overloaded), (), False
        return out


@dataclass
class FakeTask:
    """A fake ``nidaqmx.Task`` wired to ``source`` (``record(n, fs) -> (base, response)``
    in m/s², and ``clock``)."""

    source: Any
    limits: DeviceLimits = DeviceLimits()
    channels: list[dict] = field(default_factory=list)
    running: bool = False
    closed: bool = False
    reads: list[int] = field(default_factory=list)  #: samples per channel of each read

    def __post_init__(self):
        self.ai_channels = _Channels(self)
        self.timing = _Timing(self)
        self.in_stream = _InStream(self)

    def _check_open(self) -> None:
        if self.closed:
            raise DaqError("Task specified is invalid or does not exist.", INVALID_TASK)

    def start(self) -> None:
        self._check_open()
        if not self.channels or self.timing.rate is None:
            raise DaqError("The task has no channels or no sample clock.", INVALID_TASK)
        self.running = True

    def stop(self) -> None:
        self._check_open()
        self.running = False

    def read(self, number_of_samples_per_channel=None, timeout=10.0):
        """Both channels' samples in g, as ``[[...], [...]]`` (one list per channel)."""
        self._check_open()
        n = self.timing.samps_per_chan
        if number_of_samples_per_channel not in (None, n):
            raise DaqError(
                f"Requested {number_of_samples_per_channel} samples of a finite "
                f"acquisition of {n}.",
                INVALID_ATTRIBUTE_VALUE,
            )
        if len(self.channels) != 2:
            raise DaqError(
                "The simulated stand has two accelerometers; the task must hold both.", INVALID_TASK
            )
        fs = self.timing.rate
        clock = self.source.clock
        start_s = clock.now_s()
        records = self.source.record(n, fs)
        # the record takes n/fs; time spent computing it (wall clock) is part of that
        clock.sleep(n / fs - (clock.now_s() - start_s))
        out, over = [], []
        for ch, x in zip(self.channels, records):
            g = np.asarray(x, float) / G_M_S2
            if np.any(g > ch["max_val"]) or np.any(g < ch["min_val"]):
                over.append(ch["name"])
                g = np.clip(g, ch["min_val"], ch["max_val"])
            out.append(g.tolist())
        self.in_stream._overloaded = tuple(over)
        self.reads.append(n)
        return out

    def close(self) -> None:
        self.running = False
        self.closed = True

    def __enter__(self) -> FakeTask:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
