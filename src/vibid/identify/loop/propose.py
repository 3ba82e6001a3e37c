"""A round's first step: the proposals, every candidate that applies at each place to try it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from vibid.identify.loop.candidates import Place
from vibid.identify.loop.policy import Policy

if TYPE_CHECKING:
    from vibid.identify.loop.state import Inputs, State


def propose(inputs: Inputs, state: State) -> list:
    """Every candidate of the pool that applies to the current model (a structural fact,
    :meth:`~vibid.identify.loop.candidates.EffectCandidate.applies`), a resonance once per
    place to try it: each diagnosed pole and the residual's largest maxima along the band
    (:func:`residual_peaks`)."""
    current = state.current
    model = current.result.plate_model
    peaks = residual_peaks(current.result, inputs.policy)
    return [
        p for c in inputs.pool if c.applies(model) for p in c.placements(current.diagnosis, peaks)
    ]


def residual_peaks(result, policy: Policy) -> tuple[Place, ...]:
    """The frequencies of the :attr:`Policy.band_trials` largest local maxima of the
    weighted residual's magnitude along the band (with the policy's trial Q): where a
    resonance the diagnosis did not find may stand."""
    u = np.asarray(result.used)
    f = np.asarray(result.frequency_hz)[u]
    order = np.argsort(f)
    r = np.abs(
        (np.asarray(result.model_afc)[u] - np.asarray(result.H)[u]) / np.asarray(result.weights)
    )[order]
    f = f[order]
    if r.size < 3:
        return ()
    inner = np.flatnonzero((r[1:-1] >= r[:-2]) & (r[1:-1] >= r[2:])) + 1
    top = inner[np.argsort(-r[inner])][: policy.band_trials]
    return tuple(Place(float(f[i]), policy.trial_q, "residual_peak") for i in top)
