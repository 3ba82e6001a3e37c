"""Engineering constants from the identified bending stiffnesses and the declared thickness.

Isotropic plate (``D = E h³ / 12 (1 - ν²)``): ``E = 12 D (1 - ν²) / h³``, ``ν``,
``G = E / 2 (1 + ν) = 6 D (1 - ν) / h³``. Orthotropic plate (``D11 = E1 h³ / 12 (1 - ν12
ν21)``, ``D22 = E2 h³ / 12 (1 - ν12 ν21)``, ``D12 = ν12 D22 = ν21 D11``, ``D66 = G12 h³ /
12``): ``ν12 = D12 / D22``, ``E1 = 12 (D11 - D12² / D22) / h³``, ``E2 = 12 (D22 - D12² /
D11) / h³``, ``G12 = 12 D66 / h³``. Standard deviations by first-order propagation of the
parameters' covariance and of the thickness's standard uncertainty (moduli scale as h⁻³).
"""

from __future__ import annotations

import math

import numpy as np


def _constants(model: str, p: dict, h: float) -> dict:
    if model == "isotropic":
        D, nu = p["D"], p["nu"]
        return {"E_Pa": 12 * D * (1 - nu**2) / h**3, "nu": nu, "G_Pa": 6 * D * (1 - nu) / h**3}
    if model in ("orthotropic", "monoclinic"):
        D11, D12, D22, D66 = p["D11"], p["D12"], p["D22"], p["D66"]
        return {
            "E1_Pa": 12 * (D11 - D12**2 / D22) / h**3,
            "E2_Pa": 12 * (D22 - D12**2 / D11) / h**3,
            "G12_Pa": 12 * D66 / h**3,
            "nu12": D12 / D22,
        }
    return {}


def constants(model: str, parameters: dict, thickness_m: float) -> dict:
    """The engineering constants (Pa, dimensionless) of ``model``'s plate parameters (by
    name) and the thickness; empty for a model without closed forms."""
    return _constants(model, parameters, thickness_m)


def sensitivities(model: str, names, values, thickness_m: float):
    """``(keys, dc/dθ (k, p), dc/dh (k,))``: the constants' derivatives in the parameters
    and, directly (through the conversion alone), in the thickness; central differences.
    ``keys`` is empty for a model without closed forms."""
    values = np.asarray(values, float)
    names = list(names)

    def f(theta, h):
        return _constants(model, dict(zip(names, theta)), h)

    base = f(values, thickness_m)
    keys = list(base)
    J = np.zeros((len(keys), len(names)))
    for j in range(len(names) if keys else 0):
        step = 1e-6 * max(abs(values[j]), 1e-12)
        up, down = values.copy(), values.copy()
        up[j] += step
        down[j] -= step
        fu, fd = f(up, thickness_m), f(down, thickness_m)
        J[:, j] = [(fu[k] - fd[k]) / (2 * step) for k in keys]
    dh = np.array([0.0 if k.startswith("nu") else -3.0 * base[k] / thickness_m for k in keys])
    return keys, J, dh


def engineering_constants(
    model: str, names, values, covariance, thickness_m: float, thickness_std_m: float = 0.0
) -> dict:
    """``{name: {"value", "std"}}``: the constants with the parameters' covariance and the
    thickness's standard uncertainty propagated through the conversion alone (moduli as
    h⁻³). The report's figure is the budget's (:mod:`vibid.identify.assess.budget`), which also
    carries the thickness through the fit (a thicker plate is heavier, so the fitted D
    grows with h: E then scales as h⁻², not h⁻³)."""
    values = np.asarray(values, float)
    cov = np.asarray(covariance, float)
    keys, J, dh = sensitivities(model, names, values, thickness_m)
    if not keys:
        return {}
    base = _constants(model, dict(zip(list(names), values)), thickness_m)
    var = np.einsum("ij,jk,ik->i", J, np.where(np.isfinite(cov), cov, np.nan), J)
    out = {}
    for i, k in enumerate(keys):
        total = var[i] + (dh[i] * thickness_std_m) ** 2
        out[k] = {
            "value": float(base[k]),
            "std": float(math.sqrt(total)) if np.isfinite(total) and total >= 0 else None,
        }
    return out
