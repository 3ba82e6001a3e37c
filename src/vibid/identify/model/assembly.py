"""Assembled plate matrices for one geometry, discretisation and set of model terms.

For the clamped plate under base excitation (relative motion ``u = 1 + u_rel``, see
:mod:`vibid.identify.model.full`) the model needs, on the free degrees of freedom:

* one stiffness matrix per name of :attr:`PlateModel.stiffness_names
  <vibid.identify.model.terms.PlateModel.stiffness_names>`: the six bending matrices
  ``K_α`` (N·m → N/m per unit modulus), then the effects' own (an edge spring, ...), so
  that ``K(θ) = Σ s_k (1 + i β_k) K_k``;
* one inertia matrix per name of ``inertia_names``: ``"plate"``, ``ρh ∫ u v + ρh h²/12 ∫
  ∇u·∇v`` (kg), ``"sensor"``, the sensor disc's ``m/(π r²) ∫_disc (u v + h²/12 ∇u·∇v)``,
  then the effects' own;
* the rigid-translation load of each inertia matrix, ``(M_full · 1)[free]``, and the
  load of the rigid rotation about the clamp line, ``(M_full · x)[free]`` (``w = x``, for
  a base that rocks: :mod:`vibid.identify.effects.stand_resonance`);
* the probe ``c`` with ``u(x_s, y_s) = c · u`` at the sensor centre, and the effects' own
  probe vectors (a sensor displaced from its declared place).

A term may bring a field of its own beside the plate's deflection (the shear deflection of
:mod:`vibid.identify.effects.transverse_shear`): its matrices are then larger, the plate's
degrees of freedom first and the field's after them, all of the field's free; every other
matrix, load and probe is padded with zeros (the field takes no part in them).

The plate's own matrices are assembled once per (geometry, discretisation) on all degrees
of freedom (:func:`assemble_all`); a model's terms then choose the free degrees of freedom
(the clamp fixes displacement and slope along ``x = 0``; a term may release some) and add
their matrices (:func:`model_matrices`). Both are kept in small LRU caches.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from vibid.errors import VibidError
from vibid.identify.model.disc import assemble_disc, shifted_disc
from vibid.identify.model.elements import ElementTriArgyrisLocal
from vibid.identify.model.forms import (
    BENDING_FORMS,
    MODULI,
    edge_rotation,
    rotary_inertia,
    translational_inertia,
)
from vibid.identify.model.machinery import numpy_only, timed
from vibid.identify.model.mesh import Discretisation, plate_mesh
from vibid.identify.model.terms import clash

log = logging.getLogger(__name__)

#: Degrees of freedom fixed by the clamp (displacement and slope zero along x = 0).
CLAMPED_DOFS = ("u", "u_x", "u_y", "u_xy", "u_yy", "u_n")


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
    def from_setup(cls, setup) -> Geometry:
        sp_, r = setup.specimen, setup.sensors.response
        return cls(
            sp_.length_m,
            sp_.width_m,
            sp_.thickness_m,
            sp_.density_kg_m3,
            r.x_m,
            r.y_m,
            r.mass_kg,
            r.radius_m,
        )

    @property
    def mass_per_area_kg_m2(self) -> float:
        return self.density_kg_m3 * self.thickness_m


@dataclass(frozen=True, eq=False)
class AssemblyContext:
    """What a term needs to assemble its own matrices (on all degrees of freedom)."""

    geometry: Geometry
    discretisation: Discretisation
    basis: object  # skfem CellBasis
    probe: np.ndarray  # (N,) displacement at the sensor centre

    def sensor_shift(self, direction, places, shifts=None) -> dict:
        """``{k: M_k}`` (kg/m^k, k = 1..2n): the declared sensor's inertia matrix when its
        disc moves by ``s`` along the unit vector ``direction`` is ``M_sensor + Σ s^k M_k``,
        interpolated through ``s = 0`` and the n ``places`` (m; the disc must lie on the
        plate there; :func:`~vibid.identify.model.disc.shifted_disc`). With ``shifts`` the
        disc lies ``shifts[i]`` (m) away at ``places[i]``, which are then the values of
        any parameter that moves it (the polynomial is in that parameter)."""
        g = self.geometry
        centre = np.array([g.sensor_x_m, g.sensor_y_m])
        parts = shifted_disc(self.basis, centre, g.sensor_radius_m, direction, places, shifts)
        return {k: _disc_inertia(g, uv, grad) for k, (uv, grad) in parts.items()}

    def sensor_tilt(self) -> sp.csr_matrix:
        """``m/(π r²) ∫_disc ∇u·∇v`` (kg): the declared sensor's mass spread over its disc,
        times the squared tilt of the plate under it (a rotary inertia per m² of lever)."""
        g = self.geometry
        centre = np.array([g.sensor_x_m, g.sensor_y_m])
        _, grad, _ = assemble_disc(self.basis, centre, g.sensor_radius_m)
        return (g.sensor_mass_kg / (math.pi * g.sensor_radius_m**2) * grad).tocsr()

    def translational_inertia(self) -> sp.csr_matrix:
        """``ρh ∫ u v + m/(π r²) ∫_disc u v`` (kg): the plate's and the declared sensor's
        mass, without their rotary inertia."""
        g = self.geometry
        uv, _, _ = assemble_disc(
            self.basis, np.array([g.sensor_x_m, g.sensor_y_m]), g.sensor_radius_m
        )
        plate = g.mass_per_area_kg_m2 * translational_inertia.assemble(self.basis)
        return (plate + g.sensor_mass_kg / (math.pi * g.sensor_radius_m**2) * uv).tocsr()

    def clamped(self, names) -> np.ndarray:
        """The degrees of freedom named ``names`` (e.g. ``"u"``) on the clamped edge."""
        return _clamped_dofs(self.basis, names)

    def probe_at(self, centre_m) -> np.ndarray:
        """(N,) the probe ``c`` with ``u(x, y) = c · u`` at ``centre_m`` = (x, y)."""
        return _probe(self.basis, np.asarray(centre_m, float))

    def edge_rotation_matrix(self) -> sp.csr_matrix:
        """``∫_{x=0} ∂u/∂x ∂v/∂x dy`` (a rotational spring along the clamp, N·m/rad per
        metre of edge per unit stiffness)."""
        from skfem import FacetBasis

        mesh = self.basis.mesh
        facets = mesh.facets_satisfying(lambda x: np.isclose(x[0], 0.0), boundaries_only=True)
        fb = FacetBasis(
            mesh, self.basis.elem, facets=facets, intorder=_intorder(self.discretisation.element)
        )
        return edge_rotation.assemble(fb).tocsr()


@dataclass(frozen=True, eq=False)
class PlateMatrices:
    """Matrices on the free degrees of freedom (see the module docstring).

    Attributes
    ----------
    stiffness : dict name -> (n, n) CSR, one per stiffness term.
    inertia : dict name -> (n, n) CSR, one per inertia term.
    load : dict name -> (n,) the rigid unit translation's inertia load of each inertia term.
    load_rotation : dict name -> (n,) the same for the rigid unit rotation ``w = x`` about
        the clamp line (kg·m per rad).
    probes : dict name -> (n,), one per probe name of the model, ``"sensor"`` the
        displacement at the declared sensor's centre; ``probes_rigid`` each one's value on
        the rigid unit translation (1 up to round-off for the sensor's); ``probes_rotation``
        each one's value on the rigid unit rotation (the sensor's x, m per rad).
    probe, probe_rigid : the declared sensor's (properties).
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
    load_rotation: dict
    probes: dict
    probes_rigid: dict
    probes_rotation: dict
    n_dof: int
    n_dof_total: int
    sensor_area_m2: float
    rigid_mass_kg: dict
    free: np.ndarray = field(repr=False)

    def stiffness_matrix(self, coefficients: dict) -> sp.csc_matrix:
        """``Σ c_k K_k`` for a dict of (possibly complex) coefficients by name (CSC, on the
        pattern all the matrices share: :attr:`pattern`)."""
        p = self.pattern
        return p.matrix(p.data("K", coefficients))

    def inertia_matrix(self, coefficients: dict | None = None) -> sp.csc_matrix:
        """``Σ m_k M_k`` (default: every inertia matrix with coefficient 1), as
        :meth:`stiffness_matrix`."""
        p = self.pattern
        return p.matrix(p.data("M", coefficients or {k: 1.0 for k in self.inertia}))

    @functools.cached_property
    def pattern(self) -> SharedPattern:
        """Every stiffness and inertia matrix on one sparsity pattern (made on first use)."""
        return SharedPattern.of(
            {
                **{("K", k): v for k, v in self.stiffness.items()},
                **{("M", k): v for k, v in self.inertia.items()},
            }
        )

    def inertia_load(
        self, coefficients: dict | None = None, *, rotation: bool = False
    ) -> np.ndarray:
        """``Σ m_k (M_k r)[free]``, ``r`` the rigid translation (or with ``rotation`` the
        rigid rotation about the clamp line)."""
        c = coefficients or {k: 1.0 for k in self.inertia}
        load = self.load_rotation if rotation else self.load
        return sum(v * load[k] for k, v in c.items())

    @property
    def probe(self) -> np.ndarray:
        return self.probes["sensor"]

    @property
    def probe_rigid(self) -> float:
        return self.probes_rigid["sensor"]

    def probe_vector(self, coefficients: dict | None = None) -> tuple[np.ndarray, float]:
        """``(Σ c_k probe_k, Σ c_k probe_k · 1)`` (default: the declared sensor's probe)."""
        c = coefficients or {"sensor": 1.0}
        vec = sum(v * self.probes[k] for k, v in c.items())
        return vec, float(sum(v * self.probes_rigid[k] for k, v in c.items()))

    def probe_rotation(self, coefficients: dict | None = None) -> float:
        """``Σ c_k probe_k · x``: the probe's value on the rigid unit rotation (m/rad)."""
        c = coefficients or {"sensor": 1.0}
        return float(sum(v * self.probes_rotation[k] for k, v in c.items()))


