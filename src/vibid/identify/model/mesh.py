"""Discretisations of the rectangular specimen ``[0, L] x [0, W]``.

A :class:`Discretisation` names the element and a uniform structured triangle mesh
(``nx`` by ``ny`` rectangles, each cut into two triangles). Uniform meshes keep every cell
well shaped and make the sensor's footprint independent of local refinement: the disc is
integrated exactly (:mod:`vibid.identify.model.disc`) whatever cells it cuts.

The accuracy presets (:data:`ACCURACY`: cell size, corner levels) and the discretisation a
specimen gets for one of them (:func:`discretisation`) are here too, with the finer and
coarser levels of the discretisation error's extrapolation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from skfem import MeshTri

from vibid.errors import VibidError

ELEMENTS = ("argyris", "morley", "argyris-global")

#: Accuracy presets: (cell size, m; corner refinement levels; cells per bending wavelength
#: at the top of the band; cells across the specimen's shorter side). The cell size is the
#: finest a specimen needs: the paper's strip (20 mm wide) gets it whatever the band. A
#: larger specimen, whose bending waves in the band span many such cells, gets cells sized
#: by the wavelength instead (see :func:`discretisation`).
ACCURACY = {
    "fast": (0.005, 4, 8.0, 4),
    "default": (0.0033334, 4, 12.0, 6),
    "fine": (0.0016667, 6, 24.0, 12),
}


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


def bending_wavelength_m(rigidity_n_m: float, mass_per_area_kg_m2: float, f_hz: float) -> float:
    """Free bending wavelength ``2 pi (D / (rho h))^(1/4) / sqrt(omega)`` of a thin plate, m."""
    omega = 2 * np.pi * max(f_hz, 1e-9)
    return float(2 * np.pi * (rigidity_n_m / mass_per_area_kg_m2) ** 0.25 / np.sqrt(omega))


def discretisation(
    geometry,
    accuracy: str = "default",
    *,
    f_max_hz: float | None = None,
    rigidity_n_m: float | None = None,
) -> Discretisation:
    """The Argyris discretisation of an accuracy preset for a specimen (``geometry``: a
    :class:`~vibid.identify.model.assembly.Geometry`).

    Without a band (``f_max_hz``, and the softest bending rigidity ``rigidity_n_m`` the
    model is built around), the preset's cell size. With one, the cell is the larger of the
    preset's cell and ``min(wavelength(f_max) / cells_per_wavelength, shorter side /
    cells_across)``: a 150 x 100 mm plate up to 600 Hz then needs 16 x 11 cells instead of
    45 x 30, at the same accuracy of its modes in the band (about 1e-6), while the 20 mm
    strip keeps the preset's cells in every band (its width decides).
    """
    if accuracy not in ACCURACY:
        raise VibidError(f"unknown accuracy {accuracy!r}, expected one of {', '.join(ACCURACY)}")
    size, levels, per_wavelength, across = ACCURACY[accuracy]
    if f_max_hz is not None and rigidity_n_m is not None and f_max_hz > 0 and rigidity_n_m > 0:
        lam = bending_wavelength_m(rigidity_n_m, geometry.mass_per_area_kg_m2, f_max_hz)
        short = min(geometry.length_m, geometry.width_m)
        size = max(size, min(lam / per_wavelength, short / across))
    nx = max(2, math.ceil(geometry.length_m / size - 1e-6))
    ny = max(2, math.ceil(geometry.width_m / size - 1e-6))
    return Discretisation("argyris", nx, ny, levels)


def finer_discretisation(d: Discretisation) -> Discretisation:
    """The next finer level used to estimate a discretisation's error."""
    return Discretisation(d.element, (3 * d.nx + 1) // 2, (3 * d.ny + 1) // 2, d.corner_levels + 1)


def coarser_discretisation(d: Discretisation) -> Discretisation:
    """The next coarser level of :func:`finer_discretisation`'s family (cells 3/2 as large,
    one corner level fewer), the third mesh of the error's extrapolation; its finer level
    is ``d`` itself where the counts allow (the strip's 30 x 6 cells: 20 x 4)."""
    return Discretisation(
        d.element,
        max(2, round(2 * d.nx / 3)),
        max(2, round(2 * d.ny / 3)),
        max(0, d.corner_levels - 1),
    )


def cell_ratio(d: Discretisation, of: Discretisation) -> float:
    """The size of ``d``'s cells over ``of``'s (the geometric mean over both directions)."""
    return math.sqrt(of.nx / d.nx * of.ny / d.ny)
