"""Is an identified plate physically possible, and does it look like its material?

:func:`plausibility` judges the identified parameters and the report's engineering
constants (:mod:`vibid.identify.assess.engineering`) and returns sentences; it reads, prints and
logs nothing (the report, the console and the loop say them).

* Violations, whatever the material: an isotropic Poisson's ratio outside (−1, 0.5)
  (positive bulk and shear moduli of an isotropic solid); a bending stiffness matrix
  ``[[D11, D12, D16], [D12, D22, D26], [D16, D26, D66]]`` that is not positive definite
  (the strain energy ``½ κᵀ D κ`` of every curvature must be positive); a negative loss
  factor (the plate would feed energy into its vibration); a modulus ``≤ 0``.
* Handbook ranges: where ``specimen.material`` or, without it, the specimen's name names a
  class (steel, aluminium, titanium, CFRP), each constant with a range in :data:`HANDBOOK`
  lies in it or outside it, by so many standard deviations. A modulus along the length (E,
  E1) more than 2 std outside says what the declared specimen would need to reach the
  range: from bending resonances, ``ω ∝ √(D / ρ h) / L²`` gives ``E ∝ ρ L⁴ / h²``, so the
  range's edge needs the density, the free length or the thickness off by the factor
  ``r``, ``r^¼`` or ``r^-½`` (``r`` the edge over the value) on a bare strip. The response
  sensor's mass does not scale with them: it carries the share ``μ = m φ(x)² / (m_strip +
  m φ(x)²)`` of the first mode's kinetic energy (Rayleigh, with the clamped-free beam's
  first mode ``φ``, ∫φ² = L), and the first frequency stays put where ``r = (1 − μ) a + μ``
  for a density factor ``a``, ``r = c³ ((1 − μ) c + μ)`` for a length factor ``c`` (the
  sensor keeping its place relative to the length) and ``r c³ = (1 − μ) c + μ`` for a
  thickness factor ``c``, each solved for its factor (a sensor of a few grams near a real
  strip's free end carries μ = 0.18, and the density then needs +14 % where the bare
  strip's factor says +12 %: ``tests/test_plausibility.py``).

Sources of the ranges (room temperature, typical values, not design allowables): ASM
Handbook Vol. 1 (Properties and Selection: Irons, Steels) and Vol. 2 (Nonferrous Alloys);
MMPDS (formerly MIL-HDBK-5) for aluminium and titanium alloys; MatWeb's typical values;
CFRP: CMH-17 (Composite Materials Handbook, formerly MIL-HDBK-17) Vol. 2 and Daniel & Ishai,
*Engineering Mechanics of Composite Materials*, typical laminate and unidirectional values.
"""

from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass

GPa = 1e9

