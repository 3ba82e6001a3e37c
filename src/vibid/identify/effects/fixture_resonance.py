"""``fixture_resonance``: the clamp moves otherwise than the base accelerometer beside it.

The base accelerometer sits on the shaker table, the clamp on a fixture bolted to it. Near
a resonance of the fixture (or of the table between the two points) the clamp's
translation is no longer the motion the base sensor measures: per unit table motion the
clamp moves

    C(f) = 1 + a r² / (1 − r² + i r / q),   r = f / f₀

(a base-excited mode's transmissibility; an SDOF fixture, mass on a spring, has a = 1; a
mode of which the clamp carries a share has |a| < 1, and a mode the base sensor's spot
shares more than the clamp has a < 0). The plate answers to the clamp's motion, the
measured ratio divides by the base sensor's, so

    H = C(f) H_plate:

a pole and a zero close together, and a step of |H| across them: |C| goes from 1 below
f₀ to 1 − a (roughly) above, which a sensor gain or a loss law mistakes for a misfit
across the whole band. Unlike ``stand_resonance`` (the table rocking, which the base
sensor on the clamp line cannot see) the fixture translates, and the plate's own response
is unchanged. The step is a few per cent: on a real strip, from +6 % below a 665 Hz stand
feature to −7 % above (BENCHMARKS.md; ``tests/test_effect_fixture_resonance.py``).

Null value ``a_fixture = 0``. The loop places it at the diagnosed extra pole across which
|H / model| steps most (:meth:`FixtureResonance.placed_at`), also one whose phase is no
causal factor's, and it is the one candidate credited with removing such a pole
(``acausal_pole``, :attr:`vibid.identify.loop.diagnosis.Feature.kinds`): the ratio divides by
the base sensor's motion. Its frequency starts at the pole and stays within the loop's
span of it (:attr:`vibid.identify.loop.policy.Policy.pole_span`); its quality factor is free
in its box (the step's width sets it, not the pole's sharpness).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibid.identify.model.terms import Term
from vibid.parameters import A_FIXTURE, F_FIXTURE, Q_FIXTURE

#: A fixture resonance steps |H| across its pole: the step is read this factor either side
#: (the loop's span for a placed resonance, :attr:`vibid.identify.loop.policy.Policy.pole_span`).
STEP_SPAN = 1.1


@dataclass(frozen=True)
class FixtureResonance(Term):
    """``H → (1 + a r² / (1 − r² + i r / q)) H``."""

    name = "fixture_resonance"
    explains = ("extra_pole", "acausal_pole")
    needs_feature = True
    #: its frequency is the diagnosed pole's; its Q is not (the step's width sets it)
    feature_places = {"f_fixture_hz": "f_hz"}
    meaning = (
        "a resonance of the fixture that carries the clamp (the clamp moves "
        "otherwise than the base sensor beside it)"
    )
    parameters = (F_FIXTURE, Q_FIXTURE, A_FIXTURE)
    in_every_structure = False

    def placed_at(self, diagnosis):
        """The extra pole across which the ratio measured / model steps most: |R| at
        ``f / STEP_SPAN`` against ``f STEP_SPAN``, in the diagnosis's rational fit. Any
        extra pole, also one whose phase is no causal factor's: a ratio of two sensors'
        motions divides by the base sensor's, which is weak where the base shares a mode
        the clamp does not (the diagnosis's own reading of such a pole). Not a pole beside
        a mode of the model that its sensor does not see (``hidden_mode_hz``): that is the
        mode, more plainly (a sensor off its declared place), and a fixture's pole and zero
        would mimic it."""
        poles = [
            x
            for x in diagnosis.extra_poles()
            if math.isfinite(x.f_hz) and not math.isfinite(x.hidden_mode_hz)
        ]
        if not poles:
            return None

        def step(x):
            R = np.abs(diagnosis.ratio(np.array([x.f_hz / STEP_SPAN, x.f_hz * STEP_SPAN])))
            return abs(R[0] - R[1])

        return max(poles, key=step)

    def afc_map(self, p: dict, omega, H, xp):
        r = omega / (2 * math.pi * p["f_fixture_hz"])
        return H * (1.0 + p["a_fixture"] * r**2 / (1.0 - r**2 + 1j * r / p["q_fixture"]))


EFFECT = FixtureResonance()
