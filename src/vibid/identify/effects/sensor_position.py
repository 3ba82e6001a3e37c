"""``sensor_position``: the response sensor sits ``dy`` across the width from where the
setup says (a mounting error of a few millimetres, or a declared position measured to the
wrong edge).

Across the width of a strip the sensor sees the torsion modes in proportion to its offset
from the centre line, and its mass couples bending into torsion in proportion to it: a
wrong position misplaces every torsional contribution, which the declared model can only
absorb in Poisson's ratio (the torsional stiffness). The term moves the declared sensor's
disc (its mass and rotary inertia) and the point where the response is read.

The field under the sensor is interpolated across the width, at each point of the disc,
by the cubic through the declared place and three places spread over the reach of the
parameter's default box (:func:`places`), so that

    M_sensor(dy) = M_0 + Σ_k dy^k M_k (k = 1..6),     c(dy) = c_0 + Σ_k dy^k c_k (k = 1..3)

(``M_sensor`` a Gram matrix, positive for every ``dy``; exact for modes whose deflection is
at most cubic across the width, as a strip's bending, anticlastic curvature included, and
torsion are, and exact at the four places for any mode). The term is thus affine in its
coefficients (powers of ``dy``) and every evaluator reads it through the term interface.
Null value ``dy = 0``: the declared place. An undeclared ``added_mass`` stays at the
declared centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibid.identify.model.disc import polynomial_through
from vibid.identify.model.terms import Term

# sensor_dy_m (m): the catalogue declares it. Its default box is also the reach of the
# interpolation across the width (:func:`places`): the polynomial's error grows with the
# offset, and on a real strip's setup it grew from below 2e-4 of |H| to 5.7e-4 at ±10 mm.
from vibid.parameters import DY

#: Degree of the interpolation across the width.
DEGREE = 3
#: Room (m) kept between the disc and the plate's edges at the interpolation's places.
EDGE_CLEARANCE_M = 1e-6


def places(y_m: float, radius_m: float, width_m: float) -> tuple[float, ...]:
    """The :data:`DEGREE` places (m, besides 0) of the interpolation: evenly spread over
    the default box, as far as the disc stays on the plate."""
    lo = max(DY.bounds[0], -(y_m - radius_m - EDGE_CLEARANCE_M))
    hi = min(DY.bounds[1], width_m - y_m - radius_m - EDGE_CLEARANCE_M)
    grid = np.linspace(lo, hi, DEGREE + 1)
    return tuple(float(t) for t in np.delete(grid, np.argmin(np.abs(grid))))


POWERS = tuple(range(1, 2 * DEGREE + 1))


@dataclass(frozen=True)
class SensorPosition(Term):
    """The response sensor ``sensor_dy_m`` across the width from its declared centre."""

    name = "sensor_position"
    #: besides a misplaced torsion, a mode the declared place hides (its node line)
    explains = ("mode_shift", "hidden_mode")
    meaning = "the response sensor off its declared place across the width"
    parameters = (DY,)
    inertia_matrices = tuple(f"sensor_dy{k}" for k in POWERS)
    probe_vectors = tuple(f"probe_dy{k}" for k in range(1, DEGREE + 1))

    def inertia(self, p: dict, xp) -> dict:
        dy = p["sensor_dy_m"]
        return {f"sensor_dy{k}": dy**k for k in POWERS}

    def probe(self, p: dict, xp) -> dict:
        dy = p["sensor_dy_m"]
        return {f"probe_dy{k}": dy**k for k in range(1, DEGREE + 1)}

    def assemble(self, ctx) -> dict:
        g = ctx.geometry
        at = places(g.sensor_y_m, g.sensor_radius_m, g.width_m)
        across = np.array([0.0, 1.0])
        inertia = ctx.sensor_shift(across, at)
        centre = np.array([g.sensor_x_m, g.sensor_y_m])
        probes = polynomial_through(ctx.probe, [ctx.probe_at(centre + t * across) for t in at], at)
        return {f"sensor_dy{k}": inertia[k] for k in POWERS} | {
            f"probe_dy{k + 1}": c for k, c in enumerate(probes)
        }


EFFECT = SensorPosition()
