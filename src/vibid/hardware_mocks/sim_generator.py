"""A simulated SCPI sine generator: the instrument behind the ``vibidsim://NAME`` port.

:class:`SimulatedGenerator` holds the instrument's state (frequency, amplitude, output), its
error queue and its own clock, and answers one command line at a time
(:meth:`SimulatedGenerator.handle`). The pyserial handler
(:mod:`vibid.hardware_mocks.protocol_vibidsim`) finds it by ``NAME`` in a small registry
(:func:`register`, :func:`lookup`) and carries the bytes.

It behaves as a real instrument does: a setting out of its range, an unknown command or a
malformed number leaves the state unchanged and queues an SCPI error (``-222,"Data out of
range"``, ``-113,"Undefined header"``, ``-104,"Data type error"``) to be read with
``SYST:ERR?``. Its time base is off by ``clock_offset_ppm``: it really plays
``f·(1 + ppm·1e-6)`` when commanded ``f`` (:attr:`played_frequency_hz`).

Simulation-only controls carry a ``sim_`` prefix: :meth:`sim_no_reply`,
:meth:`sim_late_reply`, :meth:`sim_queue_error`, :meth:`sim_drop_connection`, :attr:`sim_reply_delay_s`,
:attr:`sim_log`, and scheduled faults (:meth:`sim_schedule`) that fire at the N-th frequency
command, or at the frequency command of a campaign's step N (:attr:`sim_step_index`), once
(:attr:`sim_fired`).

Notes (where this differs from a real instrument): there is no output impedance or load, the
amplitude is exact, a change of setting is instantaneous, and only the commands of
:mod:`vibid.acquisition.generator` (plus ``*RST`` and ``*CLS``) are understood.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vibid.acquisition.protocols import Clock

IDN = "vibid,SimGen 1,0001,1.0"
NO_ERROR = '0,"No error"'
FAULT_KINDS = ("no_reply", "error", "drop")


@dataclass
class ScheduledFault:
    kind: str  #: one of FAULT_KINDS
    at_step: int  #: the 0-based index of the frequency command it fires at
    at_index: int | None = None  #: or the campaign's step index it fires at (if given)
    count: int = 1  #: no_reply: how many replies are lost
    code: int = -310
    message: str = "System error"
    key: int = -1  #: its place in the stand configuration's list (for sim_fired)

    @classmethod
    def of(cls, fault: dict, key: int = -1) -> ScheduledFault:
        """A fault of the stand configuration (``kind``, ``at_step`` or ``at_index``, ...)."""
        at_index = fault.get("at_index")
        return cls(
            str(fault.get("kind")),
            int(fault.get("at_step", 0)),
            None if at_index is None else int(at_index),
            int(fault.get("count", 1)),
            int(fault.get("code", -310)),
            str(fault.get("message", "System error")),
            int(key),
        )

    def due(self, command: int, step_index: int | None) -> bool:
        """Whether it fires at an instrument's ``command``-th frequency command (0-based),
        played for the campaign's step ``step_index``."""
        return self.at_step == command if self.at_index is None else self.at_index == step_index


