"""The report's values as a person reads them: units, ``value ± std`` rounded to the std,
and the one list of identified quantities (:func:`quantities`) that report.md, the console
summary, the AFC figure's box, the batch summary and the Prefect UI's parameter table all
take from the JSON report, so that none of them shows a number the JSON does not hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from vibid.parameters import describe, known_parameter


def unit_of(name: str) -> str:
    """The SI unit of a report parameter (material, effect or engineering constant)."""
    if name.endswith("_Pa"):
        return "Pa"
    q = known_parameter(name)
    return "1" if q is None else q.unit


def unit_text(unit: str) -> str:
    """A unit written after a number: ``" N·m"``; nothing for a dimensionless ``"1"``."""
    return "" if unit == "1" else f" {unit.replace(' ', '·')}"


def with_std(value, std) -> str:
    """``value ± std`` with the value rounded to the std's second significant digit."""
    if value is None:
        return "n/a"
    if std is None or not math.isfinite(std) or std <= 0:
        return f"{value:.6g}"
    digits = max(0, 1 - int(math.floor(math.log10(std))))
    if abs(value) >= 1e5 or (abs(value) < 1e-3 and value != 0):
        exp = int(math.floor(math.log10(abs(value))))
        scale = 10.0**exp
        d = max(0, 1 - int(math.floor(math.log10(std / scale))))
        return f"({value / scale:.{d}f} ± {std / scale:.{d}f})e{exp:+d}"
    return f"{value:.{digits}f} ± {std:.{digits}f}"


def reading(value, std, unit: str) -> str:
    """``value ± std unit``, as the console and the figures write a quantity."""
    return with_std(value, std) + unit_text(unit)


def chi2_text(x) -> str:
    """A χ² (or score, or p value) to four significant digits; "n/a" for null."""
    return "n/a" if x is None else f"{x:.4g}"


def percent_text(x) -> str:
    """A ratio as a percentage to three significant digits; "n/a" for null."""
    return "n/a" if x is None else f"{100 * x:.3g} %"


def stage_label(added: str | None) -> str:
    """A loop stage by what it added: ``"declared model"``, ``"+ channel_delay"``."""
    return "declared model" if added is None else f"+ {added}"


def flat_name(effect: dict, name: str) -> str:
    """An effect parameter's name in a flat list: with the instance's suffix ``_k`` for an
    effect that occurs more than once (report format)."""
    return name if "instance" not in effect else f"{name}_{effect['instance']}"


def engineering_of(report: dict) -> dict:
    """The report's engineering constants (``engineering`` without its ``budget``)."""
    return {n: p for n, p in report.get("engineering", {}).items() if n != "budget"}


@dataclass(frozen=True)
class Quantity:
    """One identified quantity of a report, as every summary shows it."""

    #: the parameter's name (an effect instance's with its suffix ``_k``)
    name: str
    value: float | None
    std: float | None
    #: SI unit, ``"1"`` when dimensionless
    unit: str
    #: where it comes from: ``"model"``, the effect's name, or ``"engineering"``
    source: str

    @property
    def meaning(self) -> str:
        """What a lab engineer calls it (:func:`vibid.parameters.describe`)."""
        return describe(self.name)

    @property
    def text(self) -> str:
        """``value ± std`` (:func:`with_std`)."""
        return with_std(self.value, self.std)

    @property
    def reading(self) -> str:
        """``value ± std unit`` (:func:`reading`)."""
        return reading(self.value, self.std, self.unit)


def quantities(report: dict) -> list[Quantity]:
    """Every identified quantity of ``report``: the model's parameters, the effects'
    parameters, the engineering constants, in that order."""
    rows = [
        Quantity(n, p["value"], p["std"], unit_of(n), "model")
        for n, p in report["parameters"].items()
    ]
    rows += [
        Quantity(flat_name(e, n), p["value"], p["std"], unit_of(n), e["name"])
        for e in report["effects"]
        for n, p in e["parameters"].items()
    ]
    rows += [
        Quantity(n, p["value"], p["std"], unit_of(n), "engineering")
        for n, p in engineering_of(report).items()
    ]
    return rows


def parameter_table(report: dict) -> list[dict[str, Any]]:
    """The Prefect UI's parameter table: one row per :func:`quantities` entry, with its
    meaning and ``value ± std`` as report.md writes them, and the bare numbers (SI units)."""
    return [
        {
            "quantity": q.name,
            "meaning": q.meaning,
            "value ± std": q.text,
            "unit": q.unit,
            "source": q.source,
            "value": q.value,
            "std": q.std,
        }
        for q in quantities(report)
    ]
