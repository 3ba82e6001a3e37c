"""The two accelerometers on an NI-DAQmx device (implements ``protocols.Daq``).

One task holds both channels, created with ``ai_channels.add_ai_accel_chan``: the physical
channels ``{device}/{base_channel}`` and ``{device}/{response_channel}`` of the stand
configuration, named ``base`` and ``response``; each sensor's sensitivity (mV/g) from the
declared setup; IEPE excitation from the device (``ExcitationSource.INTERNAL``) at the
configured current (``ExcitationSource.NONE`` when it is 0); input range ±``range_g`` in g.
Each :meth:`NiDaq.acquire` sets the sample clock for a finite acquisition of ``n`` samples,
starts the task, reads, checks ``in_stream.overloaded_chans_exist`` and stops it. Readings
come back in g (``AccelUnits.G``) and are returned in m/s² (``g = 9.80665 m/s²``).

The task comes from ``task_factory`` (default: ``nidaqmx.Task``), the seam where
:mod:`vibid.hardware_mocks.fake_daq` plugs in a fake; this code has no simulated branch.
Without NI-DAQmx on the machine, opening gives one :class:`DaqUnavailable` line.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

import numpy as np

from vibid.acquisition.protocols import Reading
from vibid.acquisition.stand_config import DaqConfig
from vibid.errors import VibidError

#: standard gravity, m/s² per g
G_M_S2 = 9.80665
CHANNEL_NAMES = ("base", "response")
#: seconds allowed beyond the record's own duration before a read times out
READ_MARGIN_S = 10.0


class DaqError(VibidError):
    """The DAQ refused a setting or failed to acquire."""


class DaqUnavailable(DaqError):
    """NI-DAQmx (the driver or the Python package) is not installed on this machine."""


def nidaqmx_task() -> Any:
    """A new ``nidaqmx.Task``: the default task factory."""
    import nidaqmx

    return nidaqmx.Task()


class NiDaq:
    """Both accelerometers of a stand on one NI-DAQmx task.

    Parameters
    ----------
    sample_rate_hz : the sample clock, Hz (the setup's ``daq.sample_rate_hz``).
    sensitivities_mV_per_g : (base, response) sensor sensitivities, mV/g.
    config : the stand's DAQ section (device, channels, IEPE current in A, range in g).
    task_factory : returns a new task (``nidaqmx.Task`` or a fake with the same calls).
    """

    def __init__(
        self,
        sample_rate_hz: float,
        sensitivities_mV_per_g: tuple[float, float],
        config: DaqConfig = DaqConfig(),
        *,
        task_factory: Callable[[], Any] = nidaqmx_task,
    ):
        self.sample_rate_hz = float(sample_rate_hz)
        self.config = config
        self.physical_channels = (
            f"{config.device}/{config.base_channel}",
            f"{config.device}/{config.response_channel}",
        )
        self.sensitivities_mV_per_g = tuple(float(s) for s in sensitivities_mV_per_g)
        constants = _constants()
        self.task = _guard(task_factory, what="create the task", device=config.device)
        try:
            excitation = (
                constants.ExcitationSource.INTERNAL
                if config.iepe_current_a > 0
                else constants.ExcitationSource.NONE
            )
            for name, physical, sensitivity in zip(
                CHANNEL_NAMES, self.physical_channels, self.sensitivities_mV_per_g
            ):
                _guard(
                    self.task.ai_channels.add_ai_accel_chan,
                    physical,
                    name_to_assign_to_channel=name,
                    min_val=-config.range_g,
                    max_val=config.range_g,
                    units=constants.AccelUnits.G,
                    sensitivity=sensitivity,
                    sensitivity_units=constants.AccelSensitivityUnits.MILLIVOLTS_PER_G,
                    current_excit_source=excitation,
                    current_excit_val=config.iepe_current_a,
                    what=f"add channel {physical}",
                    device=config.device,
                )
        except BaseException:
            self.close()
            raise

    @classmethod
    def from_setup(
        cls,
        setup,
        config: DaqConfig = DaqConfig(),
        *,
        task_factory: Callable[[], Any] = nidaqmx_task,
    ) -> NiDaq:
        """The DAQ of a declared ``setup`` (its sample rate and sensor sensitivities)."""
        sensors = setup.sensors
        return cls(
            setup.daq.sample_rate_hz,
            (sensors.base.sensitivity_mV_per_g, sensors.response.sensitivity_mV_per_g),
            config,
            task_factory=task_factory,
        )

    def acquire(self, n_samples: int) -> Reading:
        """Record ``n_samples`` on both channels now (finite acquisition); m/s²."""
        constants = _constants()
        n = int(n_samples)
        if n < 2:
            raise DaqError(f"DAQ {self.config.device}: a record needs at least 2 samples, got {n}")
        device = self.config.device
        task = self.task
        _guard(
            task.timing.cfg_samp_clk_timing,
            self.sample_rate_hz,
            sample_mode=constants.AcquisitionType.FINITE,
            samps_per_chan=n,
            what="set the sample clock",
            device=device,
        )
        t0_utc = datetime.now(UTC).isoformat()
        _guard(task.start, what="start", device=device)
        try:
            data = _guard(
                task.read,
                number_of_samples_per_channel=n,
                timeout=n / self.sample_rate_hz + READ_MARGIN_S,
                what="read",
                device=device,
            )
            overloaded = ()
            if _guard(
                lambda: task.in_stream.overloaded_chans_exist, what="check overload", device=device
            ):
                overloaded = tuple(
                    _guard(
                        lambda: task.in_stream.overloaded_chans,
                        what="check overload",
                        device=device,
                    )
                )
        finally:
            _guard(task.stop, what="stop", device=device)
        g = np.asarray(data, dtype=np.float64).reshape(len(CHANNEL_NAMES), -1)
        if g.shape[1] != n:
            raise DaqError(f"DAQ {device}: read {g.shape[1]} samples per channel, asked {n}")
        return Reading(
            base_m_s2=g[0] * G_M_S2,
            response_m_s2=g[1] * G_M_S2,
            sample_rate_hz=self.sample_rate_hz,
            t0_utc=t0_utc,
            overloaded=overloaded,
        )

    def close(self) -> None:
        """Release the task (never raises)."""
        task, self.task = getattr(self, "task", None), None
        if task is not None:
            try:
                task.close()
            except Exception:  # noqa: BLE001 - closing must not mask the real error
                pass

    def __enter__(self) -> NiDaq:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _constants():
    try:
        from nidaqmx import constants
    except Exception as exc:  # noqa: BLE001 - ImportError, or a broken installation
        raise DaqUnavailable(
            f"NI-DAQmx is not installed here (the nidaqmx package cannot be imported: {_line(exc)})"
        ) from None
    return constants


def _guard(call, *args, what: str, device: str, **kwargs):
    """``call(*args, **kwargs)`` with nidaqmx's exceptions turned into one-line errors."""
    try:
        return call(*args, **kwargs)
    except VibidError:
        raise
    except Exception as exc:  # noqa: BLE001 - sorted by name below
        kind = type(exc).__name__
        missing = isinstance(exc, (ImportError, OSError)) and what == "create the task"
        if kind in ("DaqNotFoundError", "DaqNotSupportedError") or missing:
            raise DaqUnavailable(
                f"NI-DAQmx is not installed on this machine ({_line(exc)}); "
                "install it, or use the simulated stand"
            ) from None
        if kind.startswith("Daq"):
            raise DaqError(f"DAQ {device}: cannot {what}: {_line(exc)}") from None
        raise


def _line(exc: BaseException) -> str:
    """The first line of an exception's message."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
