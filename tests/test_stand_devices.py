"""`vibid devices`: serial ports with the generator's identity, NI-DAQmx devices or one line."""

import serial.tools.list_ports
from serial.tools.list_ports_common import ListPortInfo

import vibid.hardware_mocks  # noqa: F401  (the vibidsim:// scheme)
from vibid.cli import main
from vibid.cli.devices import ni_lines
from vibid.hardware_mocks.sim_generator import IDN, SimulatedGenerator, register
from vibid.hardware_mocks.virtual_stand import VirtualClock


def _port(device, description):
    info = ListPortInfo(device, skip_link_detection=True)
    info.description = description
    return info


def test_devices_lists_ports_with_idn_and_says_what_it_knows_of_ni(monkeypatch, capsys):
    generator = SimulatedGenerator(VirtualClock(), output_on=True)
    register("devtest", generator)
    silent = SimulatedGenerator(VirtualClock())
    silent.sim_no_reply()
    register("silent", silent)
    monkeypatch.setattr(
        serial.tools.list_ports,
        "comports",
        lambda: [
            _port("vibidsim://devtest", "USB serial"),
            _port("vibidsim://silent", "USB serial"),
            _port("vibidsim://gone", "unplugged"),
        ],
    )
    assert main(["devices", "--timeout-s", "0.01"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[:4] == [  # sorted by device
        "serial ports:",
        f"  vibidsim://devtest  USB serial  *IDN? {IDN}",
        "  vibidsim://gone  unplugged  cannot open (generator at vibidsim://gone: cannot open: "
        "could not open port vibidsim://gone: no simulated generator named 'gone')",
        "  vibidsim://silent  USB serial  no reply to *IDN?",
    ]
    assert out[4] == "NI-DAQmx devices:"
    assert out[5:] == ni_lines()
    assert generator.output_on  # listing only asks *IDN?; it changes nothing
    assert generator.sim_log == [("*IDN?", IDN)]


def test_devices_bad_timeout_is_one_line(capsys):
    assert main(["devices", "--timeout-s", "0"]) == 1
    assert capsys.readouterr().err == "vibid devices: error: --timeout-s must be positive\n"
