"""``sensor_inertia``: the response sensor's rotary inertia about the plate's mid-plane.

The setup declares the sensor as a thin disc: its mass spread over its footprint, with the
rotary inertia of a layer as thick as the plate. A real accelerometer is a block several
millimetres tall (a 1.7 g sensor on a 3 mm strip): when the plate tilts under it by the
slope ``∇w``, its centre of mass, ``e = h/2 + height`` above the mid-plane, moves sideways
by ``e ∇w`` and adds the kinetic energy ``½ m e² |∇ẇ|²``. Beyond the declared disc's
(``e = h/2``) this is

    ½ m (h·height + height²) |∇ẇ|²,

averaged over the disc: two inertia matrices, ``m h G`` and ``m G`` with
``G = ∫_disc ∇u·∇v / (π r²)``, scaled by ``height`` and ``height²``. The block's own
moment of inertia about its centre of mass is not separated from ``m e²`` (``height``
is then the radius of gyration of the sensor about the surface less ``h/2``, which is
what a fit can tell). It lowers the modes whose slope under the sensor is large (the
higher bending modes of a strip, where the sensor is not at an antinode). Null value
``height = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import HEIGHT


@dataclass(frozen=True)
class SensorInertia(Term):
    """The sensor's centre of mass ``height_m`` above the plate's surface."""

    name = "sensor_inertia"
    meaning = "the response sensor's rotary inertia (its height above the plate)"
    parameters = (HEIGHT,)
    inertia_matrices = ("sensor_tilt_1", "sensor_tilt_2")

    def inertia(self, p: dict, xp) -> dict:
        e = p["height_m"]
        return {"sensor_tilt_1": e, "sensor_tilt_2": e**2}

    def assemble(self, ctx) -> dict:
        tilt = ctx.sensor_tilt()
        return {"sensor_tilt_1": (ctx.geometry.thickness_m * tilt).tocsr(), "sensor_tilt_2": tilt}


EFFECT = SensorInertia()
