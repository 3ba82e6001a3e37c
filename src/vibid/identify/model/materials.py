"""Material terms: physical parameters → the six bending moduli and their loss factors.

The moment law (session format) is ``M = D κ`` with ``κ = (w,xx, w,yy, 2 w,xy)`` and the
symmetric 3 x 3 matrix ``D`` of the moduli ``D11, D12, D16, D22, D26, D66`` (N·m). Damping
enters as complex moduli ``D̂_α = D_α (1 + i β_α)`` (paper eq. 3.1.1). Each modulus scales
one bending matrix (:mod:`vibid.identify.model.forms`).

Models (names as in the session format):

* ``isotropic``: ``D, nu`` with ``D11 = D22 = D``, ``D12 = nu D``, ``D66 = (1 - nu) D / 2``;
* ``orthotropic``: ``D11, D12, D22, D66`` (``D16 = D26 = 0``);
* ``monoclinic``: the orthotropic set plus ``D16, D26``;

followed by the loss: one ``beta`` for all moduli, or with ``per_modulus_loss`` one
``beta<ij>`` per independent modulus (isotropic: ``beta11`` for D11 and D22, ``beta12``,
``beta66``; orthotropic: ``beta11, beta12, beta22, beta66``; monoclinic adds ``beta16,
beta26``).
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import MODULI, Parameter, Term

# The parameters' declarations (units, transforms, prior rules) are the catalogue's:
# STIFFNESS (stiffness parameters of each model, in the order the identification uses),
# PER_MODULUS_LOSS (loss factors of each model with one loss per modulus), MODELS.
from vibid.parameters import (  # noqa: F401  (NU: this module's public name)
    MODELS,
    NU,
    PER_MODULUS_LOSS,
    STIFFNESS,
    material_parameters,
)


def flexural_rigidity(young_pa: float, poisson: float, thickness_m: float) -> float:
    """Isotropic flexural rigidity.

    Parameters
    ----------
    young_pa : Young's modulus E in Pa.
    poisson : Poisson's ratio ν.
    thickness_m : plate thickness h in m.

    Returns
    -------
    D = E h³ / (12 (1 - ν²)) in N·m.
    """
    return young_pa * thickness_m**3 / (12.0 * (1.0 - poisson**2))


def isotropic_moduli(D, nu):
    """``(D11, D12, D16, D22, D26, D66)`` of an isotropic plate of rigidity D (N·m)."""
    return (D, nu * D, 0.0 * D, D, 0.0 * D, 0.5 * (1.0 - nu) * D)


@dataclass(frozen=True)
class Material(Term):
    """The material law as a term: its parameters scale the six bending matrices.

    Attributes
    ----------
    model : ``"isotropic"``, ``"orthotropic"`` or ``"monoclinic"``.
    per_modulus_loss : one loss factor per modulus instead of a single ``beta``.
    """

    model: str
    per_modulus_loss: bool = False
    stiffness_matrices = MODULI

    def __post_init__(self):
        if self.model not in MODELS:
            raise ValueError(f"unknown model {self.model!r}, expected one of {', '.join(MODELS)}")

    @property
    def name(self) -> str:
        return self.model

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return material_parameters(self.model, self.per_modulus_loss)

    @property
    def stiffness_names(self) -> tuple[str, ...]:
        return tuple(q.name for q in STIFFNESS[self.model])

    @property
    def proportional(self) -> bool:
        return not self.per_modulus_loss

    def common_loss(self, p: dict):
        """The loss factor that terms without their own dissipate with."""
        return p["beta11"] if self.per_modulus_loss else p["beta"]

    def stiffness(self, p: dict, xp) -> dict:
        zero = 0.0 * p[self.stiffness_names[0]]
        if self.model == "isotropic":
            vals = isotropic_moduli(p["D"], p["nu"])
        else:
            vals = (p["D11"], p["D12"], p.get("D16", zero), p["D22"], p.get("D26", zero), p["D66"])
        if not self.per_modulus_loss:
            losses = (p["beta"],) * 6
        elif self.model == "isotropic":
            losses = (p["beta11"], p["beta12"], zero, p["beta11"], zero, p["beta66"])
        else:
            losses = (
                p["beta11"],
                p["beta12"],
                p.get("beta16", zero),
                p["beta22"],
                p.get("beta26", zero),
                p["beta66"],
            )
        return dict(zip(MODULI, zip(vals, losses)))

    def bounds_from(self, bounds: dict) -> dict:
        """Bounds for every parameter, taking loss bounds from ``beta`` when per-modulus
        and holding an undeclared D16, D26 at 0."""
        out = {}
        for n in self.names:
            if n in bounds:
                out[n] = tuple(bounds[n])
            elif n.startswith("beta") and "beta" in bounds:
                out[n] = tuple(bounds["beta"])
            elif n in ("D16", "D26"):
                out[n] = (0.0, 0.0)
        return out


def infer_material(names) -> Material:
    """The material whose parameters are among ``names`` (the rest may be effects')."""
    names = set(names)
    for model in MODELS:
        for pml in (True, False):
            m = Material(model, pml)
            if set(m.names) <= names and not (set(m.names) ^ names) & _MATERIAL_NAMES:
                return m
    raise KeyError(
        "parameters " + ", ".join(sorted(names)) + " match no model: "
        "expected " + "; ".join(f"{m}: {' '.join(Material(m).names)}" for m in MODELS)
    )


_MATERIAL_NAMES = frozenset(
    n for m in MODELS for pml in (False, True) for n in Material(m, pml).names
)
