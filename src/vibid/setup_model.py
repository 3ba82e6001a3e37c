"""The declared setup of a session: specimen, sensors, DAQ, excitation, identification.

This is the typed form of the ``setup`` JSON document of the session format
(``shared/spec/session-format.md``). Everything is in SI units, as in the JSON.

Reading is two-step, so that a bad document yields every problem at once:

* :func:`Setup.from_dict` converts types and collects what it cannot read;
* :func:`setup_problems` checks meaning (positive dimensions, the sensor disc
  inside the specimen, ordered bounds, ...).

:func:`parse_setup` does both and raises :class:`SetupError` listing the
problems, each as ``"<json path>: <what is wrong>"``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any

from vibid.errors import VibidError

# the catalogue (no numerical import); MODEL_PARAMETERS: the parameter names of each
# material model, in the order the identification uses
from vibid.parameters import (
    EFFECT_PARAMETERS,
    MODEL_PARAMETERS,
    known_effect_parameter,
    material_parameters,
)


class SetupError(VibidError, ValueError):
    """A setup document that cannot be used; ``problems`` lists every reason."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("; ".join(self.problems))


@dataclass(frozen=True)
class Specimen:
    """The plate: the rectangle [0, length_m] x [0, width_m], clamped along x = 0."""

    name: str
    length_m: float
    width_m: float
    thickness_m: float
    density_kg_m3: float
    thickness_std_m: float | None = None  # optional: the thickness's standard uncertainty
    material: str | None = None  # optional free text ("Ti-6Al-4V", "steel"): the handbook class
    # optional standard uncertainties of the declared geometry (the uncertainty budget)
    length_std_m: float | None = None
    width_std_m: float | None = None
    density_std_kg_m3: float | None = None


#: The optional fields (written only when given): standard uncertainties of the declared
#: values (shared/spec/session-format.md; the uncertainty budget, vibid.identify.assess.budget).
SPECIMEN_STD = ("thickness_std_m", "length_std_m", "width_std_m", "density_std_kg_m3")
SPECIMEN_OPTIONAL = SPECIMEN_STD + ("material",)
RESPONSE_STD = ("x_std_m", "y_std_m", "mass_std_kg")


@dataclass(frozen=True)
class BaseSensor:
    """The accelerometer on the shaker table."""

    sensitivity_mV_per_g: float


@dataclass(frozen=True)
class ResponseSensor:
    """The accelerometer on the specimen: a disc of mass ``mass_kg`` and radius ``radius_m``
    centred at (``x_m``, ``y_m``)."""

    sensitivity_mV_per_g: float
    x_m: float
    y_m: float
    mass_kg: float
    radius_m: float
    # optional standard uncertainties of the declared position and mass (uncertainty budget)
    x_std_m: float | None = None
    y_std_m: float | None = None
    mass_std_kg: float | None = None


@dataclass(frozen=True)
class Sensors:
    base: BaseSensor
    response: ResponseSensor


@dataclass(frozen=True)
class Daq:
    sample_rate_hz: float


@dataclass(frozen=True)
class Excitation:
    """The stepped sine: frequencies in the order they are played, the settle time before
    each record (one number for every step, or one per step: a planned test) and the
    minimum record length (``None``: the stand's own rule; a number, or one per step)."""

    frequencies_hz: tuple[float, ...]
    settle_s: float | tuple[float, ...]
    record_s: float | tuple[float, ...] | None = None

    def settle_at(self, i: int) -> float:
        """Seconds to settle before step ``i``'s first record."""
        return _at(self.settle_s, i)

    def record_at(self, i: int) -> float | None:
        """Minimum record length of step ``i``, s (``None``: the stand's rule)."""
        return None if self.record_s is None else _at(self.record_s, i)


def _at(value, i: int) -> float:
    return float(value[i]) if isinstance(value, tuple) else float(value)


@dataclass(frozen=True)
class Identification:
    """Which material model to identify and the prior box of each of its parameters."""

    model: str
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return MODEL_PARAMETERS[self.model]


