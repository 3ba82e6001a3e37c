"""After a choice: the effects added earlier that the new one makes redundant, withdrawn;
and at the end the last addition, never tested so, tested from the loop's final estimate
(:func:`at_the_end`)."""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from typing import TYPE_CHECKING

from vibid.identify.loop import refit as refits
from vibid.identify.loop.candidates import distance_from_null
from vibid.identify.loop.evidence import Noise, log_evidence
from vibid.identify.loop.examine import diagnosed
from vibid.identify.loop.verdicts import Score, Stage, Verdict

if TYPE_CHECKING:
    from vibid.identify.loop.state import Inputs, State

log = logging.getLogger(__name__)


def withdraw(
    inputs: Inputs, stage: Stage, box: dict, prior: dict, added: list, last_too: bool = False
) -> tuple[Stage, list]:
    """``stage`` less the effects added in earlier rounds that the new one makes
    redundant (an isotropic fit's extra peak taken for a stand resonance, then the
    orthotropic material that places it; a fixture's step that stood in for a mass the
    next round adds): each one is refitted without, and withdrawn where the model without
    it is the more probable (its evidence, under the new fit's noise model). With
    ``last_too`` the stage's own addition is tested as well (:func:`at_the_end`). Returns
    the stage and a :class:`Score` per withdrawn effect."""
    gone = []
    for term in reversed(stage.result.plate_model.effects):
        res = stage.result
        if term.name not in added or not term.parameters:
            continue
        if term.name == stage.added and not last_too:
            continue
        z = distance_from_null(term, res)
        model = res.plate_model.without_effect(term)
        start = {n: v for n, v in res.parameters.items() if n in model.names}
        d, bounds = inputs.data, model.default_bounds(box)
        fm = inputs.plate.forward_model(
            d.frequency_hz[d.used], model=model, theta0=start, bounds=bounds
        )
        try:
            smaller = refits.polish(inputs.plate, d, fm, start, bounds, None, inputs.local)
        except Exception as exc:  # noqa: BLE001 - the larger model stays
            log.info("loop: %s could not be refitted without %s: %s", stage.added, term.name, exc)
            continue
        noise = Noise.of(res, d.n_residuals)
        chi2_with, chi2_without = _data_chi2(res), _data_chi2(smaller)
        odds = (
            log_evidence(smaller, prior, noise, chi2=chi2_without).log_z
            - log_evidence(res, prior, noise, chi2=chi2_with).log_z
        )
        if not (smaller.converged and odds >= 0):
            continue
        stage = Stage.of(stage.added, smaller)
        gone.append(
            Score(
                term.name,
                math.nan,
                len(term.parameters),
                math.nan,
                math.nan,
                delta_chi2=-float(chi2_without - chi2_with),
                verdict=Verdict.WITHDRAWN,
                log_evidence=odds,
                detail=((("final", True),) if last_too else (("by", stage.added),))
                + (("z", z), ("odds", odds)),
            )
        )
    return stage, gone


def at_the_end(inputs: Inputs, state: State) -> State:
    """``state`` less the added effects that its final estimate makes redundant.

    Each round tests the effects added before it from the new fit (:func:`withdraw`), so
    only the last addition was never tested from a later estimate, and it may only have
    moved the fit out of the basin an earlier refit stopped in (an isotropic plate's
    orthotropic refit left in a wrong basin, then a free length). The same test for it:
    the evidence of the model without it, refitted from the final estimate; where it goes,
    the earlier additions are tested again from that smaller fit (the last round tested
    them with it in the model). A withdrawn effect's stage goes, and the last stage kept
    takes the smaller refit (its model is the one left; where every effect goes, the
    declared model's own fit stands). The withdrawals are recorded in the last round."""
    added = [s.added for s in state.stages[1:]]
    if not added or not state.rounds:
        return state
    box, prior = state.box, state.prior
    stage, gone = withdraw(inputs, state.current, box, prior, added[-1:], last_too=True)
    if not gone:
        return state
    if added[:-1]:
        stage, more = withdraw(inputs, stage, box, prior, added[:-1], last_too=True)
        gone += more
    dropped = {s.name for s in gone}
    kept = [s for s in state.stages if s.added not in dropped]
    if kept[-1].added is not None:  # (all withdrawn: the declared model's own fit stands)
        smaller = diagnosed(inputs, Stage.of(kept[-1].added, stage.result))
        kept[-1] = replace(smaller, alternatives=kept[-1].alternatives)  # what it compared
    rounds = state.rounds[:-1] + (state.rounds[-1] + tuple(gone),)
    return replace(state, stages=tuple(kept), rounds=rounds)


def _data_chi2(result) -> float:
    """``result``'s chi2 under the data's weights as the report gives it."""
    return float(result.chi2_reduced_reported * result.dof)
