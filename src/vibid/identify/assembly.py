"""Assembled plate matrices for one geometry and discretisation, cached.

For the clamped-free plate under base excitation (relative motion ``u = 1 + u_rel``, see
:mod:`vibid.identify.fullmodel`) the model needs, on the free degrees of freedom:

* ``K[name]`` for each modulus name in :data:`vibid.identify.forms.MODULI` (N·m → N/m per
  unit modulus), so that ``K(θ) = Σ D̂_α K_α``;
* ``M`` the plate's inertia, ``ρh ∫ u v + ρh h²/12 ∫ ∇u·∇v`` (kg);
* ``M_sensor`` the sensor disc's inertia, ``m/(π r²) ∫_disc (u v + h²/12 ∇u·∇v)`` (kg);
* the rigid-translation load of each inertia term, ``(M_full · 1)[free]``;
* the probe ``c`` with ``u(x_s, y_s) = c · u`` at the sensor centre.

Everything is assembled once per (geometry, discretisation) and kept in an LRU cache.
Extra terms (an edge spring along the clamp, ...) are further entries of ``stiffness`` with
their own parameters; :func:`edge_rotation_matrix` assembles the one along ``x = 0``.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from skfem import Basis, ElementTriArgyris, ElementTriMorley, FacetBasis

from vibid.identify.disc import assemble_disc
from vibid.identify.elements import ElementTriArgyrisLocal
from vibid.identify.forms import BENDING_FORMS, MODULI, edge_rotation, rotary_inertia, translational_inertia
from vibid.identify.mesh import Discretisation, plate_mesh

log = logging.getLogger(__name__)

#: Degrees of freedom fixed by the clamp (displacement and slope zero along x = 0).
_CLAMPED_DOFS = ("u", "u_x", "u_y", "u_xy", "u_yy", "u_n")
#: Of those, the ones that only the slope condition fixes (released by an edge spring).
_SLOPE_DOFS = ("u_x", "u_xy", "u_n")


@dataclass(frozen=True)
class Geometry:
    """What the matrices depend on: the specimen and the sensor disc (SI units)."""

    length_m: float
    width_m: float
    thickness_m: float
    density_kg_m3: float
    sensor_x_m: float
    sensor_y_m: float
    sensor_mass_kg: float
    sensor_radius_m: float

    @classmethod
    def from_setup(cls, setup) -> "Geometry":
        sp_, r = setup.specimen, setup.sensors.response
        return cls(sp_.length_m, sp_.width_m, sp_.thickness_m, sp_.density_kg_m3,
                   r.x_m, r.y_m, r.mass_kg, r.radius_m)

    @property
    def mass_per_area_kg_m2(self) -> float:
        return self.density_kg_m3 * self.thickness_m


@dataclass(frozen=True, eq=False)
class PlateMatrices:
    """Matrices on the free degrees of freedom (see the module docstring).

    Attributes
    ----------
    stiffness : dict name -> (n, n) CSR, one per modulus (and per extra stiffness term).
    inertia : dict name -> (n, n) CSR: ``"plate"`` and ``"sensor"``.
    load : dict name -> (n,) the rigid unit translation's inertia load of each inertia term.
    probe : (n,) displacement at the sensor centre; ``probe_rigid`` its value on the rigid
        unit translation (1 up to round-off).
    n_dof : number of free degrees of freedom; ``n_dof_total`` all of them.
    sensor_area_m2 : the integrated area of the sensor disc.
    rigid_mass_kg : dict name -> ``1ᵀ M 1`` of each inertia term on all dofs (the mass the
        rigid translation carries: ``ρ h L W`` for the plate, ``m`` for the sensor).
    """

    geometry: Geometry
    discretisation: Discretisation
    stiffness: dict
    inertia: dict
    load: dict
    probe: np.ndarray
    probe_rigid: float
    n_dof: int
    n_dof_total: int
    sensor_area_m2: float
    rigid_mass_kg: dict
    free: np.ndarray = field(repr=False)

    def stiffness_matrix(self, moduli: dict) -> sp.csr_matrix:
        """``Σ D_α K_α`` for a dict of (possibly complex) moduli."""
        out = None
        for name, value in moduli.items():
            term = value * self.stiffness[name]
            out = term if out is None else out + term
        return out.tocsr()

    def inertia_matrix(self) -> sp.csr_matrix:
        return (self.inertia["plate"] + self.inertia["sensor"]).tocsr()

    def inertia_load(self) -> np.ndarray:
        return self.load["plate"] + self.load["sensor"]


def make_element(kind: str):
    """A fresh element instance (scikit-fem caches each global element's basis on it)."""
    if kind == "argyris":
        return ElementTriArgyrisLocal()
    if kind == "argyris-global":
        return ElementTriArgyris()
    if kind == "morley":
        return ElementTriMorley()
    raise ValueError(f"unknown element {kind!r}")


def _intorder(kind: str) -> int:
    return 4 if kind == "morley" else 10


def _clamped_dofs(basis, names) -> np.ndarray:
    dofs = basis.get_dofs(lambda x: np.isclose(x[0], 0.0))
    present = [n for n in names if n in basis.elem.dofnames]
    return np.unique(dofs.all(present))


def _rigid_translation(basis) -> np.ndarray:
    one = np.zeros(basis.N)
    one[basis.nodal_dofs[0]] = 1.0  # the first nodal dof is 'u' in Morley and Argyris
    return one


@functools.lru_cache(maxsize=8)
def assemble_plate(geometry: Geometry, discretisation: Discretisation) -> PlateMatrices:
    """Assemble (once per geometry and discretisation) every matrix the model uses."""
    g, d = geometry, discretisation
    mesh = plate_mesh(g.length_m, g.width_m, d)
    basis = Basis(mesh, make_element(d.element), intorder=_intorder(d.element))
    h = g.thickness_m
    rho_h = g.mass_per_area_kg_m2

    full_k = {name: BENDING_FORMS[name].assemble(basis) for name in MODULI}
    m_uv = translational_inertia.assemble(basis)
    m_grad = rotary_inertia.assemble(basis)
    plate = rho_h * (m_uv + h**2 / 12.0 * m_grad)
    centre = np.array([g.sensor_x_m, g.sensor_y_m])
    disc_uv, disc_grad, area = assemble_disc(basis, centre, g.sensor_radius_m)
    density = g.sensor_mass_kg / (math.pi * g.sensor_radius_m**2)
    sensor = density * (disc_uv + h**2 / 12.0 * disc_grad)

    one = _rigid_translation(basis)
    probe_full = np.asarray(basis.probes(centre[:, None]).todense()).ravel()
    clamped = _clamped_dofs(basis, _CLAMPED_DOFS)
    free = np.setdiff1d(np.arange(basis.N), clamped)

    def restrict(a):
        return a[free][:, free].tocsr()

    mats = PlateMatrices(
        geometry=g,
        discretisation=d,
        stiffness={name: restrict(k) for name, k in full_k.items()},
        inertia={"plate": restrict(plate), "sensor": restrict(sensor)},
        load={"plate": (plate @ one)[free], "sensor": (sensor @ one)[free]},
        probe=probe_full[free],
        probe_rigid=float(probe_full @ one),
        n_dof=free.size,
        n_dof_total=basis.N,
        sensor_area_m2=area,
        rigid_mass_kg={"plate": float(one @ (plate @ one)), "sensor": float(one @ (sensor @ one))},
        free=free,
    )
    log.info("assembled %s %dx%d: %d free dof, sensor area error %.1e", d.element, d.nx, d.ny,
             free.size, area / (math.pi * g.sensor_radius_m**2) - 1)
    return mats


@functools.lru_cache(maxsize=4)
def plate_basis(geometry: Geometry, discretisation: Discretisation):
    """The scikit-fem basis of a discretisation (for post-processing and extra terms)."""
    mesh = plate_mesh(geometry.length_m, geometry.width_m, discretisation)
    return Basis(mesh, make_element(discretisation.element), intorder=_intorder(discretisation.element))


def edge_rotation_matrix(geometry: Geometry, discretisation: Discretisation) -> sp.csr_matrix:
    """``∫_{x=0} ∂u/∂x ∂v/∂x dy`` on all degrees of freedom (a rotational spring along the
    clamp, N·m/rad per metre of edge per unit stiffness). With it, the slope dofs of the
    edge (``u_x, u_xy, u_n``) are unknowns instead of zeros."""
    basis = plate_basis(geometry, discretisation)
    facets = basis.mesh.facets_satisfying(lambda x: np.isclose(x[0], 0.0), boundaries_only=True)
    fb = FacetBasis(basis.mesh, basis.elem, facets=facets, intorder=_intorder(discretisation.element))
    return edge_rotation.assemble(fb).tocsr()