@dataclass(frozen=True)
class Setup:
    specimen: Specimen
    sensors: Sensors
    daq: Daq
    excitation: Excitation | None  # None: an AFC measured elsewhere (no time records)
    identification: Identification

    # -- conversion ---------------------------------------------------------------
    @classmethod
    def from_dict(cls, doc: Any) -> Setup:
        """Build a setup from the parsed JSON; raise :class:`SetupError` on missing or
        mistyped fields. Meaning is checked by :func:`setup_problems`."""
        reader = _Reader()
        setup = reader.setup(doc)
        if reader.problems:
            raise SetupError(reader.problems)
        return setup

    @classmethod
    def from_json(cls, text: str) -> Setup:
        try:
            doc = json.loads(text, parse_int=_parse_int)
        except (json.JSONDecodeError, TypeError) as exc:
            raise SetupError([f"setup: not valid JSON ({exc})"]) from None
        except RecursionError:
            raise SetupError(["setup: not valid JSON (nested too deeply)"]) from None
        return cls.from_dict(doc)

    def to_dict(self) -> dict[str, Any]:
        doc = asdict(self)
        for part, names in (
            (doc["specimen"], SPECIMEN_OPTIONAL),
            (doc["sensors"]["response"], RESPONSE_STD),
        ):
            for name in names:
                if part[name] is None:
                    del part[name]
        if self.excitation is None:
            del doc["excitation"]
        else:
            exc = doc["excitation"]
            for key in ("frequencies_hz", "settle_s", "record_s"):
                if isinstance(exc[key], (tuple, list)):
                    exc[key] = list(exc[key])
            if exc["record_s"] is None:
                del exc["record_s"]
        doc["identification"]["bounds"] = {
            k: [float(lo), float(hi)] for k, (lo, hi) in self.identification.bounds.items()
        }
        return doc

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent)


def parse_setup(text_or_doc: str | dict) -> Setup:
    """Read and check a setup; raise :class:`SetupError` listing every problem."""
    setup = (
        Setup.from_json(text_or_doc)
        if isinstance(text_or_doc, str)
        else Setup.from_dict(text_or_doc)
    )
    problems = setup_problems(setup)
    if problems:
        raise SetupError(problems)
    return setup


# -- meaning ------------------------------------------------------------------------
def setup_problems(s: Setup) -> list[str]:
    """Every rule of the session format that ``s`` breaks, as ``"path: problem"`` lines."""
    out: list[str] = []

    def positive(path: str, value: float) -> None:
        if not (math.isfinite(value) and value > 0):
            out.append(f"setup.{path}: must be a positive number, got {value!r}")

    sp = s.specimen
    for name in ("length_m", "width_m", "thickness_m", "density_kg_m3"):
        positive(f"specimen.{name}", getattr(sp, name))
    for path, block, names in (
        ("specimen", sp, SPECIMEN_STD),
        ("sensors.response", s.sensors.response, RESPONSE_STD),
    ):
        for name in names:
            v = getattr(block, name)
            if v is not None and not (math.isfinite(v) and v >= 0):
                out.append(f"setup.{path}.{name}: must be zero or positive, got {v!r}")

    positive("sensors.base.sensitivity_mV_per_g", s.sensors.base.sensitivity_mV_per_g)
    r = s.sensors.response
    positive("sensors.response.sensitivity_mV_per_g", r.sensitivity_mV_per_g)
    positive("sensors.response.radius_m", r.radius_m)
    if not (math.isfinite(r.mass_kg) and r.mass_kg >= 0):
        out.append(f"setup.sensors.response.mass_kg: must be zero or positive, got {r.mass_kg!r}")
    inside = (
        r.x_m - r.radius_m >= 0
        and r.x_m + r.radius_m <= sp.length_m
        and r.y_m - r.radius_m >= 0
        and r.y_m + r.radius_m <= sp.width_m
    )
    if not inside:
        out.append(
            "setup.sensors.response: the sensor disc (centre "
            f"x={r.x_m!r} m, y={r.y_m!r} m, radius {r.radius_m!r} m) is not inside the "
            f"specimen [0, {sp.length_m!r}] x [0, {sp.width_m!r}] m"
        )

    positive("daq.sample_rate_hz", s.daq.sample_rate_hz)
    if s.excitation is not None:
        out.extend(_excitation_problems(s))
    out.extend(_identification_problems(s.identification))
    return out


