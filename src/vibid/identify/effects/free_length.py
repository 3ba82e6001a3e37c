"""``free_length``: the clamp's effective edge lies ``dL`` beyond the declared clamp line.

Jaws do not hold a plate rigidly up to their edge: the plate bends a little inside them,
and the span that vibrates is longer than the one measured from the jaws' edge (``dL > 0``,
report format; a plate clamped past a shim may show ``dL < 0``). The plate of length
``L + dL``, with the sensor ``dL`` further from the effective edge than declared, is the
declared mesh stretched along x by ``s = (L + dL) / L``: a point at ``ξ`` of the mesh is
at ``x = s ξ`` of the plate. The forms, written on the mesh, then scale by powers of ``s``
(``∂/∂x = s⁻¹ ∂/∂ξ``, ``dA = s dξ dy``):

* bending: ``D11 → s⁻³``, ``D12 → s⁻¹``, ``D22 → s``, ``D66 → s⁻¹``, ``D16 → s⁻²``,
  ``D26 → 1``; the clamp's spring (a slope squared along the edge) ``→ s⁻²``;
* inertia: the plate's translational and rotary inertia ``→ s``, less
  ``(s − 1/s) ρh h²/12 ∫ u,ξ v,ξ`` (the rotary inertia's part along x scales by ``1/s``);
* the sensor, fixed to the plate at ``x₀ + dL`` from the effective edge, sits at
  ``ξ = L (x₀ + dL) / (L + dL)`` of the mesh: its disc and the point it reads move along
  the mesh as polynomials in ``dL`` through ``dL = 0`` and three places of the default box
  (as :mod:`~vibid.identify.effects.sensor_position` moves them across the width).

So the term keeps the one mesh and stays affine in its coefficients, and exact derivatives
cost nothing more. The stretch needs the declared length: the library's term has none,
and a model is bound to its plate's (:meth:`PlateModel.for_geometry
<vibid.identify.model.terms.PlateModel.for_geometry>`) where its forward model is built.

Not stretched: the sensor's disc itself (its footprint's length along x changes by
``dL / L``, a part in a hundred of a rotary inertia that is itself small), an
``added_mass`` (it stays at the declared centre), and a stand resonance's rotation, whose
``H_rotation`` grows by ``s`` (its ``theta_rad_per_m`` takes that up). ``dL`` and the
bending stiffness are nearly collinear (a longer span is a softer plate): the fit's
uncertainty says how much of one the other carries. Null value ``dL = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibid.identify.model.disc import polynomial_through
from vibid.identify.model.terms import Term
from vibid.parameters import DL

#: Degree of the sensor's interpolation along the mesh.
DEGREE = 3
POWERS = tuple(range(1, 2 * DEGREE + 1))
#: Powers of the stretch ``s`` that scale each bending matrix (see the module docstring).
BENDING_POWERS = {"D11": -3, "D12": -1, "D16": -2, "D22": 1, "D26": 0, "D66": -1}


def places() -> tuple[float, ...]:
    """The :data:`DEGREE` values of ``dL`` (m, besides 0) where the sensor's interpolation
    is exact: evenly spread over the default box."""
    grid = np.linspace(DL.bounds[0], DL.bounds[1], DEGREE + 1)
    return tuple(float(t) for t in np.delete(grid, np.argmin(np.abs(grid))))


def sensor_shift_m(length_m: float, sensor_x_m: float, dL_m: float) -> float:
    """How far (m) along the mesh the sensor moves: ``L (x₀ + dL) / (L + dL) − x₀``."""
    return length_m * (sensor_x_m + dL_m) / (length_m + dL_m) - sensor_x_m


@dataclass(frozen=True)
class FreeLength(Term):
    """The plate's free span ``dL_m`` longer than declared (the mesh stretched along x);
    ``length_m`` the declared length (m) of the plate it is bound to."""

    length_m: float | None = None
    name = "free_length"
    meaning = "a free span longer than declared (the clamp's effective edge inside the jaws)"
    parameters = (DL,)
    in_every_structure = False  # bound to its plate's length
    inertia_matrices = ("plate_slope_x",) + tuple(f"sensor_dx{k}" for k in POWERS)
    probe_vectors = tuple(f"probe_dx{k}" for k in range(1, DEGREE + 1))

    def scales(self, p: dict, xp) -> dict:
        s = self._stretch(p)
        return {k: s**n for k, n in BENDING_POWERS.items()} | {"clamp_edge": s**-2, "plate": s}

    def inertia(self, p: dict, xp) -> dict:
        s, dL = self._stretch(p), p["dL_m"]
        return {"plate_slope_x": 1.0 / s - s} | {f"sensor_dx{k}": dL**k for k in POWERS}

    def probe(self, p: dict, xp) -> dict:
        dL = p["dL_m"]
        return {f"probe_dx{k}": dL**k for k in range(1, DEGREE + 1)}

    def assemble(self, ctx) -> dict:
        from vibid.identify.model.forms import slope_x

        g = ctx.geometry
        if self.length_m is not None and self.length_m != g.length_m:
            raise ValueError("free_length: bound to another plate's length")
        at = places()
        shifts = [sensor_shift_m(g.length_m, g.sensor_x_m, t) for t in at]
        if g.sensor_x_m + max(shifts) + g.sensor_radius_m > g.length_m:
            raise ValueError(
                "free_length: the sensor's disc reaches the plate's tip; "
                "declare it at least 0.5 mm inside"
            )
        along = np.array([1.0, 0.0])
        inertia = ctx.sensor_shift(along, at, shifts)
        centre = np.array([g.sensor_x_m, g.sensor_y_m])
        probes = polynomial_through(
            ctx.probe, [ctx.probe_at(centre + d * along) for d in shifts], at
        )
        tilt = g.mass_per_area_kg_m2 * g.thickness_m**2 / 12.0 * slope_x.assemble(ctx.basis)
        return (
            {"plate_slope_x": tilt.tocsr()}
            | {f"sensor_dx{k}": inertia[k] for k in POWERS}
            | {f"probe_dx{k + 1}": c for k, c in enumerate(probes)}
        )

    def for_geometry(self, geometry) -> FreeLength:
        return FreeLength(float(geometry.length_m))

    def _stretch(self, p: dict):
        if self.length_m is None:
            raise ValueError("free_length: the term is not bound to a plate (for_geometry)")
        return 1.0 + p["dL_m"] / self.length_m


EFFECT = FreeLength()