#: Handbook ranges ``(low, high)`` by material class, keyed as the report's engineering
#: block (SI units). The one table; a class's key is its name in sentences.
HANDBOOK: dict[str, dict[str, tuple[float, float]]] = {
    # carbon and stainless steels. Handbooks give E 190–215 GPa, ν 0.27–0.31; issue #26's
    # target is E 180–215 GPa, ν 0.25–0.33: the wider ranges are used.
    "steel": {
        "E_Pa": (180 * GPa, 215 * GPa),
        "nu": (0.25, 0.33),
        "G_Pa": (68 * GPa, 86 * GPa),
    },  # G = E/2(1+ν) over the E and ν ranges
    # wrought aluminium alloys (1xxx–7xxx; Al–Li alloys, E up to ~80 GPa, lie above)
    "aluminium": {"E_Pa": (68 * GPa, 73 * GPa), "nu": (0.32, 0.35), "G_Pa": (25 * GPa, 28 * GPa)},
    # CP titanium and alpha/alpha-beta alloys (Ti-6Al-4V: E ≈ 114 GPa); ν: issue #26's range
    "titanium": {
        "E_Pa": (100 * GPa, 125 * GPa),
        "nu": (0.28, 0.38),
        "G_Pa": (36 * GPa, 49 * GPa),
    },  # G = E/2(1+ν) over the E and ν ranges
    # CFRP depends on the lay-up, so its ranges are broad. Isotropic model: a
    # quasi-isotropic laminate (no G range: G follows from E and ν). Orthotropic model:
    # from a balanced woven laminate to unidirectional standard-modulus fibres.
    "CFRP": {
        "E_Pa": (40 * GPa, 80 * GPa),
        "nu": (0.25, 0.35),
        "E1_Pa": (40 * GPa, 200 * GPa),
        "E2_Pa": (5 * GPa, 80 * GPa),
        "G12_Pa": (3 * GPa, 30 * GPa),
        "nu12": (0.02, 0.45),
    },
}
#: An isotropic material identified with an orthotropic model: E1 = E2 = E, G12 = G, ν12 = ν.
_ISOTROPIC_NAME = {"E1_Pa": "E_Pa", "E2_Pa": "E_Pa", "G12_Pa": "G_Pa", "nu12": "nu"}
#: Names of each class, as whole words (lower case, words separated by one space).
_SYNONYMS = {
    "steel": ("steel", "stainless", "inox", "ss"),
    "aluminium": ("aluminium", "aluminum", "al", "alu"),
    "titanium": ("titanium", "ti", "ti6al4v"),
    "CFRP": ("cfrp", "carbon fibre", "carbon fiber"),
}
_WEAK = ("carbon", "CFRP")  # "carbon" alone: CFRP, unless another class is named ("carbon steel")
_SYMBOL = {
    "E_Pa": "E",
    "G_Pa": "G",
    "nu": "ν",
    "E1_Pa": "E1",
    "E2_Pa": "E2",
    "G12_Pa": "G12",
    "nu12": "ν12",
}


@dataclass(frozen=True)
class Plausibility:
    """What :func:`plausibility` found; ``material_class`` is a key of :data:`HANDBOOK`."""

    material_class: str | None
    violations: tuple[str, ...]  # physically impossible values
    outside_handbook: tuple[str, ...]  # constants outside their class's range
    inside_handbook: tuple[str, ...]  # constants inside it

    def warnings(self) -> list[str]:
        return [*self.violations, *self.outside_handbook]


def material_class(specimen_name: str = "", material: str | None = None) -> str | None:
    """The class that ``material`` (if given) or else the name names, None if none or
    several (never a guess)."""
    text = material if material and material.strip() else specimen_name
    words = f" {' '.join(re.findall(r'[a-z0-9]+', text.lower()))} "
    found = {c for c, names in _SYNONYMS.items() for n in names if f" {n} " in words}
    if not found and f" {_WEAK[0]} " in words:
        found = {_WEAK[1]}
    return found.pop() if len(found) == 1 else None


def plausibility(
    model: str,
    parameters: dict[str, float],
    std: dict[str, float],
    constants: dict[str, dict],
    *,
    specimen_name: str = "",
    material: str | None = None,
    specimen=None,
    sensor=None,
) -> Plausibility:
    """Judge ``parameters`` (by name, N·m and 1) with their ``std`` and the engineering
    ``constants`` (``{name: {"value", "std"}}``, values may be None) of a ``model`` plate;
    ``specimen`` (``length_m``, ``width_m``, ``thickness_m``, ``density_kg_m3``: the declared
    one) lets a modulus far outside its range say what the declaration would need, with the
    response ``sensor``'s mass (``mass_kg`` at ``x_m``) where given (module doc)."""
    p = {k: v for k, v in (parameters or {}).items() if _finite(v)}
    std = std or {}
    known = {
        k: c
        for k, c in (constants or {}).items()  # the constants with a value
        if isinstance(c, dict) and _finite(c.get("value"))
    }
    violations = _violations(model, p, std)
    if not violations:  # else an impossible modulus is a consequence already said
        violations += [
            f"{_show(k, c['value'], c.get('std'))} ≤ 0: not a possible modulus"
            for k, c in known.items()
            if k.endswith("_Pa") and c["value"] <= 0
        ]
    cls = material_class(specimen_name, material)
    table = HANDBOOK.get(cls, {})
    inside, outside = [], []
    for key, c in known.items():
        rng = table.get(key) or table.get(_ISOTROPIC_NAME.get(key))
        if rng is not None and key in _SYMBOL:
            (inside if rng[0] <= c["value"] <= rng[1] else outside).append(
                _compare(cls, key, c["value"], c.get("std"), rng)
                + _declared_would_need(
                    key, c["value"], c.get("std"), rng, specimen, sensor_share(specimen, sensor)
                )
            )
    return Plausibility(cls, tuple(violations), tuple(outside), tuple(inside))


