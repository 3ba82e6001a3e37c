"""``transverse_shear``: the Reissner–Mindlin correction of a thick plate, to first order.

A Kirchhoff plate is rigid in transverse shear; a real one of thickness ``h`` also shears,
which lowers its bending frequencies by about ``(h k)² D/(κ G h³)`` relative (``k`` the
wavenumber). To first order in ``(h/λ)²`` the shear deflection is
``w_s = -(D/(κ G h)) ∇²w`` (Endo & Kimura 2007, simplified Reissner–Mindlin theory), and its
kinetic energy enters the weak form exactly like the plate's rotary inertia::

    m_s(u, v) = ρh (D/(κ G h)) ∫ ∇u·∇v        (isotropic)
              = (ρ/κ) ∫ (D11/G13 u,x v,x + D22/G23 u,y v,y)   (orthotropic, G23 = G13)

so the term is two inertia matrices with coefficients that the material sets. For an
isotropic plate ``G = E/2(1+ν)`` gives ``D/(κ G h) = h²/(6κ(1−ν))`` and the term has no
parameter of its own (the report format's "Effect names"); an orthotropic plate adds
``G13_Pa``. ``κ = 5/6`` (Reissner). The same correction on a cantilever beam reproduces
Timoshenko's frequencies to 3e-7 (mode 1) and 5e-6 (mode 2) relative on the titanium strip
(h/L = 0.03), where the shear-rigid model is 4e-4 and 4e-3 off
(``benchmarks/transverse_shear.py``, ``tests/test_effect_transverse_shear.py``).

Null: the term absent (shear-rigid). A parameter-free term cannot be scored at a null
value of its own; the loop scores it along the straight line from the model without it to
the model with it (one degree of freedom).
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import G13  # G13_Pa (Pa): the catalogue declares it

#: Reissner's shear correction factor.
KAPPA = 5.0 / 6.0


@dataclass(frozen=True)
class TransverseShear(Term):
    """Shear deformation's first-order inertia correction (module docstring).

    ``orthotropic`` selects the material's form: False for an isotropic plate (no
    parameter), True for an orthotropic or monoclinic one (``G13_Pa``).
    """

    orthotropic: bool = False
    name = "transverse_shear"
    meaning = "shear deformation of a thick plate (Reissner–Mindlin)"
    inertia_matrices = ("shear_x", "shear_y")
    all_parameters = (G13,)

    @property
    def parameters(self):
        return (G13,) if self.orthotropic else ()

    def for_material(self, material) -> "TransverseShear":
        return TransverseShear(orthotropic=material.model != "isotropic")

    def inertia(self, p: dict, xp) -> dict:
        if self.orthotropic:  # matrices (ρ/κ) ∫ u,x v,x and u,y v,y
            return {"shear_x": p["D11"] / p["G13_Pa"], "shear_y": p["D22"] / p["G13_Pa"]}
        c = 1.0 / (1.0 - p["nu"])  # matrices ρh h²/(6κ) ∫ u,x v,x and u,y v,y
        return {"shear_x": c, "shear_y": c}

    def assemble(self, ctx) -> dict:
        from vibid.identify.model.forms import slope_x, slope_y

        g = ctx.geometry
        rho = g.density_kg_m3
        scale = rho / KAPPA if self.orthotropic else g.mass_per_area_kg_m2 * g.thickness_m**2 / (6 * KAPPA)
        return {"shear_x": scale * slope_x.assemble(ctx.basis).tocsr(),
                "shear_y": scale * slope_y.assemble(ctx.basis).tocsr()}


EFFECT = TransverseShear()
