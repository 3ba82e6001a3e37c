"""The signal generator that drives the shaker: SCPI over a serial port (pyserial).

Each SCPI setting is declared once, as a :class:`Setting` of :class:`ScpiGenerator`: its
query and set commands, its validator and its range. Setting a value checks the range
*before any byte is sent*, sends the command, then reads the instrument's error queue
(``SYST:ERR?``) and raises :class:`GeneratorError` if the instrument refused it. Reading a
value queries the instrument.

The port comes from :func:`open_generator`, which calls ``serial.serial_for_url`` with the
stand configuration's URL: a real port (``/dev/ttyUSB0``, ``COM3``) and the simulated
instrument (``vibidsim://NAME``, a pyserial protocol handler in :mod:`vibid.hardware_mocks`)
take the same path through this code.

Safety: :meth:`ScpiGenerator.shutdown` switches the output off and never raises; the context
manager, :meth:`ScpiGenerator.close` and every error path of a set call it, so the shaker
stops on any exit (an exception in the middle of a step, Ctrl-C, a dropped connection).

Protocol (commands end with ``\\n``; replies are one line)::

    *IDN?            -> "maker,model,serial,firmware"
    FREQ <hz>        FREQ?  -> "<hz>"
    VOLT <vpp>       VOLT?  -> "<vpp>"           (amplitude in volts peak to peak)
    OUTP ON|OFF      OUTP?  -> "1"|"0" (or "ON"|"OFF")
    SYST:ERR?        -> '0,"No error"' or '<code>,"<message>"'
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from vibid.errors import VibidError

log = logging.getLogger(__name__)

TERMINATOR = b"\n"
#: How many queued errors one ``SYST:ERR?`` sweep reads at most (a real queue holds ~20).
MAX_QUEUED_ERRORS = 32


class GeneratorError(VibidError):
    """The generator refused a command, its port failed, or a value was out of range."""


class GeneratorTimeout(GeneratorError):
    """The generator did not answer a query within the port's timeout."""


class Setting:
    """One SCPI setting of an instrument, declared once (PyMeasure ``Instrument.control``).

    Parameters
    ----------
    get_command : the query, e.g. ``"FREQ?"``.
    set_command : the set command with one ``{}`` for the formatted value, e.g. ``"FREQ {}"``.
    doc : docstring: "Control ..., unit (type, range)".
    limits : ``(low, high)`` inclusive range of a number, or the name of an instance
        attribute holding it (a limit the instance chooses, e.g. the stand's ``max_vpp``).
    to_text : formats a validated value for the set command.
    from_text : parses the query's reply.
    """

    def __init__(
        self,
        get_command: str,
        set_command: str,
        doc: str,
        *,
        limits: tuple[float, float] | str | None = None,
        to_text: Callable[[Any], str] = lambda v: format(float(v), ".12g"),
        from_text: Callable[[str], Any] = float,
        kind: type = float,
    ):
        self.get_command = get_command
        self.set_command = set_command
        self.limits = limits
        self.to_text = to_text
        self.from_text = from_text
        self.kind = kind
        self.__doc__ = doc

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, instrument, owner=None):
        if instrument is None:
            return self
        reply = instrument.query(self.get_command)
        try:
            return self.from_text(reply)
        except (TypeError, ValueError):
            raise GeneratorError(
                f"{instrument.name}: cannot read the reply {reply!r} to {self.get_command!r}"
            ) from None

    def __set__(self, instrument, value) -> None:
        command = self.set_command.format(self.to_text(self.validate(instrument, value)))
        try:
            instrument.write(command)
            instrument.check_errors(command)
        except GeneratorError:
            if command != "OUTP OFF":  # a refused or lost command: stop the shaker first
                instrument.shutdown()
            raise

    def validate(self, instrument, value):
        """The value as sent, or :class:`GeneratorError` (nothing has been sent yet)."""
        if self.kind is bool:
            if not isinstance(value, bool):
                raise GeneratorError(f"{self.name}: expected True or False, got {value!r}")
            return value
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise GeneratorError(f"{self.name}: expected a number, got {value!r}") from None
        limits = getattr(instrument, self.limits) if isinstance(self.limits, str) else self.limits
        if limits is not None and not (limits[0] <= number <= limits[1]):  # NaN fails too
            raise GeneratorError(
                f"{self.name}: {number!r} is outside [{limits[0]:g}, "
                f"{limits[1]:g}]; nothing was sent"
            )
        return number


def _on_off(reply: str) -> bool:
    text = reply.strip().upper()
    if text in ("1", "ON"):
        return True
    if text in ("0", "OFF"):
        return False
    raise ValueError(reply)


