"""The identified model's AFC on a fine grid: what the report's AFC figure and the live view
draw, computed here (JAX, in the assess stage's turn) so that the report only draws it.

On the measured steps alone a resonance between two steps is a straight line; the fine
grid (:data:`FINE_POINTS` evenly over the measured band, plus :data:`FINE_PER_MODE` within
:data:`FINE_HALF_WIDTH_BANDWIDTHS` half-power bandwidths of each natural frequency in it)
draws its peak at its height.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

#: Points of the fine grid the model is drawn on, spread evenly over the measured band;
#: each natural frequency in the band gets FINE_PER_MODE more within a few half-power
#: bandwidths of it, so its peak is drawn at its height.
FINE_POINTS = 2000
FINE_PER_MODE = 161
#: Half-widths around a mode densely sampled, in half-power bandwidths.
FINE_HALF_WIDTH_BANDWIDTHS = 12.0
#: Modes asked of the model to find those in the band.
N_MODES = 12


class ModelCurve(NamedTuple):
    """The model's AFC on the fine grid: ``frequency_hz`` (increasing), ``H`` (complex)
    and the natural frequencies in the band ``natural_hz`` (Hz)."""

    frequency_hz: np.ndarray
    H: np.ndarray
    natural_hz: np.ndarray


def model_curve(setup, result, *, n_points: int = FINE_POINTS) -> ModelCurve:
    """The final model of ``result`` (an ``IdentificationResult`` of the declared
    ``setup``) on the fine grid over the measured band (module doc), from the reduced model
    rebuilt around the estimate (accurate to about 1e-6 of max |H|)."""
    from vibid.identify.model.plate import Plate

    plate = Plate(setup)
    f_used = np.asarray(result.frequency_hz, float)[np.asarray(result.used, bool)]
    lo, hi = float(f_used.min()), float(f_used.max())
    fn, decay = plate.natural_frequencies(result.parameters, N_MODES)
    fn, decay = np.asarray(fn, float), np.asarray(decay, float)
    inband = (fn >= lo) & (fn <= hi)
    grids = [np.linspace(lo, hi, n_points)]
    for f0, g in zip(fn[inband], decay[inband]):
        half = FINE_HALF_WIDTH_BANDWIDTHS * max(g / np.pi, 1e-6 * f0)
        grids.append(np.clip(np.linspace(f0 - half, f0 + half, FINE_PER_MODE), lo, hi))
    grid = np.unique(np.concatenate(grids))
    model = plate.forward_model(grid, model=result.plate_model, theta0=result.parameters)
    return ModelCurve(grid, np.asarray(model.afc(np.asarray(result.values, float))), fn[inband])