@dataclass(frozen=True, eq=False)
class SharedPattern:
    """Sparse matrices of one size stored on the union of their patterns (CSC, sorted):
    a weighted sum of them is a sum of their value arrays, where summing scipy matrices
    merges patterns term by term (on a strip mesh of 2861 unknowns 3.6 ms per
    ``Σ c_k K_k`` of seven matrices, thousands per loop). The sums are taken in the same
    order and the entries that come out zero dropped, as scipy's would be: the same
    matrix to the last bit, so the sparse LU orders it the same way (a model with an
    effect at its null then gives the plain model's AFC to rounding, not to the 1e-11 a
    differently ordered elimination leaves)."""

    indices: np.ndarray
    indptr: np.ndarray
    shape: tuple
    #: ("K" or "M", name) -> row of :attr:`values`
    rows: dict
    #: (matrices, nnz) each matrix's values on the pattern, zero where it has none
    values: np.ndarray

    @staticmethod
    def of(matrices: dict) -> SharedPattern:
        mats = {k: sp.csc_matrix(v) for k, v in matrices.items()}
        for m in mats.values():
            m.sum_duplicates()  # canonical: sorted indices, no duplicates
        union = functools.reduce(lambda a, b: a + b, (abs(m) for m in mats.values())).tocsc()
        union.sum_duplicates()
        n_rows = union.shape[0]
        cols = np.repeat(np.arange(union.shape[1]), np.diff(union.indptr))
        keys = cols.astype(np.int64) * n_rows + union.indices
        values = np.zeros((len(mats), union.nnz))
        for j, m in enumerate(mats.values()):
            mc = np.repeat(np.arange(m.shape[1]), np.diff(m.indptr))
            values[j, np.searchsorted(keys, mc.astype(np.int64) * n_rows + m.indices)] = m.data
        return SharedPattern(
            union.indices.copy(),
            union.indptr.copy(),
            union.shape,
            {k: j for j, k in enumerate(mats)},
            values,
        )

    def data(self, kind: str, coefficients: dict) -> np.ndarray:
        """``Σ c_k V_k`` over the matrices of ``kind`` ("K" or "M") named in
        ``coefficients``, in its order, on the pattern."""
        out = None
        for k, v in coefficients.items():
            term = v * self.values[self.rows[kind, k]]
            out = term if out is None else out + term
        return np.zeros(self.values.shape[1]) if out is None else out

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        """The CSC matrix of values ``data`` on the pattern, its zero entries dropped."""
        A = sp.csc_matrix((data, self.indices.copy(), self.indptr.copy()), shape=self.shape)
        A.eliminate_zeros()
        return A


