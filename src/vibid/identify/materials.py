"""Material parameterisations: physical parameters → six moduli and their loss factors.

The moment law (session format) is ``M = D κ`` with ``κ = (w,xx, w,yy, 2 w,xy)`` and the
symmetric 3 x 3 matrix ``D`` of the moduli ``D11, D12, D16, D22, D26, D66`` (N·m). Damping
enters as complex moduli ``D̂_α = D_α (1 + i β_α)`` (paper eq. 3.1.1).

Parameterisations (names as in :data:`vibid.setup_model.MODEL_PARAMETERS`):

* ``isotropic``: ``D, nu`` with ``D11 = D22 = D``, ``D12 = nu D``, ``D66 = (1 - nu) D / 2``;
* ``orthotropic``: ``D11, D12, D22, D66`` (``D16 = D26 = 0``);
* ``monoclinic``: the orthotropic set plus ``D16, D26``;

followed by the loss: one ``beta`` for all moduli, or with ``per_modulus_loss`` one
``beta<ij>`` per independent modulus (isotropic: ``beta11`` for D11 and D22, ``beta12``,
``beta66``; orthotropic: ``beta11, beta12, beta22, beta66``; monoclinic adds ``beta16,
beta26``).

Each parameterisation is a pure function ``theta -> (moduli (6,), losses (6,))`` that works
on numpy and JAX arrays alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibid.identify.forms import MODULI
from vibid.setup_model import MODEL_PARAMETERS

MODELS = tuple(MODEL_PARAMETERS)

_STIFFNESS_NAMES = {m: tuple(n for n in MODEL_PARAMETERS[m] if n != "beta") for m in MODELS}
_LOSS_NAMES = {
    "isotropic": ("beta11", "beta12", "beta66"),
    "orthotropic": ("beta11", "beta12", "beta22", "beta66"),
    "monoclinic": ("beta11", "beta12", "beta22", "beta66", "beta16", "beta26"),
}


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
class Parameterisation:
    """Physical parameters of one material model and how they map to moduli and losses.

    Attributes
    ----------
    model : ``"isotropic"``, ``"orthotropic"`` or ``"monoclinic"``.
    per_modulus_loss : one loss factor per modulus instead of a single ``beta``.
    """

    model: str
    per_modulus_loss: bool = False

    def __post_init__(self):
        if self.model not in MODELS:
            raise ValueError(f"unknown model {self.model!r}, expected one of {', '.join(MODELS)}")

    @property
    def stiffness_names(self) -> tuple[str, ...]:
        return _STIFFNESS_NAMES[self.model]

    @property
    def loss_names(self) -> tuple[str, ...]:
        return _LOSS_NAMES[self.model] if self.per_modulus_loss else ("beta",)

    @property
    def names(self) -> tuple[str, ...]:
        return self.stiffness_names + self.loss_names

    @property
    def proportional(self) -> bool:
        """True when every modulus shares one loss factor (real modes exist)."""
        return not self.per_modulus_loss

    def moduli(self, theta, xp=np):
        """The six storage moduli ``(D11, D12, D16, D22, D26, D66)`` as an array (N·m)."""
        p = dict(zip(self.names, (theta[i] for i in range(len(self.names)))))
        zero = 0.0 * theta[0]
        if self.model == "isotropic":
            vals = isotropic_moduli(p["D"], p["nu"])
        else:
            vals = (p["D11"], p["D12"], p.get("D16", zero), p["D22"], p.get("D26", zero), p["D66"])
        return xp.stack([xp.asarray(v) + zero for v in vals])

    def losses(self, theta, xp=np):
        """The six loss factors, in the order of :data:`MODULI`."""
        p = dict(zip(self.names, (theta[i] for i in range(len(self.names)))))
        zero = 0.0 * theta[0]
        if not self.per_modulus_loss:
            vals = (p["beta"],) * 6
        elif self.model == "isotropic":
            vals = (p["beta11"], p["beta12"], zero, p["beta11"], zero, p["beta66"])
        else:
            vals = (p["beta11"], p["beta12"], p.get("beta16", zero), p["beta22"],
                    p.get("beta26", zero), p["beta66"])
        return xp.stack([xp.asarray(v) + zero for v in vals])

    def complex_moduli(self, theta, xp=np):
        """``D_α (1 + i β_α)``, the six complex moduli."""
        return self.moduli(theta, xp) * (1.0 + 1j * self.losses(theta, xp))

    def default_bounds(self, bounds: dict) -> dict:
        """Bounds for every name, taking loss bounds from ``beta`` when per-modulus."""
        out = {}
        for n in self.names:
            if n in bounds:
                out[n] = tuple(bounds[n])
            elif n.startswith("beta") and "beta" in bounds:
                out[n] = tuple(bounds["beta"])
            elif n in ("D16", "D26"):
                out[n] = (0.0, 0.0)
        return out


def theta_from_dict(param: Parameterisation, values: dict) -> np.ndarray:
    """The parameter vector in ``param.names`` order; a clear error for a missing name."""
    missing = [n for n in param.names if n not in values]
    if missing:
        raise KeyError(f"model {param.model!r} needs {', '.join(missing)}")
    return np.array([float(values[n]) for n in param.names])


def infer_model(names) -> tuple[str, bool]:
    """The (model, per_modulus_loss) whose parameter names are exactly ``names``."""
    names = set(names)
    for model in MODELS:
        for pml in (False, True):
            if set(Parameterisation(model, pml).names) == names:
                return model, pml
    raise KeyError("parameters " + ", ".join(sorted(names)) + " match no model: expected "
                   + "; ".join(f"{m}: {' '.join(Parameterisation(m).names)}" for m in MODELS))


__all__ = ["MODULI", "MODELS", "Parameterisation", "flexural_rigidity", "isotropic_moduli",
           "theta_from_dict", "infer_model"]
