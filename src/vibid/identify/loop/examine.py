"""A stage examined: its fitted plate's modes, then its residual's diagnosis
(:func:`~vibid.identify.loop.diagnosis.diagnosis_of`)."""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import TYPE_CHECKING

from vibid.identify.fit.result import IdentificationResult
from vibid.identify.loop.diagnosis import diagnosis_of
from vibid.identify.loop.verdicts import Stage
from vibid.identify.model.plate import Modes, Plate

if TYPE_CHECKING:
    from vibid.identify.loop.state import Inputs

log = logging.getLogger(__name__)


def diagnosed(inputs: Inputs, stage: Stage) -> Stage:
    """``stage`` with its fitted plate's modes (:meth:`Plate.modes`, asked once per stage)
    and its residual's diagnosis (either None where it cannot be made)."""
    modes = modes_of(inputs.plate, stage.result)
    return replace(
        stage, modes=modes, diagnosis=diagnosis_of(modes, stage.result, inputs.left_out_hz)
    )


def modes_of(plate: Plate, result: IdentificationResult, n: int = 12) -> Modes | None:
    """The first ``n`` modes of the plate at ``result``'s estimate, or None (logged) where
    its modal problem cannot be solved: then no diagnosis is made, and no candidate that
    needs the modes in the band is tried."""
    try:
        return plate.modes(result.parameters, n)
    except Exception as exc:  # noqa: BLE001 - the modes inform, they never stop a fit
        log.warning("loop: the fitted plate's modes could not be computed: %s", exc)
        return None
