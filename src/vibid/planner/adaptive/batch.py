"""The next batch: where the current fit says a second of stand time teaches most.

Draws from the current fit's posterior (its estimate, the other minima it could not tell
from it, then its covariance), the Fisher information per step over them at candidate
frequencies (a grid over the band and each mode's half-power band evenly in phase:
:mod:`vibid.planner.information`), greedily by expected gain per second of stand time
(:mod:`vibid.planner.design`) from the information of the steps measured, aiming below the
target by as much as the report's std is now wider than the information's
(:func:`calibration`), and spending at most as much stand time as all the steps before.
Steps across each resonance the residual shows where the model has none
(:func:`unexpected_steps`) and one where each rival minimum's AFC differs most from the
estimate's (:func:`telling_apart`) come first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibid.acquisition.plan import record_samples
from vibid.acquisition.stand_config import StandConfig
from vibid.planner.adaptive.fit import CurrentFit
from vibid.planner.adaptive.options import AdaptiveOptions
from vibid.planner.prior import prior_std

__all__ = ["Batch", "next_batch"]

#: posterior draws the next batch is chosen over (the estimate and 8 Sobol normal draws)
N_DRAWS = 9
#: where a resonance the model lacks is measured: phases across its half-power band, deg
UNEXPECTED_PHASES_DEG = (-60.0, -30.0, 0.0, 30.0, 60.0)


@dataclass(frozen=True)
class Batch:
    """Steps to play, in ascending frequency: Hz, settle s, minimum record s."""

    frequency_hz: np.ndarray
    settle_s: np.ndarray
    record_s: np.ndarray
    #: the predicted drop of log(worst targeted std / target) at the estimate
    predicted_gain: float = math.nan

    def __len__(self) -> int:
        return int(self.frequency_hz.size)

    @property
    def stand_time_s(self) -> float:
        return float(np.sum(self.settle_s) + np.sum(self.record_s))


def posterior_draws(result, box: dict, n: int, seed: int) -> np.ndarray:
    """(n, p): the estimate, then normal draws of the fit's covariance (Sobol), in the box."""
    from scipy.stats import norm, qmc

    theta = np.asarray(result.values, float)
    names = list(result.parameter_names)
    cov = np.asarray(result.covariance, float)
    if not np.all(np.isfinite(cov)):
        cov = np.diag(np.nan_to_num(np.asarray(result.std, float), nan=0.0) ** 2)
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    root = v * np.sqrt(np.clip(w, 0.0, None))
    u = np.clip(
        qmc.Sobol(len(names), scramble=True, seed=seed).random(max(n - 1, 1)), 1e-6, 1 - 1e-6
    )
    draws = np.vstack([theta, theta + norm.ppf(u) @ root.T])[:n]
    lo = np.array([box[k][0] for k in names], float)
    hi = np.array([box[k][1] for k in names], float)
    span = hi - lo
    return np.clip(draws, lo + 1e-6 * span, hi - 1e-6 * span)


def next_batch(
    setup,
    config: StandConfig,
    fit: CurrentFit,
    options: AdaptiveOptions,
    measured_hz,
    measured_record_s,
    *,
    spent_s: float,
    floor_s: float,
    seed: int = 0,
) -> Batch:
    """The next steps (module doc, 4): at most ``options.batch_size``, within the stand
    time left under the cap and no more than all the steps before took (so that a batch the
    information overrates wastes at most as much as was spent)."""
    from vibid.planner.design import greedy
    from vibid.planner.information import fisher, information

    r = fit.result
    names = tuple(r.parameter_names)
    box = r.plate_model.default_bounds(dict(setup.identification.bounds))
    draws, n_rivals = design_draws(r, box, seed)
    forced = unexpected_steps(fit, measured_hz)
    measured_hz = np.asarray(measured_hz, float)
    info = information(
        setup,
        names,
        draws,
        options.band_hz,
        noise=fit.noise,
        extra_hz=measured_hz,
        plate=r.plate_model,
        bounds=box,
        more_hz=forced,
    )
    n_cand = info.frequency_hz.size - measured_hz.size
    measured = (n_cand + np.arange(measured_hz.size), np.asarray(measured_record_s, float))
    targeted = [names.index(t.name) for t in options.targets]
    t_std = np.array([[t.std_of(d[j]) for t, j in zip(options.targets, targeted)] for d in draws])
    # the report's std is the Fisher one widened (a Birge ratio, the model's error): aim
    # lower by the factor it is wider now, so that the batch reaches the target by the
    # report's measure. Rival minima widen it too, but steps that tell them apart remove
    # that, not more precision at the estimate: those steps come first, and no factor.
    if not n_rivals:
        t_std = t_std * calibration(info, measured, r, targeted)
    fs = setup.daq.sample_rate_hz
    shortest = np.array(
        [record_samples(f, fs, config.timing) / fs for f in info.frequency_hz[:n_cand]]
    )
    weak = np.diag(1.0 / prior_std(names, box, {}, draws[0]) ** 2)  # the box: keeps A invertible
    A0 = weak[None] + fisher(info, *measured).sum(axis=1)
    start = np.searchsorted(info.frequency_hz[:n_cand], np.round(forced, 6)).clip(0, n_cand - 1)
    start = np.unique(
        np.concatenate([start, telling_apart(info, n_cand, n_rivals, shortest, floor_s)])
    ).astype(int)
    steps = greedy(
        info,
        np.arange(n_cand),
        shortest,
        t_std,
        targeted,
        A0,
        floor_s=floor_s,
        cap_s=config.timing.max_settle_s,
        quantile=0.5,
        settle_quantile=0.9,
        max_stand_time_s=max(min(options.max_stand_time_s - spent_s, spent_s), 0.0),
        start=start,
        max_steps=max(options.batch_size, start.size),
        measured=measured,
    )
    gain = predicted_gain(info, measured, (steps.index, steps.record_s), targeted, t_std[0])
    return Batch(info.frequency_hz[steps.index], steps.settle_s, steps.record_s, gain)


