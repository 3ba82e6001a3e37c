"""pyserial URL handler ``vibidsim://NAME``: a serial port wired to a simulated generator.

pyserial finds this module because :mod:`vibid.hardware_mocks` appends itself to
``serial.protocol_handler_packages``; then ``serial.serial_for_url("vibidsim://stand")``
returns a :class:`Serial` connected to the :class:`~vibid.hardware_mocks.sim_generator.
SimulatedGenerator` registered as ``stand``. The shape follows pyserial's own
``serial/urlhandler/protocol_loop.py``.

Bytes written are split into lines; each complete line goes to the instrument, whose reply
(plus ``\\n``) is queued for :meth:`Serial.read`. A read that finds too few bytes waits the
port's ``timeout`` on the *stand's clock* (no real waiting on a virtual clock) and returns
what there is, as a real port does when the instrument is silent. A dropped connection
(``sim_drop_connection``) makes reads and writes raise ``SerialException``, as pyserial does
when a USB adapter is unplugged.
"""

from __future__ import annotations

import urllib.parse

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, to_bytes

from vibid.hardware_mocks.sim_generator import lookup


class Serial(SerialBase):
    """A serial port whose other end is a simulated SCPI generator."""

    BAUDRATES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)

    def __init__(self, *args, **kwargs):
        self.instrument = None
        self._incoming = bytearray()  # written by the host, not yet a whole line
        self._outgoing = bytearray()  # replies waiting to be read
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        parts = urllib.parse.urlsplit(self.port)
        if parts.scheme != "vibidsim" or not parts.netloc:
            raise SerialException(f"expected vibidsim://NAME, got {self.port!r}")
        try:
            self.instrument = lookup(parts.netloc)
        except KeyError:
            raise SerialException(
                f"could not open port {self.port}: no simulated generator named {parts.netloc!r}"
            ) from None
        if not self.instrument.connected:
            raise SerialException(f"could not open port {self.port}: device not connected")
        self._incoming.clear()
        self._outgoing.clear()
        self.is_open = True

    def close(self) -> None:
        self.is_open = False

    def _reconfigure_port(self, *args, **kwargs) -> None:
        """Nothing to configure: the link has no baud rate."""

    def _check(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()
        if not self.instrument.connected:
            raise SerialException(
                "device reports readiness to read but returned no data "
                "(device disconnected or multiple access on port?)"
            )

    def _deliver_late(self) -> None:
        """Replies the instrument held back arrive now (after the host's read timed out)."""
        while self.instrument.late_replies:
            self._outgoing += self.instrument.late_replies.pop(0).encode("ascii") + b"\n"

    @property
    def in_waiting(self) -> int:
        self._check()
        self._deliver_late()
        return len(self._outgoing)

    def write(self, data) -> int:
        self._check()
        self._deliver_late()
        data = to_bytes(data)
        self._incoming += data
        while b"\n" in self._incoming:
            line, _, rest = bytes(self._incoming).partition(b"\n")
            self._incoming = bytearray(rest)
            reply = self.instrument.handle(line.decode("ascii", "replace"))
            if reply is not None:
                self._outgoing += reply.encode("ascii") + b"\n"
        return len(data)

    def read(self, size: int = 1) -> bytes:
        self._check()
        if len(self._outgoing) < size and self._timeout:
            self.instrument.clock.sleep(self._timeout)  # the instrument is silent: time out
        out = bytes(self._outgoing[:size])
        del self._outgoing[:size]
        return out

    def reset_input_buffer(self) -> None:
        self._check()
        self._outgoing.clear()

    def reset_output_buffer(self) -> None:
        self._check()

    def flush(self) -> None:
        self._check()
