"""``frequency_dependent_loss``: a loss factor that varies with frequency.

Polymer matrices and coatings dissipate more at some frequencies than others; over a band
the power law ``β(f) = β (f / f_ref)^α`` with ``f_ref = 1000 Hz`` (report format: ``beta``
is then the loss factor at 1 kHz) covers it. It multiplies every loss factor of the model,
so the modes stay real and the modal solver applies it at each frequency. Null ``α = 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import ALPHA  # alpha (1): the catalogue declares it

#: The reference frequency of the law (report format).
F_REF_HZ = 1000.0


@dataclass(frozen=True)
class FrequencyDependentLoss(Term):
    """Loss factors times ``(f / 1 kHz)^alpha``."""

    name = "frequency_dependent_loss"
    explains = ("damping",)
    meaning = "a loss factor that varies with frequency"
    parameters = (ALPHA,)

    def loss_law(self, p: dict, omega, xp):
        return (omega / (2 * math.pi * F_REF_HZ)) ** p["alpha"]


EFFECT = FrequencyDependentLoss()
