"""The stand configuration (``STAND.json``): the stand's own settings, apart from the specimen.

The declared setup (``setup_model``) says what is tested; this file says how the stand in
this lab is wired and driven. Every field has a default, so ``{}`` is a valid configuration
of the simulated stand. Units are SI, as everywhere in vibid (voltages in volts).

    {
      "generator": {"url": "vibidsim://stand", "baudrate": 9600, "timeout_s": 2.0},
      "daq": {"device": "Dev1", "base_channel": "ai0", "response_channel": "ai1",
              "iepe_current_a": 0.004, "range_g": 50.0},
      "drive": {"target_base_m_s2": 5.0, "tolerance": 0.05, "initial_vpp": 0.2,
                "max_vpp": 5.0, "abort_response_m_s2": 2000.0},
      "timing": {"expected_loss_factor": 0.003, "settle_time_constants": 5.0,
                 "max_settle_s": 10.0, "min_record_s": 0.25, "min_cycles": 20},
      "simulated": {"params": {"D": 17.97, "nu": 0.286, "beta": 0.003},
                    "effects": {"clamp_compliance": {"k_theta_N_per_rad": 16000}},
                    "noise": 0.0004, "seed": 0, "clock_offset_ppm": 40.0,
                    "shaker_m_s2_per_v": 25.0, "faults": []}
    }

``simulated`` describes the virtual specimen and the fake instruments; a real stand
ignores it. ``noise`` is each channel's noise standard deviation relative to the base
acceleration amplitude (as ``vibid simulate --noise``). ``effects`` are undeclared effects of
the library (``vibid.identify.effects``) that the virtual specimen has and the declared setup
does not; an effect that may occur more than once takes a list, e.g. ``"stand_resonance":
[{"f_hz": 660, "q": 30, "theta_rad_per_m": 0.3}]``. ``faults`` are fault injections understood by the mocks (see
``vibid.hardware_mocks``), e.g. ``{"kind": "no_reply", "at_step": 3}``.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from vibid.errors import VibidError


class StandConfigError(VibidError, ValueError):
    """A stand configuration that cannot be used (one line per problem, joined)."""


@dataclass(frozen=True)
class GeneratorConfig:
    url: str = "vibidsim://stand"  #: pyserial URL: ``/dev/ttyUSB0``, ``COM3``, ``vibidsim://...``
    baudrate: int = 9600
    timeout_s: float = 2.0  #: reply timeout of one SCPI query


@dataclass(frozen=True)
class DaqConfig:
    device: str = "Dev1"
    base_channel: str = "ai0"
    response_channel: str = "ai1"
    iepe_current_a: float = 0.004  #: IEPE excitation current, A (0 switches it off)
    range_g: float = 50.0  #: input range, ± g


@dataclass(frozen=True)
class DriveConfig:
    target_base_m_s2: float = 5.0  #: base acceleration amplitude to hold, m/s²
    tolerance: float = 0.05  #: accept the drive when |base| is within ±5 % of target
    initial_vpp: float = 0.2  #: first drive level tried, V peak to peak
    max_vpp: float = 5.0  #: never drive above this, V peak to peak
    abort_response_m_s2: float = 2000.0  #: abort the campaign above this response amplitude


@dataclass(frozen=True)
class TimingConfig:
    expected_loss_factor: float = 0.003  #: for the settle time near a resonance, Q = 1/β
    settle_time_constants: float = 5.0  #: settle this many time constants Q/(π f)
    max_settle_s: float = 10.0
    min_record_s: float = 0.25  #: record at least this long ...
    min_cycles: int = 20  #: ... and at least this many whole cycles


@dataclass(frozen=True)
class SimulatedConfig:
    params: dict[str, float] = field(
        default_factory=lambda: {"D": 17.97, "nu": 0.286, "beta": 0.003}
    )
    effects: dict[str, dict[str, float] | list[dict[str, float]]] = field(default_factory=dict)
    noise: float = 4e-4
    seed: int = 0
    clock_offset_ppm: float = 40.0
    shaker_m_s2_per_v: float = 25.0  #: base acceleration amplitude per volt peak to peak
    faults: tuple[dict[str, Any], ...] = ()


@dataclass(frozen=True)
class StandConfig:
    generator: GeneratorConfig = GeneratorConfig()
    daq: DaqConfig = DaqConfig()
    drive: DriveConfig = DriveConfig()
    timing: TimingConfig = TimingConfig()
    simulated: SimulatedConfig = SimulatedConfig()

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: Any, *, where: str = "stand configuration") -> StandConfig:
        if not isinstance(doc, dict):
            raise StandConfigError(f"{where}: expected a JSON object")
        problems: list[str] = []
        sections = {}
        for f in fields(cls):
            part = doc.get(f.name, {})
            sections[f.name] = _section(f.default.__class__, part, f.name, problems)
        for key in doc:
            if key not in sections:
                problems.append(f"{key}: unknown section (known: {', '.join(sections)})")
        if problems:
            raise StandConfigError(f"{where}: " + "; ".join(problems))
        return cls(**sections)


def _section(kind, part, name: str, problems: list[str]):
    if not isinstance(part, dict):
        problems.append(f"{name}: expected an object")
        return kind()
    values = {}
    known = {f.name: f for f in fields(kind)}
    for key, value in part.items():
        if key not in known:
            problems.append(f"{name}.{key}: unknown setting (known: {', '.join(known)})")
            continue
        default = getattr(kind(), key)
        if isinstance(default, bool) or isinstance(default, str):
            ok = isinstance(value, type(default))
        elif isinstance(default, (int, float)):
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            if (
                ok
                and isinstance(default, int)
                and not isinstance(default, bool)
                and value != int(value)
            ):
                ok = False
            value = type(default)(value) if ok else value
        elif isinstance(default, dict):
            ok = isinstance(value, dict)
        elif isinstance(default, tuple):
            ok = isinstance(value, list)
            value = tuple(value) if ok else value
        else:
            ok = True
        if not ok:
            problems.append(f"{name}.{key}: expected {type(default).__name__}, got {value!r}")
            continue
        values[key] = value
    return kind(**values)


def load_stand_config(path: str | os.PathLike | None) -> StandConfig:
    """Read ``STAND.json``; ``None`` gives the defaults. Errors name the file, one line."""
    if path is None:
        return StandConfig()
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            doc = json.load(fh)
    except OSError as exc:
        raise StandConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise StandConfigError(f"{path}: not JSON: {exc.msg} (line {exc.lineno})") from None
    return StandConfig.from_dict(doc, where=path)