def _excitation_problems(s: Setup) -> list[str]:
    out = []
    freqs = s.excitation.frequencies_hz
    if not freqs:
        out.append("setup.excitation.frequencies_hz: must list at least one frequency")
    for i, f in enumerate(freqs):
        if not (math.isfinite(f) and f > 0):
            out.append(
                f"setup.excitation.frequencies_hz[{i}]: must be a positive number, got {f!r}"
            )
        elif math.isfinite(s.daq.sample_rate_hz) and f >= s.daq.sample_rate_hz / 2:
            out.append(
                f"setup.excitation.frequencies_hz[{i}]: {f!r} Hz is not below the Nyquist "
                f"frequency {s.daq.sample_rate_hz / 2!r} Hz"
            )
    out += _per_step_problems(
        "settle_s", s.excitation.settle_s, len(freqs), lambda v: v >= 0, "zero or positive"
    )
    if s.excitation.record_s is not None:
        out += _per_step_problems(
            "record_s", s.excitation.record_s, len(freqs), lambda v: v > 0, "positive"
        )
    return out


def _per_step_problems(name: str, value, n: int, ok, meaning: str) -> list[str]:
    """Problems of an excitation time given as one number or as one number per step."""
    path = f"setup.excitation.{name}"
    if not isinstance(value, tuple):
        good = math.isfinite(value) and ok(value)
        return [] if good else [f"{path}: must be {meaning}, got {value!r}"]
    if len(value) != n:
        return [f"{path}: lists {len(value)} values for {n} frequencies (one per step)"]
    return [
        f"{path}[{i}]: must be {meaning}, got {v!r}"
        for i, v in enumerate(value)
        if not (math.isfinite(v) and ok(v))
    ]


def _identification_problems(ident: Identification) -> list[str]:
    if ident.model not in MODEL_PARAMETERS:
        return [
            f"setup.identification.model: unknown model {ident.model!r}, "
            f"expected one of {', '.join(MODEL_PARAMETERS)}"
        ]
    out = []
    names = MODEL_PARAMETERS[ident.model]
    own = {q.name: q for q in material_parameters(ident.model)}

    def declared(name: str):
        """The model's or an effect's parameter ``name`` (an instance's too), or None."""
        return own.get(name) or known_effect_parameter(name)

    got = set(ident.bounds)
    if missing := [n for n in names if n not in got]:
        out.append(
            f"setup.identification.bounds: model {ident.model!r} needs bounds for "
            f"{', '.join(missing)}"
        )
    if extra := sorted((n for n in got if declared(n) is None), key=str):
        out.append(
            f"setup.identification.bounds: {', '.join(map(_name, extra))} "
            f"{'is' if len(extra) == 1 else 'are'} not a parameter of model {ident.model!r} "
            f"({', '.join(names)}) nor of an effect ({', '.join(EFFECT_PARAMETERS)})"
        )
    for name, (lo, hi) in ident.bounds.items():
        if (q := declared(name)) is not None and (problem := q.bounds_problem(lo, hi)):
            out.append(f"setup.identification.bounds.{name}: {problem}")
    return out