def make_element(kind: str):
    """A fresh element instance (scikit-fem caches each global element's basis on it)."""
    from skfem import ElementTriArgyris, ElementTriMorley

    if kind == "argyris":
        return ElementTriArgyrisLocal()
    if kind == "argyris-global":
        return ElementTriArgyris()
    if kind == "morley":
        return ElementTriMorley()
    raise ValueError(f"unknown element {kind!r}")


def _intorder(kind: str) -> int:
    return 4 if kind == "morley" else 10


@dataclass(frozen=True, eq=False)
class _AllDofs:
    """The plate's own matrices on every degree of freedom, and what restricting needs."""

    context: AssemblyContext
    stiffness: dict
    inertia: dict
    one: np.ndarray
    x: np.ndarray  # the rigid rotation about the clamp line, w = x (m per rad)
    sensor_area_m2: float


#: a loop's refits visit a dozen effect structures, each on its mesh and on the model
#: error's finer one: caches that hold them all keep each assembled once per run
@functools.lru_cache(maxsize=16)
@numpy_only
@timed("matrices")
def assemble_all(geometry: Geometry, discretisation: Discretisation) -> _AllDofs:
    """Assemble the plate's bending and inertia matrices on all degrees of freedom."""
    from skfem import Basis

    g, d = geometry, discretisation
    mesh = plate_mesh(g.length_m, g.width_m, d)
    basis = Basis(mesh, make_element(d.element), intorder=_intorder(d.element))
    h = g.thickness_m
    stiffness = {name: BENDING_FORMS[name].assemble(basis) for name in MODULI}
    plate = g.mass_per_area_kg_m2 * (
        translational_inertia.assemble(basis) + h**2 / 12.0 * rotary_inertia.assemble(basis)
    )
    centre = np.array([g.sensor_x_m, g.sensor_y_m])
    sensor, area = _sensor_inertia(basis, g, centre)
    one = np.zeros(basis.N)
    one[basis.nodal_dofs[0]] = 1.0  # the rigid unit translation: 'u' is the first nodal dof
    x = basis.project(lambda p: p[0])  # exact: the element holds every linear field
    ctx = AssemblyContext(g, d, basis, _probe(basis, centre))
    return _AllDofs(ctx, stiffness, {"plate": plate, "sensor": sensor}, one, x, area)


