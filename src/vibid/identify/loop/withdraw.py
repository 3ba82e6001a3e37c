"""After a choice: the effects added earlier that the new one makes redundant, withdrawn."""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from vibid.identify.loop import refit as refits
from vibid.identify.loop.candidates import distance_from_null
from vibid.identify.loop.evidence import Noise, log_evidence
from vibid.identify.loop.verdicts import Score, Stage, Verdict

if TYPE_CHECKING:
    from vibid.identify.loop.state import Inputs

log = logging.getLogger(__name__)


def withdraw(
    inputs: Inputs, stage: Stage, box: dict, prior: dict, added: list
) -> tuple[Stage, list]:
    """``stage`` less the effects added in earlier rounds that the new one makes
    redundant (an isotropic fit's extra peak taken for a stand resonance, then the
    orthotropic material that places it; a fixture's step that stood in for a mass the
    next round adds): each one is refitted without, and withdrawn where the model without
    it is the more probable (its evidence, under the new fit's noise model). Returns the
    stage and a :class:`Score` per withdrawn effect."""
    gone = []
    for term in reversed(stage.result.plate_model.effects):
        res = stage.result
        if term.name == stage.added or term.name not in added or not term.parameters:
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
                detail=(("by", stage.added), ("z", z), ("odds", odds)),
            )
        )
    return stage, gone


def _data_chi2(result) -> float:
    """``result``'s chi2 under the data's weights as the report gives it."""
    return float(result.chi2_reduced_reported * result.dof)
