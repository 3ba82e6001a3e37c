"""The SCPI generator driver against the simulated instrument, through pyserial.

Exact-protocol tests (PyMeasure's ``expected_protocol``): the instrument's log of
(command, reply) pairs must equal the expected list, every reply must have been read and no
byte left in either direction.
"""

import contextlib
import itertools
import math

import pytest

import vibid.hardware_mocks  # noqa: F401  (registers the vibidsim:// scheme with pyserial)
from vibid.acquisition.generator import (
    GeneratorError,
    GeneratorTimeout,
    ScpiGenerator,
    open_generator,
)
from vibid.acquisition.protocols import Generator
from vibid.errors import VibidError
from vibid.hardware_mocks.sim_generator import IDN, SimulatedGenerator, register
from vibid.hardware_mocks.virtual_stand import VirtualClock

OK = '0,"No error"'
_names = itertools.count()


def instrument_and_driver(*, timeout_s=0.05, max_vpp=5.0, clock=None, **state):
    clock = clock or VirtualClock()
    inst = SimulatedGenerator(clock, **state)
    name = f"gen{next(_names)}"
    register(name, inst)
    return inst, open_generator(f"vibidsim://{name}", timeout_s=timeout_s, max_vpp=max_vpp)


@contextlib.contextmanager
def expected_protocol(pairs, **kwargs):
    """Yield a driver on a fresh simulated instrument; on exit, assert that the
    instrument saw exactly ``pairs`` and that nothing is left unread or unsent."""
    inst, gen = instrument_and_driver(**kwargs)
    yield gen
    assert inst.sim_log == list(pairs)
    assert gen.port.in_waiting == 0
    assert not gen.port._incoming


def test_driver_is_a_generator():
    _, gen = instrument_and_driver()
    assert isinstance(gen, Generator)


@pytest.mark.parametrize(
    "name, value, command",
    [
        ("frequency_hz", 123.4, "FREQ 123.4"),
        ("frequency_hz", 1499.99025, "FREQ 1499.99025"),
        ("amplitude_vpp", 0.5, "VOLT 0.5"),
        ("output_enabled", True, "OUTP ON"),
        ("output_enabled", False, "OUTP OFF"),
    ],
)
def test_set_sends_one_command_then_reads_the_error_queue(name, value, command):
    with expected_protocol([(command, None), ("SYST:ERR?", OK)]) as gen:
        setattr(gen, name, value)


@pytest.mark.parametrize(
    "name, state, reply, value",
    [
        ("frequency_hz", {"frequency_hz": 250.5}, ("FREQ?", "250.5"), 250.5),
        ("amplitude_vpp", {"amplitude_vpp": 0.125}, ("VOLT?", "0.125"), 0.125),
        ("output_enabled", {"output_on": True}, ("OUTP?", "1"), True),
        ("output_enabled", {"output_on": False}, ("OUTP?", "0"), False),
        ("idn", {}, ("*IDN?", IDN), IDN),
    ],
)
def test_get_sends_one_query(name, state, reply, value):
    with expected_protocol([reply], **state) as gen:
        assert getattr(gen, name) == value


@pytest.mark.parametrize(
    "name, value",
    [
        ("frequency_hz", 0.0),
        ("frequency_hz", 30e6),
        ("frequency_hz", math.nan),
        ("frequency_hz", "fast"),
        ("amplitude_vpp", 5.5),
        ("amplitude_vpp", 0.0),
        ("output_enabled", "yes"),
        ("output_enabled", 1),
    ],
)
def test_out_of_range_raises_before_any_byte(name, value):
    with expected_protocol([], max_vpp=5.0) as gen:
        with pytest.raises(GeneratorError, match=f"{name}: .*") as info:
            setattr(gen, name, value)
    assert "\n" not in str(info.value)


def test_refused_setting_is_reported_and_output_goes_off():
    # the driver allows 7 V (max_vpp 10) but this instrument's maximum is 5 V
    inst, gen = instrument_and_driver(max_vpp=10.0, output_on=True, amplitude_vpp=1.0)
    inst.max_vpp = 5.0
    with pytest.raises(GeneratorError, match=r"after 'VOLT 7': -222 Data out of range$"):
        gen.amplitude_vpp = 7.0
    assert inst.sim_log == [
        ("VOLT 7", None),
        ("SYST:ERR?", '-222,"Data out of range"'),
        ("SYST:ERR?", OK),
        ("OUTP OFF", None),
        ("SYST:ERR?", OK),
    ]
    assert inst.amplitude_vpp == 1.0 and not inst.output_on