@dataclass
class SimulatedGenerator:
    """The instrument's state and command interpreter.

    Parameters
    ----------
    clock : the stand's clock (reply delays and the time of the last change are on it).
    clock_offset_ppm : relative error of the instrument's time base, ppm.
    frequency_limits_hz : the instrument's frequency range, Hz.
    max_vpp : the instrument's largest amplitude, V peak to peak.
    """

    clock: Clock
    clock_offset_ppm: float = 0.0
    frequency_limits_hz: tuple[float, float] = (1e-3, 20e6)
    max_vpp: float = 10.0
    frequency_hz: float = 1000.0
    amplitude_vpp: float = 0.1
    output_on: bool = False
    #: clock time of the last change of frequency, amplitude or output, s
    changed_at_s: float = 0.0
    #: state just before the last change: (played frequency Hz, amplitude Vpp, output on)
    previous: tuple[float, float, bool] = (1000.0, 0.1, False)
    #: number of frequency commands accepted so far (the campaign's step count)
    frequency_commands: int = 0
    sim_reply_delay_s: float = 0.0
    sim_log: list[tuple[str, str | None]] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    connected: bool = True
    #: replies held back by :meth:`sim_late_reply`, for the port to deliver late
    late_replies: list[str] = field(default_factory=list)
    _lost_replies: int = 0
    _late: int = 0
    _faults: list[ScheduledFault] = field(default_factory=list)
    #: keys of the scheduled faults that have fired (shared with a reopened stand, so that
    #: each fault fires once: see :class:`~vibid.hardware_mocks.virtual_stand.VirtualStand`)
    sim_fired: set[int] = field(default_factory=set)
    #: the campaign's step now being played (set by the virtual stand's ``begin_step``;
    #: None outside a campaign): a fault with ``at_index`` fires at that step's frequency
    sim_step_index: int | None = None

    # -- what the specimen sees ---------------------------------------------------------
    def played_at(self, frequency_hz: float) -> float:
        """The frequency really played when ``frequency_hz`` is commanded, Hz."""
        return frequency_hz * (1.0 + 1e-6 * self.clock_offset_ppm)

    @property
    def played_frequency_hz(self) -> float:
        """The frequency really played now (the commanded one on the instrument's clock), Hz."""
        return self.played_at(self.frequency_hz)

    @property
    def drive_vpp(self) -> float:
        """The amplitude at the output now, V peak to peak (0 when the output is off)."""
        return self.amplitude_vpp if self.output_on else 0.0

    # -- simulation-only controls -------------------------------------------------------
    def sim_no_reply(self, count: int = 1) -> None:
        """Lose the next ``count`` replies (the command is still carried out)."""
        self._lost_replies += int(count)

    def sim_late_reply(self, count: int = 1) -> None:
        """Hold the next ``count`` replies back until after the host's read timed out: they
        arrive before its next command (:attr:`late_replies`, delivered by the port)."""
        self._late += int(count)

    def sim_queue_error(self, code: int = -310, message: str = "System error") -> None:
        """Put an error in the queue, as an instrument fault would."""
        self.errors.append(f'{int(code)},"{message}"')

    def sim_drop_connection(self) -> None:
        """Unplug the instrument: the port raises on its next read or write."""
        self.connected = False

    def sim_left_playing(self, other: SimulatedGenerator) -> None:
        """Start as ``other`` was left when its link went down: the same frequency, amplitude
        and output, played steadily (no transient until the next change). A reopened stand
        finds the generator still driving the shaker after a dropped connection."""
        self.frequency_hz, self.amplitude_vpp = other.frequency_hz, other.amplitude_vpp
        self.output_on = other.output_on
        self.previous = (self.played_frequency_hz, self.amplitude_vpp, self.output_on)
        self.changed_at_s = -math.inf

    def sim_schedule(self, fault: dict, key: int = -1) -> None:
        """Schedule a fault from the stand configuration, e.g. ``{"kind": "no_reply",
        "at_step": 3}``: it fires when the ``at_step``-th frequency command arrives (counted
        from this instrument's start), or with ``"at_index": N`` at the frequency command of
        the campaign's step ``N`` (whatever the instrument played before); its ``key`` goes
        into :attr:`sim_fired` then."""
        kind = fault.get("kind")
        if kind not in FAULT_KINDS:
            raise ValueError(
                f"unknown fault kind {kind!r}, expected one of {', '.join(FAULT_KINDS)}"
            )
        self._faults.append(ScheduledFault.of(fault, key))

    # -- the instrument -----------------------------------------------------------------
    def handle(self, line: str) -> str | None:
        """Carry out one command line; return the reply line, or None (no reply)."""
        command = line.strip()
        reply = self._execute(command)
        if reply is not None and self._lost_replies > 0:
            self._lost_replies -= 1
            reply = None
        if reply is not None and self._late > 0:
            self._late -= 1
            self.late_replies.append(reply)
            self.sim_log.append((command, reply))
            return None
        self.sim_log.append((command, reply))
        if reply is not None and self.sim_reply_delay_s > 0:
            self.clock.sleep(self.sim_reply_delay_s)
        return reply

    def _execute(self, command: str) -> str | None:
        head, _, arg = command.partition(" ")
        head = head.upper()
        if head == "*IDN?":
            return IDN
        if head == "SYST:ERR?":
            return self.errors.pop(0) if self.errors else NO_ERROR
        if head == "FREQ?":
            return format(self.frequency_hz, ".12g")
        if head == "VOLT?":
            return format(self.amplitude_vpp, ".12g")
        if head == "OUTP?":
            return "1" if self.output_on else "0"
        if head == "FREQ":
            self._set_number(arg, self.frequency_limits_hz, self._set_frequency)
        elif head == "VOLT":
            self._set_number(arg, (0.0, self.max_vpp), lambda v: self._change(amplitude_vpp=v))
        elif head == "OUTP":
            if arg.strip().upper() in ("ON", "1", "OFF", "0"):
                self._change(output_on=arg.strip().upper() in ("ON", "1"))
            else:
                self.errors.append('-104,"Data type error"')
        elif head == "*RST":
            self._change(frequency_hz=1000.0, amplitude_vpp=0.1, output_on=False)
        elif head == "*CLS":
            self.errors.clear()
        else:
            self.errors.append('-113,"Undefined header"')
        return None

    def _set_number(self, text: str, limits: tuple[float, float], apply) -> None:
        try:
            value = float(text)
        except ValueError:
            self.errors.append('-104,"Data type error"')
            return
        if not (math.isfinite(value) and limits[0] <= value <= limits[1]):
            self.errors.append('-222,"Data out of range"')
            return
        apply(value)

    def _set_frequency(self, value: float) -> None:
        step = self.frequency_commands
        self.frequency_commands += 1
        for fault in [f for f in self._faults if f.due(step, self.sim_step_index)]:
            self._faults.remove(fault)
            self.sim_fired.add(fault.key)
            if fault.kind == "no_reply":
                self.sim_no_reply(fault.count)
            elif fault.kind == "error":
                self.sim_queue_error(fault.code, fault.message)
            else:
                self.sim_drop_connection()
        self._change(frequency_hz=value)

    def _change(self, **values) -> None:
        """Apply ``values``; a real change (not a repeat of the state) starts a transient."""
        if all(getattr(self, name) == value for name, value in values.items()):
            return
        self.previous = (self.played_frequency_hz, self.amplitude_vpp, self.output_on)
        for name, value in values.items():
            setattr(self, name, value)
        self.changed_at_s = self.clock.now_s()


_REGISTRY: dict[str, SimulatedGenerator] = {}


def register(name: str, instrument: SimulatedGenerator) -> None:
    """Make ``instrument`` answer at ``vibidsim://name`` (replaces any earlier one)."""
    _REGISTRY[name] = instrument


def lookup(name: str) -> SimulatedGenerator:
    """The instrument registered as ``name``; ``KeyError`` when there is none."""
    return _REGISTRY[name]
