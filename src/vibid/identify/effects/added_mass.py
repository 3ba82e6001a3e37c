"""``added_mass``: an undeclared point mass at the response sensor (glue, cable, a stud).

The declared sensor's mass is spread over its disc (:mod:`vibid.identify.model.disc`);
what the setup does not declare sits at the disc's centre as a point mass ``m``: the
inertia gains ``m c cᵀ`` (``c`` the probe at the sensor centre) and, as it moves with the
base, its rigid-translation load ``m c (cᵀ 1)``. Null value ``m = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import scipy.sparse as sp

from vibid.identify.model.terms import Term
from vibid.parameters import MASS  # mass_kg (kg): the catalogue declares it


@dataclass(frozen=True)
class AddedMass(Term):
    """A point mass ``mass_kg`` at the response sensor's centre."""

    name = "added_mass"
    meaning = "an undeclared mass at the response sensor (glue, cable)"
    parameters = (MASS,)
    inertia_matrices = ("point_mass",)

    def inertia(self, p: dict, xp) -> dict:
        return {"point_mass": p["mass_kg"]}

    def assemble(self, ctx) -> dict:
        c = sp.csr_matrix(ctx.probe)
        return {"point_mass": (c.T @ c).tocsr()}


EFFECT = AddedMass()
