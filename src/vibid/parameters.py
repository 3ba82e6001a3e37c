"""The parameter catalogue: every parameter vibid knows, declared once.

Each parameter of the plate model (the material law's moduli and loss factors, each
effect's own) is a :class:`Parameter` here: its name as in the session format and the
report, its SI unit, how the optimisers map it onto the real line, its default prior box,
the value at which its term vanishes, the rule a prior box must respect, and a lab's
one-line description (:data:`DESCRIPTIONS`). The model's terms
(:mod:`vibid.identify.model.materials`, :mod:`vibid.identify.effects`) take their
parameters from here; so do the setup's checks, the command line and the reports, which
thus never import the numerical core (this module imports the standard library only).

Instances: an effect listed in :data:`MULTI_INSTANCE` (``stand_resonance``) may occur
several times in one model. In every flat parameter dict (the setup's bounds, a
command line's ``NAME=VALUE``, a report's values) the k-th instance's parameters carry
the suffix ``_k``, k = 1, 2, ...: ``f_hz_1, q_1, theta_rad_per_m_1, f_hz_2, ...``
(:func:`instance_name`, :func:`split_instance`). :func:`catalogue` lists their parameters
once, unsuffixed; :func:`known_parameter` resolves a suffixed name to its declaration
renamed.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class Parameter:
    """One parameter of a term.

    Attributes
    ----------
    name : as in the session format and the report, e.g. ``"D"``, ``"tau_s"``.
    unit : SI unit, e.g. ``"N m"``, ``"s"``, ``"1"``.
    kind : how the optimisers map it onto the real line (:mod:`vibid.identify.fit.space`):
        ``("log",)``, ``("logit", a, b)`` or ``("linear",)``.
    bounds : default prior box ``(low, high)`` for an effect (None: the setup must give it).
    null : the value at which the term vanishes exactly (None for material parameters;
        may be ``inf``, e.g. a rigid clamp's stiffness).
    rule : what a prior box must respect: ``"positive"``, ``"non-negative"``,
        ``("interval", a, b)`` (open at a, closed at b) or None. A single value respects
        it too, the interval open at both ends (:meth:`value_problem`).
    noun : what the parameter is, for messages (``"a stiffness"``, ``"the loss factor"``).
    limit : ``limit(x, scale) -> str | None``: why value ``x`` is beyond what a specimen
        of the declared sizes ``scale`` (:func:`specimen_scale`) can have, or None; None
        where no physical limit applies beyond ``rule``.
    """

    name: str
    unit: str
    kind: tuple = ("linear",)
    bounds: tuple[float, float] | None = None
    null: float | None = None
    rule: object = None
    noun: str = ""
    limit: Callable[[float, Mapping[str, float]], str | None] | None = None

    def value_problem(self, x: float, scale: Mapping[str, float] | None = None) -> str | None:
        """Why ``x`` cannot be this parameter's value (a specimen's true value, a value to
        evaluate the model at), or None. It must be a finite number (or the parameter's
        null, e.g. a rigid clamp's ``inf``) that respects :attr:`rule`; with ``scale``
        (the declared specimen's sizes, :func:`specimen_scale`) also :attr:`limit`."""
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            return f"{self.name} must be a number, got {x!r}"
        if x == self.null:
            return None
        if not math.isfinite(x):
            return f"{self.name} must be a finite number, got {x!r}"
        what = f"{self.name} ({self.noun})" if self.noun else self.name
        if self.rule == "positive" and not x > 0:
            return f"{what} must be positive, got {x!r}"
        if self.rule == "non-negative" and x < 0:
            return f"{what} cannot be negative, got {x!r}"
        if isinstance(self.rule, tuple) and self.rule[0] == "interval":
            a, b = self.rule[1], self.rule[2]
            if not a < x < b:
                return f"{what} must lie in ({a:g}, {b:g}), got {x!r}"
        if self.limit is not None and scale is not None:
            return self.limit(x, scale)
        return None

    def bounds_problem(self, low: float, high: float) -> str | None:
        """Why ``[low, high]`` cannot be this parameter's prior box, or None."""
        if not (math.isfinite(low) and math.isfinite(high)):
            return f"bounds must be finite, got [{low!r}, {high!r}]"
        if not low < high:
            return f"low {low!r} must be below high {high!r}"
        if self.rule == "positive" and low <= 0:
            return f"{self.name} is {self.noun or 'positive'} and must be positive, low is {low!r}"
        if self.rule == "non-negative" and low < 0:
            return f"{self.noun or self.name} cannot be negative, low is {low!r}"
        if isinstance(self.rule, tuple) and self.rule[0] == "interval":
            a, b = self.rule[1], self.rule[2]
            if not (a < low and high <= b):
                return f"{self.noun} bounds must lie in ({a:g}, {b:g}], got [{low!r}, {high!r}]"
        return None


# -- the material --------------------------------------------------------------------------
# The moment law is ``M = D κ`` with the moduli D11, D12, D16, D22, D26, D66 (N·m) and complex
# moduli ``D_α (1 + i β_α)`` (:mod:`vibid.identify.model.materials`). Material parameters
# have no default box (the setup gives it) and no null.
def _stiffness(name: str, signed: bool = False) -> Parameter:
    if signed:
        return Parameter(name, "N m", ("linear",))
    return Parameter(name, "N m", ("log",), rule="positive", noun="a stiffness")


def _loss(name: str) -> Parameter:
    return Parameter(name, "1", ("log",), rule="non-negative", noun="the loss factor")


#: The isotropic plate's flexural rigidity.
D = _stiffness("D")
NU = Parameter(
    "nu", "1", ("logit", -1.0, 0.5), rule=("interval", -1.0, 0.5), noun="Poisson's ratio"
)
D11 = _stiffness("D11")
#: D12, D16 and D26 may be negative.
D12 = _stiffness("D12", True)
D22 = _stiffness("D22")
D66 = _stiffness("D66")
D16 = _stiffness("D16", True)
D26 = _stiffness("D26", True)

#: One loss factor for every modulus.
BETA = _loss("beta")
#: One loss factor per modulus (``per_modulus_loss``).
BETA11 = _loss("beta11")
BETA12 = _loss("beta12")
BETA22 = _loss("beta22")
BETA66 = _loss("beta66")
BETA16 = _loss("beta16")
BETA26 = _loss("beta26")
#: Every loss factor by name.
LOSS_FACTORS: dict[str, Parameter] = {
    q.name: q for q in (BETA, BETA11, BETA12, BETA22, BETA66, BETA16, BETA26)
}

#: Stiffness parameters of each material model, in the order the identification uses.
STIFFNESS: dict[str, tuple[Parameter, ...]] = {
    "isotropic": (D, NU),
    "orthotropic": (D11, D12, D22, D66),
    "monoclinic": (D11, D12, D22, D66, D16, D26),
}
#: Loss factors of each model with one loss per modulus (isotropic: ``beta11`` for D11
#: and D22).
PER_MODULUS_LOSS: dict[str, tuple[str, ...]] = {
    "isotropic": ("beta11", "beta12", "beta66"),
    "orthotropic": ("beta11", "beta12", "beta22", "beta66"),
    "monoclinic": ("beta11", "beta12", "beta22", "beta66", "beta16", "beta26"),
}
#: The material models, by their session-format names.
MODELS: tuple[str, ...] = tuple(STIFFNESS)


def material_parameters(model: str, per_modulus_loss: bool = False) -> tuple[Parameter, ...]:
    """The parameters of material ``model``: its stiffness, then its loss factor(s).

    Raises :class:`ValueError` for an unknown model."""
    if model not in STIFFNESS:
        raise ValueError(f"unknown model {model!r}, expected one of {', '.join(MODELS)}")
    losses = PER_MODULUS_LOSS[model] if per_modulus_loss else ("beta",)
    return STIFFNESS[model] + tuple(LOSS_FACTORS[n] for n in losses)


#: Parameter names of each material model with one loss factor (the setup's models).
MODEL_PARAMETERS: dict[str, tuple[str, ...]] = {
    m: tuple(q.name for q in material_parameters(m)) for m in MODELS
}

#: Every material parameter by name (every model, one or per-modulus loss).
MATERIAL_PARAMETERS: dict[str, Parameter] = {
    q.name: q for m in MODELS for pml in (False, True) for q in material_parameters(m, pml)
}


# -- physical limits of a value, given the declared specimen --------------------------------
def specimen_scale(setup) -> dict[str, float]:
    """The declared sizes a parameter's value is judged against (:attr:`Parameter.limit`):
    the specimen's mass ``specimen_mass_kg`` (kg) and free length ``length_m``, its width
    ``width_m`` and the response sensor's centre across it, ``sensor_y_m`` (m). ``setup``:
    a :class:`vibid.setup_model.Setup` (read by attribute: no import)."""
    sp, r = setup.specimen, setup.sensors.response
    return {
        "specimen_mass_kg": sp.density_kg_m3 * sp.length_m * sp.width_m * sp.thickness_m,
        "length_m": sp.length_m,
        "width_m": sp.width_m,
        "sensor_y_m": r.y_m,
    }


def _lighter_than_the_specimen(x: float, scale: Mapping[str, float]) -> str | None:
    """An undeclared mass at the sensor (glue, a cable's share, a sensor declared too
    light) is a small part of what vibrates: one as heavy as the whole plate is another
    specimen, a mass on a spring (a cantilever's first bending frequency falls with a tip
    mass M as 1/sqrt(M + 0.24 m), to 0.44 of the bare plate's at M = m, and the modes the
    identification resolves are the mass's), no detail the setup left out."""
    m = scale.get("specimen_mass_kg")
    if m is not None and math.isfinite(m) and x > m:
        return (
            f"mass_kg (the added mass) {x!r} kg outweighs the specimen that carries it "
            f"({m:.4g} kg): declare such a mass in the setup's sensor, not as an effect"
        )
    return None


def _a_free_length_left(x: float, scale: Mapping[str, float]) -> str | None:
    """The free length ``length_m + dL_m`` is a length: positive."""
    length = scale.get("length_m")
    if length is not None and math.isfinite(length) and not length + x > 0:
        return (
            f"dL_m (the free length's change) {x!r} m leaves no free length (the "
            f"declared free length is {length:g} m)"
        )
    return None


def _on_the_plate(x: float, scale: Mapping[str, float]) -> str | None:
    """The sensor's centre, moved across the width by ``x``, is on the plate (a sensor
    off its edge measures nothing of it)."""
    y, width = scale.get("sensor_y_m"), scale.get("width_m")
    if y is not None and width is not None and not 0 <= y + x <= width:
        return (
            f"sensor_dy_m (the sensor's offset across the width) {x!r} m puts the "
            f"sensor's centre off the plate (declared at y = {y:g} m of its {width:g} m)"
        )
    return None


# -- the effects (vibid.identify.effects, one module each) ---------------------------------
#: ``added_mass``: an undeclared point mass at the response sensor (null 0).
MASS = Parameter(
    "mass_kg",
    "kg",
    ("log",),
    bounds=(0.0, 5e-3),
    null=0.0,
    rule="non-negative",
    noun="the added mass",
    limit=_lighter_than_the_specimen,
)
#: ``channel_delay``: the response channel's delay against the base channel (null 0).
TAU = Parameter("tau_s", "s", ("linear",), bounds=(-1e-4, 1e-4), null=0.0, noun="the delay")
#: ``clamp_compliance``: a rotational spring per metre of clamped edge (null: the rigid
#: clamp, ``inf``).
K_THETA = Parameter(
    "k_theta_N_per_rad",
    "N/rad",
    ("log",),
    bounds=(1e2, 1e9),
    null=math.inf,
    rule="positive",
    noun="a stiffness",
)
#: ``frequency_dependent_loss``: the exponent of ``β (f / 1 kHz)^α`` (null 0).
ALPHA = Parameter("alpha", "1", ("linear",), bounds=(-1.0, 1.0), null=0.0, noun="the loss exponent")
#: ``sensor_gain``: the response sensor's sensitivity against the base sensor's (null 1).
GAIN = Parameter(
    "gain", "1", ("log",), bounds=(0.8, 1.25), null=1.0, rule="positive", noun="a gain"
)
#: ``sensor_position``: the response sensor's offset across the width (null 0). The box
#: is also the reach of the interpolation across the width
#: (:func:`vibid.identify.effects.sensor_position.places`): its error grows with the
#: offset, and on a real strip's setup grew from below 2e-4 of |H| to 5.7e-4 at ±10 mm.
DY = Parameter(
    "sensor_dy_m",
    "m",
    ("linear",),
    bounds=(-5e-3, 5e-3),
    null=0.0,
    noun="the sensor's offset across the width",
    limit=_on_the_plate,
)
#: ``transverse_shear``: the transverse shear modulus, a parameter on an orthotropic or
#: monoclinic plate only (an isotropic plate's follows from E and nu); null: the term
#: absent.
G13 = Parameter(
    "G13_Pa", "Pa", ("log",), bounds=(1e8, 1e11), null=None, rule="positive", noun="a shear modulus"
)
#: ``stand_resonance`` (several instances, :data:`MULTI_INSTANCE`): a resonance of the
#: stand, its frequency, quality factor and the base rotation per base translation.
F_HZ = Parameter(
    "f_hz",
    "Hz",
    ("log",),
    bounds=(5.0, 5000.0),
    null=None,
    rule="positive",
    noun="a resonance frequency",
)
Q = Parameter(
    "q", "1", ("log",), bounds=(2.0, 500.0), null=None, rule="positive", noun="a quality factor"
)
THETA = Parameter(
    "theta_rad_per_m",
    "rad/m",
    ("linear",),
    bounds=(-5.0, 5.0),
    null=0.0,
    noun="the base rotation per base translation",
)
#: ``fixture_resonance``: a resonance of the fixture that carries the clamp, which the base
#: sensor beside it does not share: its frequency, quality factor and the clamp's share of
#: it (the fixture's motion at the clamp per unit table motion, quasi-statically; null 0).
F_FIXTURE = Parameter(
    "f_fixture_hz",
    "Hz",
    ("log",),
    bounds=(5.0, 5000.0),
    null=None,
    rule="positive",
    noun="a resonance frequency",
)
Q_FIXTURE = Parameter(
    "q_fixture",
    "1",
    ("log",),
    bounds=(2.0, 500.0),
    null=None,
    rule="positive",
    noun="a quality factor",
)
A_FIXTURE = Parameter(
    "a_fixture",
    "1",
    ("linear",),
    bounds=(-2.0, 2.0),
    null=0.0,
    noun="the clamp's share of the fixture's mode",
)
#: ``clamp_loss``: the clamp's own loss factor (its null is the plate's beta, not a
#: fixed number). Its physical range starts at 0, the lossless spring (report format), so
#: its box does too, on a linear scale (a log scale cannot reach 0).
BETA_CLAMP = Parameter(
    "beta_clamp",
    "1",
    ("linear",),
    bounds=(0.0, 0.5),
    null=None,
    rule="non-negative",
    noun="the clamp's loss factor",
)
#: ``free_length``: the change of the plate's free length (null 0).
DL = Parameter(
    "dL_m",
    "m",
    ("linear",),
    bounds=(-5e-3, 5e-3),
    null=0.0,
    noun="the free length's change",
    limit=_a_free_length_left,
)
#: ``sensor_inertia``: the height of the response sensor's centre of mass (null 0).
HEIGHT = Parameter(
    "height_m",
    "m",
    ("linear",),
    bounds=(0.0, 0.02),
    null=0.0,
    rule="non-negative",
    noun="the sensor's height",
)

#: Every effect's parameters by effect name, in every material's form (``transverse_shear``
#: has ``G13_Pa`` on an orthotropic or monoclinic plate only: :func:`effect_parameters`).
EFFECT_PARAMETERS_BY_EFFECT: dict[str, tuple[Parameter, ...]] = {
    "added_mass": (MASS,),
    "channel_delay": (TAU,),
    "clamp_compliance": (K_THETA,),
    "clamp_loss": (BETA_CLAMP,),
    "fixture_resonance": (F_FIXTURE, Q_FIXTURE, A_FIXTURE),
    "free_length": (DL,),
    "frequency_dependent_loss": (ALPHA,),
    "sensor_gain": (GAIN,),
    "sensor_inertia": (HEIGHT,),
    "sensor_position": (DY,),
    "stand_resonance": (F_HZ, Q, THETA),
    "transverse_shear": (G13,),
}
#: Effects that may occur several times in one model (their parameters' names carry the
#: instance's suffix ``_k`` in a flat parameter dict).
MULTI_INSTANCE: tuple[str, ...] = ("stand_resonance",)
#: Effect parameters that an isotropic plate's form of their effect lacks.
_NOT_ISOTROPIC = frozenset({"G13_Pa"})


def effect_parameters(effect: str, model: str | None = None) -> tuple[Parameter, ...]:
    """The parameters of ``effect`` (unsuffixed) on a plate of material ``model`` (None:
    in every material's form, as :data:`EFFECT_PARAMETERS_BY_EFFECT`); KeyError for an
    unknown effect."""
    params = EFFECT_PARAMETERS_BY_EFFECT[effect]
    if model == "isotropic":
        params = tuple(q for q in params if q.name not in _NOT_ISOTROPIC)
    return params


#: Every effect parameter by name (unsuffixed for instance effects).
EFFECT_PARAMETERS: dict[str, Parameter] = {
    q.name: q for params in EFFECT_PARAMETERS_BY_EFFECT.values() for q in params
}

#: The effect of each effect parameter (unsuffixed name -> effect name).
EFFECT_OF: dict[str, str] = {
    q.name: e for e, params in EFFECT_PARAMETERS_BY_EFFECT.items() for q in params
}

_INSTANCE_PARAMETERS = frozenset(
    q.name for e in MULTI_INSTANCE for q in EFFECT_PARAMETERS_BY_EFFECT[e]
)
_SUFFIX = re.compile(r"^(.+)_([1-9][0-9]*)$")


# -- instances -----------------------------------------------------------------------------
def instance_name(name: str, k: int) -> str:
    """The name of parameter ``name`` of the ``k``-th instance (k = 1, 2, ...) of its
    effect: ``instance_name("f_hz", 2) == "f_hz_2"``. ValueError when ``name`` is not a
    parameter of a :data:`MULTI_INSTANCE` effect or ``k`` is not a positive integer."""
    if name not in _INSTANCE_PARAMETERS:
        raise ValueError(
            f"{name!r} is not a parameter of an effect with instances ({', '.join(MULTI_INSTANCE)})"
        )
    if isinstance(k, bool) or not isinstance(k, int) or k < 1:
        raise ValueError(f"an instance is numbered 1, 2, ..., got {k!r}")
    return f"{name}_{k}"


def split_instance(name: str) -> tuple[str, int | None]:
    """``(base name, k)`` of an instance parameter's name (``"q_1"`` -> ``("q", 1)``), else
    ``(name, None)`` (``"q"`` -> ``("q", None)``, ``"beta11"`` -> ``("beta11", None)``)."""
    m = _SUFFIX.match(name)
    if m and m.group(1) in _INSTANCE_PARAMETERS:
        return m.group(1), int(m.group(2))
    return name, None


def flat_values(effect: str, instances: list[dict]) -> dict[str, float]:
    """One flat parameter dict from an effect's values given per instance, each with its
    parameters unsuffixed (``[{"f_hz": 660, ...}, ...]`` -> ``{"f_hz_1": 660, ...}``); an
    effect without instances takes one. ValueError, in a sentence that names what to give,
    when an item's names are not the effect's or it occurs more often than it may."""
    own = sorted(q.name for q in effect_parameters(effect))
    several = effect in MULTI_INSTANCE
    if len(instances) > 1 and not several:
        raise ValueError(f"{effect} occurs once, given {len(instances)} times")
    out = {}
    for k, values in enumerate(instances, start=1):
        if not isinstance(values, dict) or set(values) != set(own):
            got = ", ".join(sorted(values)) if isinstance(values, dict) else repr(values)
            raise ValueError(f"give {', '.join(own)}, got {got or 'nothing'}")
        out |= {(instance_name(n, k) if several else n): float(v) for n, v in values.items()}
    return out


# -- look-ups ------------------------------------------------------------------------------
def _build() -> dict[str, Parameter]:
    out = dict(MATERIAL_PARAMETERS)
    for name, q in EFFECT_PARAMETERS.items():
        if name in out:
            raise AssertionError(f"parameter {name!r} is declared twice")
        out[name] = q
    return out


_CATALOGUE: dict[str, Parameter] = _build()


def catalogue() -> dict[str, Parameter]:
    """Every parameter by name: every material model's, then every effect's (instance
    effects' unsuffixed). A new dict each call."""
    return dict(_CATALOGUE)


def known_parameter(name: str) -> Parameter | None:
    """The declaration of parameter ``name``, or None if no term has it. An instance's
    name (``"f_hz_2"``) gives its effect's declaration renamed (``name == "f_hz_2"``)."""
    q = _CATALOGUE.get(name)
    if q is not None:
        return q
    base, k = split_instance(name)
    if k is None:
        return None
    return dataclasses.replace(_CATALOGUE[base], name=name)


def known_effect_parameter(name: str) -> Parameter | None:
    """Like :func:`known_parameter` for the effects' parameters only (None for a material
    parameter)."""
    base, _ = split_instance(name)
    return known_parameter(name) if base in EFFECT_PARAMETERS else None


# -- what a lab calls them -----------------------------------------------------------------
#: What a lab engineer calls each parameter (and each engineering constant the report
#: derives from them), one line each; units come from the declarations.
DESCRIPTIONS: dict[str, str] = {
    "D": "bending stiffness",
    "nu": "Poisson's ratio",
    "beta": "loss factor",
    "D11": "bending stiffness along the length",
    "D22": "bending stiffness across",
    "D12": "coupling stiffness",
    "D66": "twisting stiffness",
    "D16": "coupling stiffness 16",
    "D26": "coupling stiffness 26",
    "E_Pa": "Young's modulus",
    "G_Pa": "shear modulus",
    "E1_Pa": "Young's modulus along the length",
    "E2_Pa": "Young's modulus across",
    "G12_Pa": "in-plane shear modulus",
    "nu12": "Poisson's ratio 12",
    "sensor_dy_m": "sensor offset across the width",
    "beta11": "loss factor of D11",
    "beta12": "loss factor of D12",
    "beta22": "loss factor of D22",
    "beta66": "loss factor of D66",
    "beta16": "loss factor of D16",
    "beta26": "loss factor of D26",
    "mass_kg": "undeclared mass at the sensor",
    "tau_s": "delay between the channels",
    "k_theta_N_per_rad": "clamp's rotational stiffness per metre of edge",
    "alpha": "loss factor's frequency exponent",
    "gain": "response sensor's relative gain",
    "G13_Pa": "transverse shear modulus",
    "f_hz": "stand resonance's frequency",
    "q": "stand resonance's quality factor",
    "theta_rad_per_m": "stand resonance's base rotation per base translation",
    "beta_clamp": "clamp's loss factor",
    "dL_m": "change of the free length",
    "height_m": "sensor's height",
    "f_fixture_hz": "fixture resonance's frequency",
    "q_fixture": "fixture resonance's quality factor",
    "a_fixture": "clamp's share of the fixture resonance",
}


def describe(name: str) -> str:
    """The one-line description of a parameter or engineering constant (an instance's
    ends with its number: ``"stand resonance's frequency (2)"``); "" when unknown."""
    if name in DESCRIPTIONS:
        return DESCRIPTIONS[name]
    base, k = split_instance(name)
    if k is None or base not in DESCRIPTIONS:
        return ""
    return f"{DESCRIPTIONS[base]} ({k})"


__all__ = [
    "Parameter",
    # material
    "D",
    "NU",
    "D11",
    "D12",
    "D22",
    "D66",
    "D16",
    "D26",
    "BETA",
    "BETA11",
    "BETA12",
    "BETA22",
    "BETA66",
    "BETA16",
    "BETA26",
    "LOSS_FACTORS",
    "STIFFNESS",
    "PER_MODULUS_LOSS",
    "MODELS",
    "MODEL_PARAMETERS",
    "MATERIAL_PARAMETERS",
    "material_parameters",
    # effects
    "MASS",
    "TAU",
    "K_THETA",
    "ALPHA",
    "GAIN",
    "DY",
    "G13",
    "F_HZ",
    "Q",
    "THETA",
    "BETA_CLAMP",
    "DL",
    "HEIGHT",
    "F_FIXTURE",
    "Q_FIXTURE",
    "A_FIXTURE",
    "EFFECT_PARAMETERS_BY_EFFECT",
    "EFFECT_PARAMETERS",
    "EFFECT_OF",
    "MULTI_INSTANCE",
    "effect_parameters",
    # instances and look-ups
    "instance_name",
    "split_instance",
    "catalogue",
    "known_parameter",
    "known_effect_parameter",
    "DESCRIPTIONS",
    "describe",
    "specimen_scale",
]
