"""`vibid devices [--timeout-s 0.5]`: what the stand can see.

Serial ports (pyserial's ``list_ports``), each with the ``*IDN?`` of the generator where one
answers, then the NI-DAQmx devices and their analog input channels, or one line saying
NI-DAQmx is not installed.
"""

from __future__ import annotations


def add_parser(sub):
    p = sub.add_parser(
        "devices",
        help="list serial ports and NI-DAQmx devices",
        description=__doc__.split("\n\n")[1],
    )
    p.add_argument(
        "--timeout-s",
        type=float,
        default=0.5,
        help="how long to wait for each port's *IDN? reply, s (default 0.5)",
    )
    p.add_argument("--baudrate", type=int, default=9600, help="baud rate of the query")
    p.set_defaults(run=run)


def serial_lines(timeout_s: float, baudrate: int) -> list[str]:
    """One line per serial port: device, description, and the generator's identity."""
    from serial.tools.list_ports import comports

    from vibid.acquisition.generator import GeneratorError, open_generator

    lines = []
    for port in sorted(comports(), key=lambda p: p.device):
        try:
            with_idn = open_generator(port.device, baudrate=baudrate, timeout_s=timeout_s)
        except GeneratorError as exc:
            idn = f"cannot open ({exc})"
        else:
            try:
                idn = f"*IDN? {with_idn.query('*IDN?')}"
            except GeneratorError:
                idn = "no reply to *IDN?"
            finally:
                with_idn.port.close()  # only asked: leave the instrument's output as it is
        lines.append(f"  {port.device}  {port.description or ''}  {idn}".rstrip())
    return lines or ["  (none)"]


def ni_lines() -> list[str]:
    """One line per NI-DAQmx device with its analog inputs, or one line why there are none."""
    try:
        import nidaqmx.system

        system = nidaqmx.system.System.local()
        version = system.driver_version
        devices = list(system.devices)
    except Exception as exc:  # noqa: BLE001 - DaqNotFoundError, ImportError, OSError, ...
        if type(exc).__name__ in ("DaqNotFoundError", "DaqNotSupportedError") or isinstance(
            exc, (ImportError, OSError)
        ):
            return ["  NI-DAQmx is not installed on this machine"]
        return [f"  NI-DAQmx cannot list devices: {' '.join(str(exc).split())[:200]}"]
    lines = [f"  NI-DAQmx {version.major_version}.{version.minor_version}.{version.update_version}"]
    for device in devices:
        channels = ", ".join(device.ai_physical_chans.channel_names) or "no analog inputs"
        lines.append(f"  {device.name}  {device.product_type}  {channels}")
    if not devices:
        lines.append("  (no devices)")
    return lines


def run(args) -> int:
    from vibid.errors import VibidError

    if not args.timeout_s > 0:
        raise VibidError("--timeout-s must be positive")
    print("serial ports:")
    print("\n".join(serial_lines(args.timeout_s, args.baudrate)))
    print("NI-DAQmx devices:")
    print("\n".join(ni_lines()))
    return 0