def _sensor_inertia(basis, g: Geometry, centre: np.ndarray):
    """The sensor disc's inertia matrix (kg, :func:`_disc_inertia`) and its area (m²)."""
    disc_uv, disc_grad, area = assemble_disc(basis, centre, g.sensor_radius_m)
    return _disc_inertia(g, disc_uv, disc_grad), area


def _disc_inertia(g: Geometry, uv, grad) -> sp.csr_matrix:
    """``m/(π r²) (uv + h²/12 grad)``: the sensor's mass spread over its disc, from the
    disc integrals ``∫ u v`` and ``∫ ∇u·∇v``."""
    scale = g.sensor_mass_kg / (math.pi * g.sensor_radius_m**2)
    return (scale * (uv + g.thickness_m**2 / 12.0 * grad)).tocsr()


def _probe(basis, centre: np.ndarray) -> np.ndarray:
    return np.asarray(basis.probes(centre[:, None]).todense()).ravel()


def plate_basis(geometry: Geometry, discretisation: Discretisation):
    """The scikit-fem basis of a discretisation (for post-processing and extra terms)."""
    return assemble_all(geometry, discretisation).context.basis


def _clamped_dofs(basis, names) -> np.ndarray:
    dofs = basis.get_dofs(lambda x: np.isclose(x[0], 0.0))
    present = [n for n in names if n in basis.elem.dofnames]
    return np.unique(dofs.all(present)) if present else np.zeros(0, int)


