"""A refit's parameter held inside its prior box: where a new effect's refit takes a
parameter the current fit has inside its box outside it, for no more chi2 than a
parameter that explains nothing takes from the misfit, the effect is judged on the refit
with that parameter held at its current value.

Poisson's ratio of a strip, which its two bending modes barely determine, wanders to a
face of its box with every effect tried on a real strip (BENCHMARKS.md); judged free,
an effect that explains a large share of the misfit would be weighed on that excursion.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from vibid.identify.fit.local import HeldProblem, run_local
from vibid.identify.fit.minima import indistinct_chi2
from vibid.identify.fit.noise import misfit_scale

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Held:
    """A refit with the parameters it would take outside their prior box held at the
    current fit's values (:func:`held_inside`): the run, the values held, and how much
    lower chi2 the excursion went (``excursion``) against what a parameter that explains
    nothing removes from the misfit (``indistinct``)."""

    run: object  # LocalResult
    values: dict
    boxes: dict  # each held parameter's prior box
    excursion: float
    indistinct: float

    def kinds(self, space) -> dict:
        """Transforms that hold each value in the polish: a logit over a span a millionth
        of its prior box wide (the covariance is the Fisher information's in the
        parameters themselves, so the held one keeps its full standard deviation)."""
        out = {}
        for n, v in self.values.items():
            t = space.transforms[space.names.index(n)]
            half = HELD_SPAN * (t.high - t.low) / 2
            out[n] = ("logit", v - half, v + half)
        return out

    @property
    def sentence(self) -> str:
        """What the report says of the hold."""
        boxes = ", ".join(f"{n} {lo:.3g} to {hi:.3g}" for n, (lo, hi) in self.boxes.items())
        return (
            ", ".join(f"{n} held at {v:.3g}" for n, v in self.values.items())
            + f": free, the refit takes {'it' if len(self.values) == 1 else 'them'} "
            f"outside the prior box ({boxes}) for a chi2 lower by {self.excursion:.3g}, "
            "no more than a parameter that explains nothing removes from this misfit "
            f"({self.indistinct:.3g})"
        )


#: The width of a held parameter's span in the polish, as a share of its prior box.
HELD_SPAN = 1e-6


def held_inside(res, space, u0, u, around, local: str) -> Held | None:
    """Where a refit (ended at ``u``) takes a parameter that the current fit (``u0``) has
    inside its prior box outside it (Poisson's ratio of a strip, which two bending modes
    barely determine, wanders to a face with a new effect), the refit with those
    parameters held at the current values: a :class:`Held` when its chi2 lies above the
    free refit's by no more than the misfit's own error lets a parameter that explains
    nothing remove (:func:`~vibid.identify.fit.minima.indistinct_chi2` in units of the
    reduced chi2 times the residual's correlation,
    :func:`~vibid.identify.fit.noise.misfit_scale`: the units the judge weighs a new
    effect in), else None (the excursion is what explains the residual: the judge rejects
    the refit). The held refit starts from ``u``, the held parameters at their current
    values, and runs twice: the second time on a basis built where the first ended (from
    the free refit's basis, 0.5 away in nu, a real strip's refit stopped at chi2 2.24e7
    instead of 1.88e7). The held parameter keeps its full std."""
    current = set(space.out_of_bounds(space.theta(u0)))
    strayed = [
        n
        for n in space.out_of_bounds(space.theta(u))
        if n in res.parameter_names and n not in current
    ]
    if not strayed:
        return None
    free_loss = around(u).chi2(u)
    birge, tau = misfit_scale(res)
    indistinct = indistinct_chi2(len(strayed), max(1.0, birge) * tau)
    at = [space.names.index(n) for n in strayed]
    free = np.array([i for i in range(space.size) if i not in at])
    full = np.array(u, float)
    full[at] = u0[at]
    try:
        for _ in range(2):  # the second on a basis built where the first ended
            fixed = HeldProblem(around(full), free, full)
            r, _ = run_local(local, fixed, full[free], None)  # converged: its chi2 is judged
            full = fixed.space.full(r.u)
    except Exception as exc:  # noqa: BLE001 - the refit's excursion stands
        log.info("loop: a held refit failed: %s", exc)
        return None
    if (
        not (r.converged and np.isfinite(r.loss) and np.isfinite(free_loss))
        or r.loss > free_loss + indistinct
    ):
        return None
    log.info(
        "loop: %s held inside the prior box (chi2 %.6g against %.6g free)",
        ", ".join(strayed),
        r.loss,
        free_loss,
    )
    return Held(
        replace(r, u=full, theta=space.theta(full)),
        {n: float(space.theta(u0)[k]) for n, k in zip(strayed, at)},
        {n: (space.transforms[k].low, space.transforms[k].high) for n, k in zip(strayed, at)},
        float(r.loss - free_loss),
        indistinct,
    )
