"""``transverse_shear``: the shear deflection of a thick plate (simplified Reissner–Mindlin).

A Kirchhoff plate is rigid in transverse shear; a real one of thickness ``h`` also shears,
which lowers its bending frequencies by about ``(h k)² D/(κ G h³)`` relative (``k`` the
wavenumber) and adds its own deflection to what the sensor reads. The simplified
Reissner–Mindlin theory (Endo & Kimura 2007) splits the deflection into a bending part
``w_b`` (the Kirchhoff plate: its curvature carries the moments, its slope the rotary
inertia) and a shear part ``w_s``, a field of its own that carries the shear force::

    U = ½ a(w_b, w_b) + ½ κGh ∫ |∇w_s|²,   T = ½ ∫ ρh (1 + w_b + w_s)² + rotary(w_b) + sensor

(``w_s = 0`` on the clamped edge, its slope free there; the base's rigid motion ``1`` and
every translational mass, the plate's and the sensor's, move with ``w_b + w_s``). On a
beam this is Timoshenko's theory exactly (shear force ``κGA (w' − ψ)``, ``ψ = w_b'``), the
sensor's inertia force and the response between the resonances included; vibid's plate
with the term matches the exact Timoshenko cantilever's AFC to 1e-9 on a simulated 3 mm
strip up to 4.4 kHz (``tests/test_transverse_shear_vs_timoshenko.py``).

The term is the shear field's degrees of freedom (the plate's element, its displacement
fixed on the clamp line: :mod:`vibid.identify.model.assembly` adds them after the plate's):

* a stiffness ``κGh ∫ ∇u·∇v`` on the field, its coefficient set by the material:
  ``κGh = 6κ D(1−ν)/h²`` for an isotropic plate (``G = E/2(1+ν)``: no parameter of its
  own, the report format's "Effect names"), ``κ h G13`` for an orthotropic one (``G13_Pa``;
  ``G23 = G13``); it shares the plate's loss factor;
* an inertia ``ρh ∫ u v + m/(π r²) ∫_disc u v`` coupling the field to the plate's
  deflection and to itself (the base's rigid motion loads it through the same matrix);
* a probe: the sensor reads ``w_b + w_s`` at its centre.

``κ = 5/6`` (Reissner). Not carried: the shear under an undeclared added mass (the
declared sensor's mass is used; second order in the shear). A model cannot hold the term
beside a free length or a moved sensor (:attr:`excludes`): their matrices move the
plate's or the sensor's mass on the bending deflection alone, and the field, coupled to
the declared mass, would then see a mass the plate does not have (the kinetic energy of
``w_b = −w_s`` turns negative: on the exact beam with a free length a refit took 265 s
on bases whose modes reached 545 Hz of the 6 kHz wanted).

Null: the term absent (shear-rigid). A parameter-free term cannot be scored at a null
value of its own; the loop scores it along the straight line from the model without it to
the model with it (one degree of freedom).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from vibid.identify.model.terms import Term
from vibid.parameters import G13  # G13_Pa (Pa): the catalogue declares it

#: Reissner's shear correction factor.
KAPPA = 5.0 / 6.0
#: The dofs that fix the shear deflection on the clamp line (its value along the edge:
#: the value and its derivatives along the edge at the nodes there).
HELD_ON_CLAMP = ("u", "u_y", "u_yy")


@dataclass(frozen=True)
class TransverseShear(Term):
    """The shear deflection as a field of its own (module docstring).

    ``orthotropic`` selects the material's form: False for an isotropic plate (no
    parameter), True for an orthotropic or monoclinic one (``G13_Pa``).
    """

    orthotropic: bool = False
    name = "transverse_shear"
    meaning = "shear deformation of a thick plate (Reissner–Mindlin)"
    stiffness_matrices = ("shear",)
    inertia_matrices = ("shear_mass",)
    probe_vectors = ("shear_probe",)
    all_parameters = (G13,)
    excludes = ("free_length", "sensor_position")

    @property
    def parameters(self):
        return (G13,) if self.orthotropic else ()

    def for_material(self, material) -> TransverseShear:
        return TransverseShear(orthotropic=material.model != "isotropic")

    def stiffness(self, p: dict, xp) -> dict:
        if self.orthotropic:  # matrix κh ∫ ∇u·∇v
            return {"shear": (p["G13_Pa"], None)}
        return {"shear": (p["D"] * (1.0 - p["nu"]), None)}  # matrix 6κ/h² ∫ ∇u·∇v

    def inertia(self, p: dict, xp) -> dict:
        return {"shear_mass": 1.0}

    def probe(self, p: dict, xp) -> dict:
        return {"shear_probe": 1.0}

    def assemble(self, ctx) -> dict:
        from vibid.identify.model.forms import slope_x, slope_y

        h = ctx.geometry.thickness_m
        n = ctx.basis.N
        field = np.setdiff1d(np.arange(n), ctx.clamped(HELD_ON_CLAMP))  # the field's dofs
        lift = sp.csr_matrix(
            (np.ones(field.size), (field, np.arange(field.size))), shape=(n, field.size)
        )  # field dofs -> the plate's dofs
        gradient = (slope_x.assemble(ctx.basis) + slope_y.assemble(ctx.basis)).tocsr()
        scale = KAPPA * h if self.orthotropic else 6.0 * KAPPA / h**2
        zero = sp.csr_matrix((n, n))
        mass = ctx.translational_inertia()
        coupling = mass @ lift
        probe = np.concatenate([np.zeros(n), lift.T @ ctx.probe])
        return {
            "shear": sp.block_diag([zero, scale * (lift.T @ gradient @ lift)]).tocsr(),
            "shear_mass": sp.bmat([[None, coupling], [coupling.T, lift.T @ mass @ lift]]).tocsr(),
            "shear_probe": probe,
        }


EFFECT = TransverseShear()