def design_draws(result, box: dict, seed: int) -> tuple[np.ndarray, int]:
    """The draws a batch is chosen over: the estimate, the other minima the fit could not
    tell from it (their number is returned too), then draws of its covariance."""
    draws = posterior_draws(result, box, N_DRAWS, seed)
    rivals = np.array(list(result.rivals), float).reshape(-1, draws.shape[1])
    return np.vstack([draws[:1], rivals, draws[1:]]), len(rivals)


def unexpected_steps(fit: CurrentFit, measured_hz) -> np.ndarray:
    """Frequencies across each resonance the residual shows where the model has none, evenly
    in its phase, unless steps lie across its half-power band already."""
    from vibid.planner.information import across_mode

    todo = [(f, q) for f, q in fit.unexpected if not _covered(f, q, measured_hz)]
    if not todo:
        return np.zeros(0)
    f, q = np.array(todo, float).T
    return across_mode(f, 1.0 / q, UNEXPECTED_PHASES_DEG).ravel()


def predicted_gain(info, measured, new, targeted, t_std) -> float:
    """How much the new steps lower ``log`` of the worst targeted std over its target
    ``t_std`` at the estimate (draw 0), by the information."""
    from vibid.planner.design import data_std

    def worst(index, record):
        return float(
            np.max(
                data_std(info, np.asarray(index, int), np.asarray(record, float))[0, targeted]
                / t_std
            )
        )

    before = worst(*measured)
    after = worst(np.concatenate([measured[0], new[0]]), np.concatenate([measured[1], new[1]]))
    return math.log(before / after) if np.isfinite(before) and np.isfinite(after) else math.nan


def telling_apart(info, n_cand: int, n_rivals: int, record_s, floor_s: float) -> np.ndarray:
    """For each rival minimum (draws 1..``n_rivals`` of ``info``; draw 0 the estimate), the
    candidate where the two AFCs differ most against the step's noise and model error, per
    second of its stand time (its shortest record and the settle floor)."""
    out = []
    T = np.asarray(record_s, float)
    for i in range(1, n_rivals + 1):
        diff = np.abs(info.H[i, :n_cand] - info.H[0, :n_cand]) ** 2
        var = info.s_1s[0, :n_cand] ** 2 / T + info.e[0, :n_cand] ** 2
        out.append(int(np.argmax(diff / var / (T + floor_s))))
    return np.asarray(out, int)


def calibration(info, measured, result, targeted) -> np.ndarray:
    """Per targeted parameter, the information's standard uncertainty of the steps measured
    (at the estimate) over the one the fit reports: 1 where they agree, below where the
    report's is wider."""
    from vibid.planner.design import data_std

    predicted = data_std(info, measured[0].astype(int), measured[1])[0, targeted]
    reported = np.asarray(result.std, float)[targeted]
    with np.errstate(divide="ignore", invalid="ignore"):
        k = predicted / reported
    return np.where(np.isfinite(k), np.clip(k, 1e-3, 1.0), 1.0)


def _covered(f_hz: float, q: float, measured_hz) -> bool:
    """Whether steps lie across this resonance's half-power band already (three or more)."""
    m = np.asarray(measured_hz, float)
    return int(np.count_nonzero(np.abs(m - f_hz) <= f_hz / q)) >= 3