class ScpiGenerator:
    """A SCPI sine generator on an open pyserial port (implements ``protocols.Generator``).

    Parameters
    ----------
    port : an open ``serial.SerialBase`` (its ``timeout`` is the reply timeout).
    name : how messages name the instrument (the URL).
    max_vpp : the highest amplitude this driver will ever command, V peak to peak (the
        stand's drive limit; the instrument's own maximum is checked by the instrument).
    """

    #: the generator's frequency range this driver accepts, Hz
    FREQUENCY_LIMITS_HZ = (1e-3, 20e6)
    #: the smallest amplitude this driver accepts, V peak to peak
    MIN_VPP = 1e-3

    frequency_hz = Setting(
        "FREQ?",
        "FREQ {}",
        "Control the output frequency, Hz (float, 1 mHz to 20 MHz).",
        limits=FREQUENCY_LIMITS_HZ,
    )
    amplitude_vpp = Setting(
        "VOLT?",
        "VOLT {}",
        "Control the output amplitude, V peak to peak (float, 1 mV to ``max_vpp``).",
        limits="amplitude_limits_vpp",
    )
    output_enabled = Setting(
        "OUTP?",
        "OUTP {}",
        "Control the output: True drives the shaker (bool).",
        to_text=lambda on: "ON" if on else "OFF",
        from_text=_on_off,
        kind=bool,
    )

    def __init__(self, port, *, name: str = "generator", max_vpp: float = 10.0):
        self.port = port
        self.name = name
        self.amplitude_limits_vpp = (self.MIN_VPP, float(max_vpp))

    # -- I/O: the only place that touches the port --------------------------------------
    def write(self, command: str) -> None:
        """Send one command line."""
        try:
            self.port.write(command.encode("ascii") + TERMINATOR)
        except Exception as exc:  # noqa: BLE001 - pyserial raises SerialException, OSError, ...
            raise GeneratorError(f"{self.name}: cannot send {command!r}: {_text(exc)}") from None

    def query(self, command: str) -> str:
        """Send one query and return its reply line (without the terminator). A late reply
        to an earlier, timed-out query is discarded first, so replies never shift."""
        try:
            stale = self.port.in_waiting and self.port.read(self.port.in_waiting)
        except Exception as exc:  # noqa: BLE001
            raise GeneratorError(
                f"{self.name}: connection lost before {command!r}: {_text(exc)}"
            ) from None
        if stale:
            log.warning("%s: discarded a late reply %r before %r", self.name, stale, command)
        self.write(command)
        try:
            reply = self.port.read_until(TERMINATOR)
        except Exception as exc:  # noqa: BLE001
            raise GeneratorError(
                f"{self.name}: connection lost waiting for the reply to {command!r}: {_text(exc)}"
            ) from None
        if not reply.endswith(TERMINATOR):
            raise GeneratorTimeout(
                f"{self.name}: no reply to {command!r} within {self.port.timeout:g} s"
            )
        return reply[: -len(TERMINATOR)].decode("ascii", "replace").strip()

    def check_errors(self, after: str = "") -> None:
        """Read the error queue until it is empty; raise :class:`GeneratorError` naming the
        first error (and how many followed) if there was any."""
        errors = []
        for _ in range(MAX_QUEUED_ERRORS):
            reply = self.query("SYST:ERR?")
            code, _, message = reply.partition(",")
            try:
                if int(code) == 0:
                    break
            except ValueError:
                raise GeneratorError(
                    f"{self.name}: unexpected reply {reply!r} to 'SYST:ERR?'"
                ) from None
            errors.append(f"{code.strip()} {message.strip().strip(chr(34))}")
        if errors:
            more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
            after = f" after {after!r}" if after else ""
            raise GeneratorError(f"{self.name}: instrument error{after}: {errors[0]}{more}")

    # -- identity, safe state -----------------------------------------------------------
    @property
    def idn(self) -> str:
        """Measure the instrument's identification (``*IDN?``), str."""
        return self.query("*IDN?")

    def shutdown(self) -> None:
        """Set the safe state: output off. Never raises (a failure is logged)."""
        try:
            self.output_enabled = False
        except Exception as exc:  # noqa: BLE001 - the safe state must not raise
            log.warning("%s: could not confirm the output is off: %s", self.name, exc)

    def close(self) -> None:
        """Output off, then release the port. Never raises."""
        try:
            self.shutdown()
        finally:
            try:
                self.port.close()
            except Exception as exc:  # noqa: BLE001
                log.warning("%s: closing the port failed: %s", self.name, exc)

    def __enter__(self) -> ScpiGenerator:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_generator(
    url: str, *, baudrate: int = 9600, timeout_s: float = 2.0, max_vpp: float = 10.0
) -> ScpiGenerator:
    """Open the generator at a pyserial ``url`` (``/dev/ttyUSB0``, ``COM3``,
    ``vibidsim://NAME``) and return its driver; the output is left as it is (the campaign
    switches it off first thing). Failure to open is one :class:`GeneratorError` line."""
    import serial

    try:
        port = serial.serial_for_url(url, baudrate=baudrate, timeout=timeout_s)
    except (serial.SerialException, ValueError, OSError) as exc:
        raise GeneratorError(f"generator at {url}: cannot open: {_text(exc)}") from None
    return ScpiGenerator(port, name=f"generator at {url}", max_vpp=max_vpp)


def _text(exc: BaseException) -> str:
    """An exception as one line."""
    return " ".join(str(exc).split()) or type(exc).__name__
