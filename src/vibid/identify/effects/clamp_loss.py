"""``clamp_loss``: the clamp's own loss factor.

:mod:`~vibid.identify.effects.clamp_compliance` lets the clamp's rotational spring
dissipate like the plate. A real clamp's loss is its own: a clean, tight spring loses
almost nothing, a clamp that slips a little loses far more than the plate (friction in the
jaws, which damps the first mode most, as it bends the root most). This term gives the
spring the loss factor ``β_clamp``: its stiffness becomes ``k_θ (1 + i β_clamp)``. The
model's stiffness terms then no longer share one loss factor, its modes are complex, and
the reduced model solves per frequency instead of modally.

It goes with ``clamp_compliance`` (it has nothing to act on without a spring). Its null
value is the plate's loss factor (then the term changes nothing); where a fixed null is
needed, work in the ratio ``β_clamp / β`` (null 1).
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import BETA_CLAMP


@dataclass(frozen=True)
class ClampLoss(Term):
    """The clamp spring's loss factor ``beta_clamp`` instead of the plate's."""

    name = "clamp_loss"
    explains = ("damping",)
    meaning = "the clamp's own loss (its spring dissipates unlike the plate)"
    parameters = (BETA_CLAMP,)
    proportional = False
    in_every_structure = False
    #: the effect it refines, which a model must have first
    requires = "clamp_compliance"

    def loss_factors(self, p: dict, xp) -> dict:
        return {"clamp_edge": p["beta_clamp"]}

    def null_values(self, values: dict) -> dict:
        """``beta_clamp`` at which the term changes nothing: the plate's loss factor."""
        return {"beta_clamp": float(values["beta"])} if "beta" in values else {}


EFFECT = ClampLoss()
