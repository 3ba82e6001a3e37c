"""``stand_resonance``: the shaker table or fixture rocking in a mode of its own.

A single cantilever puts a moment on the table, and a table or fixture has modes of its
own: near one of them the base does not only translate, it rocks about the clamp line. The
base accelerometer sits on the clamp line and does not see the rotation; the plate does.
With the base's rotation per unit base translation (rad/m, report format)

    θ(f) = θ₀ / (1 − (f/f₀)² + i f / (f₀ q)),

the plate's absolute motion is ``1 + θ x`` (``x`` from the clamp line) plus its response
to both, so that

    H = H_translation + θ(f) H_rotation,

``H_rotation`` the sensor's motion (m per rad) when the base turns by one radian: the
rigid rotation's load ``M x`` in place of the translation's ``M 1``
(:mod:`vibid.identify.model.assembly`). A resonance of the stand appears in H where the
plate has no mode, with the stand's frequency and quality factor; away from it θ is the
small quasi-static tilt ``θ₀``. Null value ``θ₀ = 0``.

An effect that may occur more than once: instance ``k`` has the parameters ``f_hz_k``,
``q_k`` and ``theta_rad_per_m_k`` (report format, "Effect names").
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import F_HZ, THETA, Q, instance_name


@dataclass(frozen=True)
class StandResonance(Term):
    """One resonance of the stand: the base rotation ``θ(f)`` per unit base translation."""

    instance: int = 1
    name = "stand_resonance"
    explains = ("extra_pole",)
    needs_feature = True
    feature_places = {"f_hz": "f_hz", "q": "q"}
    meaning = "a resonance of the shaker table or fixture (the base rocks about the clamp line)"
    rotates_base = True
    in_every_structure = False

    @property
    def parameters(self) -> tuple:
        return tuple(
            dataclasses.replace(q, name=instance_name(q.name, self.instance))
            for q in (F_HZ, Q, THETA)
        )

    def base_rotation(self, p: dict, omega, xp):
        f0, q, theta0 = (p[n] for n in self.names)
        r = omega / (2 * math.pi * f0)
        return theta0 / (1.0 - r**2 + 1j * r / q)

    def next_instance(self) -> StandResonance:
        """Another resonance of the stand (the next instance)."""
        return StandResonance(self.instance + 1)


EFFECT = StandResonance()
