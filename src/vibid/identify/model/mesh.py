"""Discretisations of the rectangular specimen ``[0, L] x [0, W]``.

A :class:`Discretisation` names the element and a uniform structured triangle mesh
(``nx`` by ``ny`` rectangles, each cut into two triangles). Uniform meshes keep every cell
well shaped and make the sensor's footprint independent of local refinement: the disc is
integrated exactly (:mod:`vibid.identify.model.disc`) whatever cells it cuts.

The accuracy presets (cell size, corner levels) live in :mod:`vibid.identify.model.forward`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from skfem import MeshTri

ELEMENTS = ("argyris", "morley", "argyris-global")


@dataclass(frozen=True)
class Discretisation:
    """Element kind and mesh counts.

    Attributes
    ----------
    element : ``"argyris"`` (quintic C1, local-coordinate basis; the default),
        ``"morley"`` (quadratic non-conforming) or ``"argyris-global"`` (scikit-fem's own
        Argyris basis in global coordinates; a reference, use on uniform meshes only).
    nx, ny : number of mesh rectangles along the length and across the width.
    """

    element: str
    nx: int
    ny: int
    corner_levels: int = 0

    @property
    def label(self) -> str:
        return f"{self.element} {self.nx}x{self.ny}" + (
            f" +{self.corner_levels} corner levels" if self.corner_levels else ""
        )

    def refined(self, factor: int = 2) -> Discretisation:
        return Discretisation(self.element, self.nx * factor, self.ny * factor, self.corner_levels)

    def coarsened(self, factor: int = 2) -> Discretisation:
        return Discretisation(
            self.element, max(1, self.nx // factor), max(1, self.ny // factor), self.corner_levels
        )


def plate_mesh(length_m: float, width_m: float, disc: Discretisation) -> MeshTri:
    """The triangle mesh of ``[0, length_m] x [0, width_m]``: uniform, then refined
    ``disc.corner_levels`` times around the two clamped corners (0, 0) and (0, W).

    The clamped-free corners carry the plate's corner singularity, which limits a uniform
    mesh to second-order convergence whatever the element; each level halves the cells
    within a radius (halved per level, starting at two cells) of each corner, conformingly.
    """
    mesh = MeshTri.init_tensor(
        np.linspace(0.0, length_m, disc.nx + 1), np.linspace(0.0, width_m, disc.ny + 1)
    )
    radius = 2.0 * max(length_m / disc.nx, width_m / disc.ny)
    for level in range(disc.corner_levels):
        c = mesh.p[:, mesh.t].mean(axis=1)
        dist = np.minimum(np.hypot(c[0], c[1]), np.hypot(c[0], c[1] - width_m))
        mesh = mesh.refined(np.nonzero(dist < radius / 2**level)[0])
    return mesh