def _violations(model: str, p: dict[str, float], std: dict[str, float]) -> list[str]:
    out = []
    if model == "isotropic":
        if "D" in p and p["D"] <= 0:
            out.append(f"D = {_par('D', p, std)} N·m ≤ 0: a bending stiffness must be positive")
        if "nu" in p and not -1 < p["nu"] < 0.5:
            limit = 0.5 if p["nu"] >= 0.5 else -1.0
            out.append(
                f"ν = {_par('nu', p, std)} is not a possible Poisson's ratio of an "
                f"isotropic material, which needs −1 < ν < 0.5"
                f"{_beyond(p['nu'], std.get('nu'), limit)}"
            )
    if all(k in p for k in ("D11", "D12", "D22", "D66")):
        D11, D12, D22, D66 = p["D11"], p["D12"], p["D22"], p["D66"]
        D16, D26 = p.get("D16", 0.0), p.get("D26", 0.0)
        why = [f"{k} = {p[k]:.4g} N·m ≤ 0" for k in ("D11", "D22", "D66") if p[k] <= 0]
        if D12**2 >= D11 * D22:
            why.append(f"D12² = {D12**2:.4g} ≥ D11·D22 = {D11 * D22:.4g} (N·m)²")
        det = (
            D11 * (D22 * D66 - D26**2)
            - D12 * (D12 * D66 - D26 * D16)
            + D16 * (D12 * D26 - D22 * D16)
        )
        if not why and det <= 0:
            why.append(f"its determinant {det:.4g} (N·m)³ ≤ 0 (D16, D26 too large)")
        if why:
            matrix = (
                "[[D11, D12, D16], [D12, D22, D26], [D16, D26, D66]]"
                if "D16" in p or "D26" in p
                else "[[D11, D12, 0], [D12, D22, 0], [0, 0, D66]]"
            )
            out.append(
                f"the bending stiffness matrix {matrix} is not positive definite: " + "; ".join(why)
            )
    out += [
        f"{k} = {_par(k, p, std)} < 0{_beyond(v, std.get(k), 0.0)}: a loss factor "
        f"cannot be negative, the plate would feed energy into its vibration"
        for k, v in p.items()
        if k.startswith("beta") and v < 0
    ]
    return out


def _compare(cls: str, key: str, value: float, sd, rng: tuple[float, float]) -> str:
    scale, unit = (GPa, " GPa") if key.endswith("_Pa") else (1.0, "")
    span = f"{rng[0] / scale:g}–{rng[1] / scale:g}{unit}"
    if rng[0] <= value <= rng[1]:
        return f"{_show(key, value, sd)} lies in {cls}'s range {span}"
    side, limit = ("below", rng[0]) if value < rng[0] else ("above", rng[1])
    by = ""
    if _finite(sd) and sd > 0:
        n = round(abs(value - limit) / sd, 1)
        note = ": consistent with the range within its uncertainty" if n <= 2 else ""
        by = f" (by {n:.1f} std{note})"
    return f"{_show(key, value, sd)} lies {side} {cls}'s handbook range {span}{by}"


def sensor_share(specimen, sensor) -> float:
    """The response sensor's share μ of the first bending mode's kinetic energy (module
    doc); 0 without a sensor or a specimen."""
    if specimen is None or sensor is None or not sensor.mass_kg:
        return 0.0
    L = specimen.length_m
    m_strip = specimen.density_kg_m3 * L * specimen.width_m * specimen.thickness_m
    b = _CANTILEVER_ROOT * min(max(sensor.x_m / L, 0.0), 1.0)
    sigma = (math.cosh(_CANTILEVER_ROOT) + math.cos(_CANTILEVER_ROOT)) / (
        math.sinh(_CANTILEVER_ROOT) + math.sin(_CANTILEVER_ROOT)
    )
    phi = math.cosh(b) - math.cos(b) - sigma * (math.sinh(b) - math.sin(b))  # ∫φ² = L
    m_sensor = sensor.mass_kg * phi**2
    return m_sensor / (m_strip + m_sensor)


