"""``clamp_compliance``: an elastic clamp, a rotational spring along the clamped edge.

A real clamp lets the plate's root turn a little under the bending moment. Along ``x = 0``
the displacement still follows the table (the base motion), but the slope is no longer
zero: a rotational spring of stiffness ``k_θ`` per metre of edge (N·m/rad per m, i.e.
N/rad) resists it, with the energy ``½ k_θ ∫_{x=0} (∂w/∂x)² dy``. In the FE model the
slope degrees of freedom of the edge (``u_x, u_xy, u_n`` of the Argyris element) become
unknowns and the edge form :func:`~vibid.identify.model.forms.edge_rotation`, assembled
once with a scikit-fem ``FacetBasis``, scales with ``k_θ``. The spring dissipates like the
plate (the material's loss factor), so the modes stay real.

The null value is the rigid clamp, ``k_θ → ∞`` (the model without this term). Where a
finite null is needed (a score test at the null), work in the compliance ``1 / k_θ``
(null 0); reports give ``k_θ``.
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import K_THETA  # k_theta_N_per_rad: the catalogue declares it

#: The clamp's degrees of freedom that only the slope condition fixes.
SLOPE_DOFS = ("u_x", "u_xy", "u_n")


@dataclass(frozen=True)
class ClampCompliance(Term):
    """A rotational spring ``k_θ`` (N/rad) per metre along the clamped edge ``x = 0``."""

    name = "clamp_compliance"
    meaning = "an elastic clamp (a rotational spring along the clamped edge)"
    parameters = (K_THETA,)
    stiffness_matrices = ("clamp_edge",)
    released = SLOPE_DOFS

    def stiffness(self, p: dict, xp) -> dict:
        return {"clamp_edge": (p["k_theta_N_per_rad"], None)}

    def assemble(self, ctx) -> dict:
        return {"clamp_edge": ctx.edge_rotation_matrix()}


EFFECT = ClampCompliance()
