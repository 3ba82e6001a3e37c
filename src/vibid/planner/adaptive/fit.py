"""The fit of the steps measured so far, and what it says: is the target reached?

:func:`fit_steps` fits as the report does (the signal stage's AFC sorted by frequency, the
declared model, the closed loop when the one judge of "fits the data" says the residual asks
for it); a later fit starts from the last one (its model with the effects found so far; the
declared model, and the loop, again when that no longer explains the data). Without a
previous fit it is the report's own identification, which the campaign also asks before it
stops on a warm fit's word.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibid.errors import VibidError

log = logging.getLogger(__name__)

__all__ = ["CurrentFit", "fit_steps", "noise_level", "reached", "worst_ratio"]


@dataclass(frozen=True)
class CurrentFit:
    """The fit of the steps measured so far: ``result`` (the final model's, effects
    included), ``declared`` (the declared model's: where the next fit starts when the
    effects no longer explain), ``loop`` (the closed loop's, when it ran), ``unexpected_hz``
    (with Q: resonances the residual shows where the model has none) and ``noise`` (each
    channel's noise relative to the base amplitude, estimated from the AFC's std)."""

    result: Any
    declared: Any
    loop: Any
    noise: float
    unexpected: tuple[tuple[float, float], ...] = ()
    seconds: float = math.nan
    #: a local refit from the last fit (cheap); else the report's own identification
    #: (the global search with the report's restarts and seed, the loop where asked)
    warm: bool = False

    def std_of(self, name: str) -> tuple[float, float]:
        """(value, reported standard uncertainty) of a parameter."""
        j = list(self.result.parameter_names).index(name)
        return float(self.result.values[j]), float(self.result.std[j])


def reached(fit: CurrentFit, targets) -> tuple[bool, str]:
    """Whether each target is met by the fit's reported std, and the line that says so."""
    parts, ok = [], True
    for t in targets:
        value, std = fit.std_of(t.name)
        want = t.std_of(value)
        ok &= bool(std <= want)
        if t.relative:
            parts.append(f"{t.name} {100 * std / abs(value):.3g} % (target {100 * t.value:g} %)")
        else:
            parts.append(f"{t.name} {std:.3g} (target {t.value:g})")
    return ok, ", ".join(parts)


def worst_ratio(fit: CurrentFit, targets) -> float:
    """The largest targeted standard uncertainty over its target."""
    out = 0.0
    for t in targets:
        value, std = fit.std_of(t.name)
        out = max(out, std / t.std_of(value))
    return out


def fit_steps(
    setup,
    afc,
    previous: CurrentFit | None = None,
    *,
    loop: bool = True,
    candidates=None,
    restarts: int = 5,
    seed: int = 0,
) -> CurrentFit:
    """Fit the AFC of the steps so far (sorted by frequency), as the module doc says.
    Without ``previous``, the report's own identification (``restarts``, ``seed``)."""
    from vibid.identify.engine.threads import jax_turn
    from vibid.identify.fit import Measurement, SearchOptions, identify
    from vibid.identify.fit.noise import explains

    t0 = time.perf_counter()
    with jax_turn():
        if previous is not None:
            warm = _local(setup, afc, previous.result)
            if warm is not None and explains(warm):
                return CurrentFit(
                    warm,
                    previous.declared,
                    previous.loop,
                    noise_level(afc),
                    seconds=time.perf_counter() - t0,
                    warm=True,
                )
        declared = None
        if previous is not None:
            declared = _local(setup, afc, previous.declared)
        if declared is None or not declared.converged:
            declared = identify(
                setup,
                Measurement(afc.frequency_hz, afc.H, afc.std, used=afc.used),
                search=SearchOptions(restarts=restarts, seed=seed),
            )
        result, closed = declared, None
        if loop and declared.converged and not explains(declared):
            from vibid.identify.loop import close_loop

            closed = close_loop(
                setup,
                afc.frequency_hz,
                afc.H,
                afc.std,
                used=afc.used,
                candidates=candidates,
                declared=declared,
            )
            result = closed.final
        unexpected = () if explains(result) else _unexpected(setup, result, closed)
    return CurrentFit(
        result,
        declared,
        closed,
        noise_level(afc),
        unexpected,
        time.perf_counter() - t0,
        warm=previous is not None,
    )


def _local(setup, afc, start_result):
    """``start_result``'s model (its effects included) refitted locally from its estimate,
    or None where it cannot be."""
    from vibid.identify.fit import Measurement, ModelChoice, SearchOptions, identify
    from vibid.identify.model.plate import build_forward_model

    plate = start_result.plate_model
    if plate is None:
        return None
    start = {n: float(v) for n, v in zip(start_result.parameter_names, start_result.values)}
    box = plate.default_bounds(dict(setup.identification.bounds))
    try:
        fm = build_forward_model(
            setup, afc.frequency_hz[afc.used], model=plate, theta0=start, bounds=box
        )
        return identify(
            setup,
            Measurement(afc.frequency_hz, afc.H, afc.std, used=afc.used),
            ModelChoice(name=plate.model, forward_model=fm, bounds=box),
            SearchOptions(method="local", start=start),
        )
    except VibidError as exc:
        log.info("adaptive: the local refit failed (%s); searching again", exc)
        return None


def _unexpected(setup, result, closed) -> tuple[tuple[float, float], ...]:
    """Resonances the residual shows where the fitted model has none: (f_hz, Q)."""
    from vibid.identify.loop.diagnosis import diagnosis_of
    from vibid.identify.loop.examine import modes_of
    from vibid.identify.model.plate import Plate

    diagnosis = None
    if closed is not None and closed.stages:
        diagnosis = closed.stages[-1].diagnosis
    if diagnosis is None:
        diagnosis = diagnosis_of(modes_of(Plate(setup), result), result)
    if diagnosis is None:
        return ()
    return tuple(
        (float(f.f_hz), float(f.q))
        for f in diagnosis.features
        if f.kind == "extra_pole" and np.isfinite(f.f_hz) and f.q > 2
    )


def noise_level(afc) -> float:
    """Each channel's noise relative to the base amplitude, from the AFC's std: the median
    over the used steps of ``s / (√(2/N) √(1 + |H|²))`` (:mod:`vibid.planner.information`)."""
    used = np.asarray(afc.used, bool)
    n = np.array([p.n_samples for p in afc.points], float)[used]
    s = np.asarray(afc.std, float)[used]
    h = np.abs(np.asarray(afc.H))[used]
    level = s / (np.sqrt(2.0 / n) * np.sqrt(1.0 + h**2))
    level = level[np.isfinite(level) & (level > 0)]
    return float(np.median(level)) if level.size else 1e-3