# -- type conversion ------------------------------------------------------------------
class _Reader:
    """Turns parsed JSON into dataclasses, collecting a message per missing/mistyped field."""

    def __init__(self) -> None:
        self.problems: list[str] = []

    def _obj(self, doc: Any, path: str) -> dict:
        if not isinstance(doc, dict):
            self.problems.append(f"{path}: expected a JSON object, got {_kind(doc)}")
            return {}
        return doc

    def _num(self, doc: dict, key: str, path: str) -> float:
        if key not in doc:
            self.problems.append(f"{path}.{key}: missing")
            return math.nan
        v = doc[key]
        if not _is_number(v):
            self.problems.append(f"{path}.{key}: expected a number, got {_kind(v)}")
            return math.nan
        return self._float(v, f"{path}.{key}")

    def _float(self, v, path: str) -> float:
        """The number ``v`` (a JSON number: :func:`_is_number`) as a float; an integer
        beyond the floats (or beyond Python's digits of an integer string) is a problem
        named by ``path``, not an OverflowError, and reads as nan."""
        try:
            if isinstance(v, _LongInteger):
                raise OverflowError
            return float(v)
        except OverflowError:
            self.problems.append(
                f"{path}: must be a finite number, got an integer of "
                f"{_digits(v)} digits (beyond the floating-point range)"
            )
            return math.nan

    def _str(self, doc: dict, key: str, path: str) -> str:
        if key not in doc:
            self.problems.append(f"{path}.{key}: missing")
            return ""
        if not isinstance(doc[key], str):
            self.problems.append(f"{path}.{key}: expected a string, got {_kind(doc[key])}")
            return ""
        return doc[key]

    def setup(self, doc: Any) -> Setup:
        root = self._obj(doc, "setup")
        sp = self._section(root, "specimen", "setup")
        sen = self._section(root, "sensors", "setup")
        base = self._section(sen, "base", "setup.sensors") if sen else {}
        resp = self._section(sen, "response", "setup.sensors") if sen else {}
        daq = self._section(root, "daq", "setup")
        # an imported AFC's setup has no excitation (session-format.md)
        exc = self._section(root, "excitation", "setup") if "excitation" in root else None
        ide = self._section(root, "identification", "setup")

        p = "setup.specimen"
        specimen = Specimen(
            name=self._str(sp, "name", p) if sp else "",
            length_m=self._num(sp, "length_m", p) if sp else math.nan,
            width_m=self._num(sp, "width_m", p) if sp else math.nan,
            thickness_m=self._num(sp, "thickness_m", p) if sp else math.nan,
            density_kg_m3=self._num(sp, "density_kg_m3", p) if sp else math.nan,
            material=self._str(sp, "material", p) if sp and "material" in sp else None,
            **{k: self._num(sp, k, p) for k in SPECIMEN_STD if sp and k in sp},
        )
        p = "setup.sensors.response"
        sensors = Sensors(
            base=BaseSensor(
                self._num(base, "sensitivity_mV_per_g", "setup.sensors.base") if base else math.nan
            ),
            response=ResponseSensor(
                *(
                    self._num(resp, k, p) if resp else math.nan
                    for k in ("sensitivity_mV_per_g", "x_m", "y_m", "mass_kg", "radius_m")
                ),
                **{k: self._num(resp, k, p) for k in RESPONSE_STD if resp and k in resp},
            ),
        )
        daq_ = Daq(self._num(daq, "sample_rate_hz", "setup.daq") if daq else math.nan)
        excitation = (
            None
            if exc is None
            else Excitation(
                frequencies_hz=self._frequencies(exc) if exc else (),
                settle_s=self._per_step(exc, "settle_s") if exc else math.nan,
                record_s=self._per_step(exc, "record_s") if exc and "record_s" in exc else None,
            )
        )
        identification = Identification(
            model=self._str(ide, "model", "setup.identification") if ide else "",
            bounds=self._bounds(ide) if ide else {},
        )
        return Setup(specimen, sensors, daq_, excitation, identification)

    def _section(self, parent: dict, key: str, path: str) -> dict:
        """The sub-object ``parent[key]``, or {} with a problem recorded."""
        if key not in parent:
            if parent or path == "setup":
                self.problems.append(f"{path}.{key}: missing")
            return {}
        return self._obj(parent[key], f"{path}.{key}")

    def _frequencies(self, exc: dict) -> tuple[float, ...]:
        path = "setup.excitation.frequencies_hz"
        if "frequencies_hz" not in exc:
            self.problems.append(f"{path}: missing")
            return ()
        v = exc["frequencies_hz"]
        if not isinstance(v, list) or not all(map(_is_number, v)):
            self.problems.append(f"{path}: expected a list of numbers")
            return ()
        return tuple(self._float(f, f"{path}[{i}]") for i, f in enumerate(v))

    def _per_step(self, exc: dict, key: str) -> float | tuple[float, ...]:
        """An excitation time: one number, or a list of numbers (one per step)."""
        v = exc.get(key)
        if isinstance(v, list):
            if not all(map(_is_number, v)):
                self.problems.append(
                    f"setup.excitation.{key}: expected a number or a list of numbers"
                )
                return math.nan
            return tuple(self._float(x, f"setup.excitation.{key}[{i}]") for i, x in enumerate(v))
        return self._num(exc, key, "setup.excitation")

    def _bounds(self, ide: dict) -> dict[str, tuple[float, float]]:
        path = "setup.identification.bounds"
        if "bounds" not in ide:
            self.problems.append(f"{path}: missing")
            return {}
        raw = ide["bounds"]
        if not isinstance(raw, dict):
            self.problems.append(f"{path}: expected a JSON object, got {_kind(raw)}")
            return {}
        out = {}
        for name, pair in raw.items():
            where = _field(path, name)
            ok = isinstance(pair, list) and len(pair) == 2 and all(map(_is_number, pair))
            if not ok:
                self.problems.append(f"{where}: expected [low, high], got {_show(pair)}")
                continue
            out[name] = (self._float(pair[0], f"{where}[0]"), self._float(pair[1], f"{where}[1]"))
        return out


