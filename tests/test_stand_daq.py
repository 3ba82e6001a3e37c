"""The NI-DAQmx driver against the fake task: what it configures, what it returns."""

import dataclasses

import numpy as np
import pytest
from nidaqmx.constants import AccelSensitivityUnits, AccelUnits, AcquisitionType, ExcitationSource
from nidaqmx.errors import DaqNotFoundError

from vibid.acquisition.daq import G_M_S2, DaqError, DaqUnavailable, NiDaq
from vibid.acquisition.protocols import Daq
from vibid.acquisition.stand import open_stand
from vibid.acquisition.stand_config import DaqConfig, StandConfig
from vibid.hardware_mocks.fake_daq import FakeTask
from vibid.hardware_mocks.virtual_stand import VirtualClock
from vibid.setup_model import example_setup

FS = 25600.0


class Source:
    """Known records in m/s²: a 100 Hz sine of ``amplitudes`` on (base, response)."""

    def __init__(self, amplitudes=(5.0, 40.0)):
        self.clock = VirtualClock()
        self.amplitudes = amplitudes
        self.calls = []

    def record(self, n, fs):
        self.calls.append((n, fs, self.clock.now_s()))
        t = np.arange(n) / fs
        return tuple(a * np.sin(2 * np.pi * 100.0 * t) for a in self.amplitudes)


def open_daq(source, config=DaqConfig(), sensitivities=(98.7, 10.2)):
    tasks = []

    def factory():
        tasks.append(FakeTask(source))
        return tasks[-1]

    return NiDaq(FS, sensitivities, config, task_factory=factory), tasks


def test_channels_are_configured_from_the_setup_and_the_stand():
    config = DaqConfig(
        device="Dev1",
        base_channel="ai2",
        response_channel="ai0",
        iepe_current_a=0.004,
        range_g=40.0,
    )
    daq, (task,) = open_daq(Source(), config, sensitivities=(98.7, 10.2))
    assert isinstance(daq, Daq)
    assert [(c["physical_channel"], c["name"]) for c in task.channels] == [
        ("Dev1/ai2", "base"),
        ("Dev1/ai0", "response"),
    ]
    for channel, sensitivity in zip(task.channels, (98.7, 10.2)):
        assert channel["sensitivity"] == sensitivity
        assert channel["sensitivity_units"] is AccelSensitivityUnits.MILLIVOLTS_PER_G
        assert channel["units"] is AccelUnits.G
        assert (channel["min_val"], channel["max_val"]) == (-40.0, 40.0)
        assert channel["current_excit_source"] is ExcitationSource.INTERNAL
        assert channel["current_excit_val"] == 0.004


def test_zero_current_switches_the_excitation_off():
    daq, (task,) = open_daq(Source(), DaqConfig(iepe_current_a=0.0))
    assert [c["current_excit_source"] for c in task.channels] == [ExcitationSource.NONE] * 2