#: β₁ L of the clamped-free beam's first mode.
_CANTILEVER_ROOT = 1.8751040687


def _factor(ratio) -> float:
    """The x in [1/8, 8] where the increasing ``ratio(x)`` equals 1, by bisection."""
    lo, hi = 0.125, 8.0
    for _ in range(80):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if ratio(mid) < 1.0 else (lo, mid)
    return math.sqrt(lo * hi)


def _declared_would_need(key: str, value: float, sd, rng, specimen, mu: float = 0.0) -> str:
    """``; from its bending resonances E goes as ρ L⁴ / h²: …`` where a modulus along the
    length lies more than 2 std outside its range (module doc; ``mu`` the sensor's share
    of the first mode); "" otherwise."""
    if key not in ("E_Pa", "E1_Pa") or specimen is None or rng[0] <= value <= rng[1]:
        return ""
    edge = rng[0] if value < rng[0] else rng[1]
    if _finite(sd) and sd > 0 and abs(value - edge) <= 2 * sd:
        return ""
    r = edge / value
    # the factors that keep the first frequency (module doc): the density's, the length's
    # and the thickness's, each minus 1 (relative changes)
    denser = (r - mu) / (1 - mu) - 1
    longer = _factor(lambda c: c**3 * ((1 - mu) * c + mu) / r) - 1
    thinner = _factor(lambda c: r * c**3 / ((1 - mu) * c + mu)) - 1
    clamp = (
        (
            " (or a clamp less rigid than the model's); a clamp whose line lies inside its "
            "jaws lengthens the free span: a reference strip of known modulus in the same "
            "clamp measures it (vibid identify --reference-E)"
        )
        if r > 1
        else ""
    )
    return (
        f"; from bending resonances {_SYMBOL[key]} goes as ρ L⁴ / h²: "
        f"{edge / GPa:g} GPa would need the declared density {100 * denser:+.0f} %, "
        f"the free length {100 * longer:+.1f} % ({1e3 * specimen.length_m * longer:+.2g} "
        f"mm) or the thickness {100 * thinner:+.1f} % "
        f"({1e3 * specimen.thickness_m * thinner:+.2g} mm){clamp}"
    )


def _beyond(value: float, sd, limit: float) -> str:
    """`` (1.3 std above 0.5: ...)``: how far ``value`` is past a physical limit."""
    if not (_finite(sd) and sd > 0):
        return ""
    n = round(abs(value - limit) / sd, 1)
    return (
        f" ({n:.1f} std {'above' if value > limit else 'below'} {limit:g}"
        f"{': possible within its uncertainty' if n <= 2 else ''})"
    )


def _show(key: str, value: float, sd) -> str:
    """``E = 90.3 ± 2.1 GPa``: moduli in GPa, ratios plain; two significant digits of std."""
    # decimals: (fewest, most, without a std)
    scale, unit, (fewest, most, plain) = (
        (GPa, " GPa", (1, 3, 1)) if key.endswith("_Pa") else (1.0, "", (2, 4, 3))
    )
    v, s = value / scale, (sd / scale if _finite(sd) and sd > 0 else None)
    d = plain if s is None else max(fewest, min(most, 1 - math.floor(math.log10(s))))
    pm = "" if s is None else f" ± {s:.{d}f}" if round(s, d) else f" ± {s:.1g}"
    return f"{_SYMBOL.get(key, key)} = {v:.{d}f}{pm}{unit}"


def _par(name: str, p: dict[str, float], std: dict[str, float]) -> str:
    s = std.get(name)
    return f"{p[name]:.4g}" + (f" ± {s:.2g}" if _finite(s) and s > 0 else "")


def _finite(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x)