def _kind(v: Any) -> str:
    return {
        dict: "an object",
        list: "a list",
        str: "a string",
        bool: "a boolean",
        type(None): "null",
        int: "a number",
        float: "a number",
        _LongInteger: "a number",
    }.get(type(v), type(v).__name__)


class _LongInteger:
    """A JSON integer of more digits than Python converts (``sys.get_int_max_str_digits``),
    kept as its text so that the reader names its field instead of json's ValueError."""

    def __init__(self, text: str) -> None:
        self.text = text


def _parse_int(text: str) -> int | _LongInteger:
    try:
        return int(text)
    except ValueError:  # json matched the digits already: only the digit limit is left
        return _LongInteger(text)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, _LongInteger)) and not isinstance(v, bool)


def _digits(v: int | _LongInteger) -> int:
    """How many digits the integer ``v`` has (without str(), which has a digit limit)."""
    if isinstance(v, _LongInteger):
        return len(v.text.lstrip("-"))
    n, k = abs(v), max(1, int(abs(v).bit_length() * 0.30102999566398120))  # x log10(2)
    while 10**k <= n:  # the count: the least k with n < 10**k
        k += 1
    while k > 1 and 10 ** (k - 1) > n:
        k -= 1
    return k


#: A name that can be written as it is in a JSON path (``setup.identification.bounds.D``).
_PLAIN_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _name(name: Any) -> str:
    """A document's key as a message shows it: as it is when a plain name, else quoted
    (``repr``: a line break or other control character escaped, the message one line)."""
    return name if isinstance(name, str) and _PLAIN_NAME.fullmatch(name) else repr(name)


def _field(path: str, name: Any) -> str:
    """The path of the key ``name`` under ``path``: ``path.name``, or ``path['odd name']``."""
    plain = isinstance(name, str) and _PLAIN_NAME.fullmatch(name)
    return f"{path}.{name}" if plain else f"{path}[{name!r}]"


def _show(v: Any, limit: int = 60) -> str:
    """``v`` as JSON on one line, shortened to about ``limit`` characters."""
    try:
        text = json.dumps(v, default=_kind)
    except (ValueError, TypeError, RecursionError):  # an integer beyond str()'s digits, ...
        text = _kind(v)
    return text if len(text) <= limit else text[:limit] + "..."


def example_setup() -> Setup:
    """The paper's steel strip (Table 1) with its shifted 1 g sensor, 201 steps to 1500 Hz."""
    return Setup(
        specimen=Specimen("steel strip 100x20x1", 0.100, 0.020, 0.001, 7920.0),
        sensors=Sensors(
            base=BaseSensor(100.0),
            response=ResponseSensor(100.0, x_m=0.090, y_m=0.015, mass_kg=0.001, radius_m=0.001),
        ),
        daq=Daq(25600.0),
        excitation=Excitation(tuple(7.5 * k for k in range(1, 201)), settle_s=0.5),
        identification=Identification(
            "isotropic", {"D": (1.0, 100.0), "nu": (0.0, 0.5), "beta": (1e-4, 0.1)}
        ),
    )