def test_acquire_sets_the_clock_reads_n_samples_and_returns_m_s2():
    source = Source()
    daq, (task,) = open_daq(source)
    reading = daq.acquire(6400)
    assert (task.timing.rate, task.timing.sample_mode, task.timing.samps_per_chan) == (
        FS,
        AcquisitionType.FINITE,
        6400,
    )
    assert task.reads == [6400] and not task.running
    expected = source.record(6400, FS)
    np.testing.assert_allclose(reading.base_m_s2, expected[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(reading.response_m_s2, expected[1], rtol=1e-12, atol=1e-12)
    assert reading.sample_rate_hz == FS and reading.overloaded == ()
    assert source.clock.now_s() == pytest.approx(6400 / FS)  # the read took the record's time
    daq.acquire(1000)
    assert task.timing.samps_per_chan == 1000 and task.reads == [6400, 1000]
    daq.close()
    assert task.closed


def test_overload_is_reported_and_the_record_clipped():
    # 40 m/s² on a ±2 g range: the response channel clips
    daq, _ = open_daq(Source(amplitudes=(5.0, 40.0)), DaqConfig(range_g=2.0))
    reading = daq.acquire(2560)
    assert reading.overloaded == ("response",)
    assert reading.response_m_s2.max() == pytest.approx(2.0 * G_M_S2)
    assert reading.base_m_s2.max() == pytest.approx(5.0, rel=1e-3)
    assert daq.acquire(2560).overloaded == ("response",)  # each read reports its own


@pytest.mark.parametrize(
    "config, sensitivities, match",
    [
        (
            DaqConfig(base_channel="ai7"),
            (100.0, 100.0),
            r"cannot add channel Dev1/ai7: Physical channel specified does not exist",
        ),
        (
            DaqConfig(range_g=60.0),
            (100.0, 100.0),
            r"cannot add channel Dev1/ai0: Requested value is not a supported value",
        ),
        (
            DaqConfig(iepe_current_a=0.003),
            (100.0, 100.0),
            r"cannot add channel Dev1/ai0: Requested value",
        ),
    ],
)
def test_settings_the_device_refuses_are_one_line(config, sensitivities, match):
    with pytest.raises(DaqError, match=f"^DAQ Dev1: {match}") as info:
        open_daq(Source(), config, sensitivities)
    assert "\n" not in str(info.value)


def test_a_sample_rate_the_device_refuses_is_one_line():
    daq, _ = open_daq(Source())
    daq.sample_rate_hz = 100_000.0
    with pytest.raises(
        DaqError, match=r"^DAQ Dev1: cannot set the sample clock: Requested value"
    ) as info:
        daq.acquire(100)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "error",
    [
        DaqNotFoundError(
            "Could not find an installation of NI-DAQmx. Please ensure that NI-DAQmx "
            "is installed on this machine or contact National Instruments for support."
        ),
        OSError("libnidaqmx.so: cannot open shared object file"),
        ImportError("No module named 'nidaqmx'"),
    ],
)
def test_missing_ni_daqmx_is_one_line(error):
    def factory():
        raise error

    with pytest.raises(DaqUnavailable, match="^NI-DAQmx is not installed on this machine") as info:
        NiDaq(FS, (100.0, 100.0), task_factory=factory)
    assert "\n" not in str(info.value)


def test_ni_stand_on_this_machine_opens_or_says_ni_daqmx_is_missing():
    setup = example_setup()
    try:
        stand = open_stand("ni", setup, StandConfig())
    except DaqUnavailable as exc:
        assert "\n" not in str(exc)
    except DaqError:
        pass  # NI-DAQmx is installed here but has no Dev1
    else:  # pragma: no cover - a lab machine
        stand.close()


def test_from_setup_takes_rate_and_sensitivities_from_the_setup():
    setup = example_setup()
    sensors = dataclasses.replace(
        setup.sensors, base=dataclasses.replace(setup.sensors.base, sensitivity_mV_per_g=9.81)
    )
    setup = dataclasses.replace(setup, sensors=sensors)
    tasks = []
    daq = NiDaq.from_setup(
        setup, DaqConfig(), task_factory=lambda: tasks.append(FakeTask(Source())) or tasks[-1]
    )
    assert daq.sample_rate_hz == setup.daq.sample_rate_hz
    assert [c["sensitivity"] for c in tasks[0].channels] == [9.81, 100.0]


def test_a_failed_read_is_one_line_and_stops_the_task():
    from nidaqmx.errors import DaqError as NiDaqError

    class Failing(Source):
        def record(self, n, fs):
            raise NiDaqError(
                "Some or all of the samples requested have not yet been acquired.\n"
                "Increase the timeout.",
                -200284,
            )

    daq, (task,) = open_daq(Failing())
    with pytest.raises(
        DaqError,
        match=r"^DAQ Dev1: cannot read: Some or all of the samples requested "
        r"have not yet been acquired\.$",
    ):
        daq.acquire(256)
    assert not task.running