def test_every_queued_error_is_read_and_counted():
    inst, gen = instrument_and_driver()
    inst.sim_queue_error(-310, "System error")
    inst.sim_queue_error(-350, "Queue overflow")
    with pytest.raises(GeneratorError, match=r"-310 System error \(and 1 more\)"):
        gen.frequency_hz = 100.0
    assert [c for c, _ in inst.sim_log].count("SYST:ERR?") == 4  # 2 errors, 0, then after OUTP OFF
    assert not inst.errors


def test_no_reply_is_a_timeout_on_the_stands_clock():
    clock = VirtualClock()
    inst, gen = instrument_and_driver(clock=clock, timeout_s=0.25, frequency_hz=80.0)
    inst.sim_no_reply()
    with pytest.raises(
        GeneratorTimeout,
        match=r"^generator at vibidsim://gen\d+: no reply to 'FREQ\?' within 0.25 s$",
    ):
        gen.frequency_hz  # noqa: B018
    assert clock.now_s() == pytest.approx(0.25)  # waited the timeout, virtually
    assert gen.frequency_hz == 80.0  # the next query is answered


def test_a_late_reply_is_discarded_so_replies_never_shift():
    inst, gen = instrument_and_driver(frequency_hz=80.0, amplitude_vpp=0.3)
    inst.sim_late_reply()
    with pytest.raises(GeneratorTimeout):
        gen.frequency_hz  # noqa: B018 - its reply comes after the timeout ...
    assert gen.amplitude_vpp == 0.3  # ... and is not taken for the next query's
    assert gen.port.in_waiting == 0


def test_reply_delay_takes_time_on_the_stands_clock():
    clock = VirtualClock()
    inst, gen = instrument_and_driver(clock=clock)
    inst.sim_reply_delay_s = 0.01
    assert gen.idn == IDN
    assert clock.now_s() == pytest.approx(0.01)


def test_scheduled_no_reply_at_a_step_stops_the_output():
    inst, gen = instrument_and_driver(output_on=True)
    inst.sim_schedule({"kind": "no_reply", "at_step": 1})
    gen.frequency_hz = 100.0
    with pytest.raises(GeneratorTimeout, match="no reply to 'SYST:ERR\\?'"):
        gen.frequency_hz = 110.0
    assert inst.frequency_hz == 110.0 and not inst.output_on


def test_dropped_connection_is_one_line_and_shutdown_does_not_raise():
    inst, gen = instrument_and_driver(output_on=True)
    inst.sim_drop_connection()
    with pytest.raises(
        GeneratorError,
        match="^generator at vibidsim://gen\\d+: cannot send 'FREQ 100': device reports readiness",
    ) as info:
        gen.frequency_hz = 100.0
    assert "\n" not in str(info.value)
    gen.shutdown()
    gen.close()
    assert inst.output_on  # nothing reached it: the real instrument would keep playing


def test_unknown_port_is_one_line():
    with pytest.raises(
        VibidError, match="^generator at vibidsim://nobody: cannot open: could not open port"
    ):
        open_generator("vibidsim://nobody")
    with pytest.raises(VibidError, match="^generator at nosuch://x: cannot open: invalid URL"):
        open_generator("nosuch://x")


def _step(gen: ScpiGenerator, frequency_hz: float):
    gen.frequency_hz = frequency_hz
    gen.output_enabled = True


def test_output_off_after_an_exception_in_the_middle_of_a_step():
    inst, gen = instrument_and_driver()
    with pytest.raises(RuntimeError):
        with gen:
            _step(gen, 200.0)
            raise RuntimeError("the DAQ failed")
    assert not inst.output_on
    assert inst.sim_log[-2:] == [("OUTP OFF", None), ("SYST:ERR?", OK)]
    assert not gen.port.is_open


class _InterruptOnce(VirtualClock):
    """A clock whose first sleep is interrupted by Ctrl-C (as while waiting for a reply)."""

    armed = False

    def sleep(self, seconds):
        if self.armed:
            self.armed = False
            raise KeyboardInterrupt
        super().sleep(seconds)


def test_output_off_after_ctrl_c_while_waiting_for_a_reply():
    clock = _InterruptOnce()
    inst, gen = instrument_and_driver(clock=clock)
    inst.sim_reply_delay_s = 0.01
    with pytest.raises(KeyboardInterrupt):
        with gen:
            _step(gen, 200.0)
            assert inst.output_on
            clock.armed = True
            gen.frequency_hz = 210.0  # Ctrl-C arrives while SYST:ERR? is awaited
    assert not inst.output_on
    assert inst.sim_log[-2:] == [("OUTP OFF", None), ("SYST:ERR?", OK)]