def model_matrices(
    geometry: Geometry, discretisation: Discretisation, effects: tuple = ()
) -> PlateMatrices:
    """The matrices of a plate with the given effect terms, on its free degrees of freedom
    (see the module docstring); ``effects`` is ``PlateModel.effects``. Terms that bring no
    matrix, probe or released degree of freedom (a delay, a gain, a loss law) share the
    matrices of the model without them."""
    pair = clash(effects)
    if pair:
        raise VibidError(
            f"the effects {pair[0]} and {pair[1]} cannot share a model "
            f"(vibid.identify.effects.{pair[0]} says why)"
        )
    own = tuple(
        t
        for t in effects
        if t.stiffness_matrices or t.inertia_matrices or t.probe_vectors or t.released
    )
    return _model_matrices(geometry, discretisation, own)


@functools.lru_cache(maxsize=32)
def _term_matrices(term, geometry: Geometry, discretisation: Discretisation) -> dict:
    """A term's own matrices and probes on all degrees of freedom, assembled once per mesh:
    the structures of a loop's later rounds hold the same term beside other ones (on a
    real strip's loop the sensor's shifted disc, 2.3 s a mesh, was assembled four times)."""
    return term.assemble(assemble_all(geometry, discretisation).context)


@functools.lru_cache(maxsize=32)
@numpy_only
@timed("matrices")
def _model_matrices(
    geometry: Geometry, discretisation: Discretisation, effects: tuple
) -> PlateMatrices:
    full = assemble_all(geometry, discretisation)
    basis = full.context.basis
    released = {dof for t in effects for dof in t.released}
    clamped = _clamped_dofs(basis, [n for n in CLAMPED_DOFS if n not in released])
    free = np.setdiff1d(np.arange(basis.N), clamped)
    stiffness, inertia = dict(full.stiffness), dict(full.inertia)
    probes = {"sensor": full.context.probe}
    for t in effects:
        for name, matrix in _term_matrices(t, geometry, discretisation).items():
            if name in t.probe_vectors:
                probes[name] = np.asarray(matrix, float)
            else:
                (stiffness if name in t.stiffness_matrices else inertia)[name] = matrix
    # a term's own field (module docstring): every dof beyond the plate's is free
    size = max(a.shape[0] for a in (*stiffness.values(), *inertia.values(), *probes.values()))
    free = np.concatenate([free, np.arange(basis.N, size)])

    def pad(a):
        extra = size - a.shape[0]
        if not extra:
            return a
        if a.ndim == 1:
            return np.concatenate([a, np.zeros(extra)])
        return sp.block_diag([a, sp.csr_matrix((extra, extra))]).tocsr()

    stiffness = {k: pad(a) for k, a in stiffness.items()}
    inertia = {k: pad(a) for k, a in inertia.items()}
    probes = {k: pad(c) for k, c in probes.items()}

    def restrict(a):
        return a[free][:, free].tocsr()

    one, x = pad(full.one), pad(full.x)
    mats = PlateMatrices(
        geometry=geometry,
        discretisation=discretisation,
        stiffness={k: restrict(a) for k, a in stiffness.items()},
        inertia={k: restrict(a) for k, a in inertia.items()},
        load={k: (a @ one)[free] for k, a in inertia.items()},
        load_rotation={k: (a @ x)[free] for k, a in inertia.items()},
        probes={k: c[free] for k, c in probes.items()},
        probes_rigid={k: float(c @ one) for k, c in probes.items()},
        probes_rotation={k: float(c @ x) for k, c in probes.items()},
        n_dof=free.size,
        n_dof_total=size,
        sensor_area_m2=full.sensor_area_m2,
        rigid_mass_kg={k: float(one @ (a @ one)) for k, a in inertia.items()},
        free=free,
    )
    log.info(
        "assembled %s %dx%d%s: %d free dof",
        discretisation.element,
        discretisation.nx,
        discretisation.ny,
        "".join(f" +{t.name}" for t in effects),
        free.size,
    )
    return mats


def assemble_plate(geometry: Geometry, discretisation: Discretisation) -> PlateMatrices:
    """The clamped plate's matrices (no effect terms)."""
    return model_matrices(geometry, discretisation, ())


def edge_rotation_matrix(geometry: Geometry, discretisation: Discretisation) -> sp.csr_matrix:
    """The clamp spring's matrix on all degrees of freedom
    (:meth:`AssemblyContext.edge_rotation_matrix`)."""
    return assemble_all(geometry, discretisation).context.edge_rotation_matrix()
