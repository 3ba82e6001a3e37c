"""The test planner: the stepped sine that reaches target uncertainties in the least stand time.

``plan_test`` asks the plate model where the AFC holds information about the named
parameters over the whole prior (:mod:`.information`: Fisher information per second of
record, per prior draw), chooses steps greedily by expected information per second of stand
time (:mod:`.design`), and gives each a settle time from the predicted Q of the modes around
it (:mod:`.settle`) and a record length. :func:`planned_setup` writes the plan as a setup
(``excitation.settle_s`` and ``excitation.record_s`` as lists, session-format.md) that
``vibid campaign`` plays as it is. The prediction is the identification's own estimator
(the same Jacobian and noise weighting) at each draw; it leaves out model error, the drive
control's and the unsettled steps' re-records, so the campaign's stand time is a little
longer than predicted.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from vibid.acquisition.plan import plan_summary, record_samples
from vibid.acquisition.stand_config import StandConfig
from vibid.errors import VibidError
from vibid.planner.design import Steps, data_std, greedy, met, sequence_settle
from vibid.planner.information import information
from vibid.planner.prior import (
    Target,
    check_stand_time_cap,
    parse_prior,
    parse_targets,
    prior_draws,
    prior_std,
)

__all__ = ["Plan", "Prediction", "parse_prior", "parse_targets", "plan_test", "planned_setup"]


@dataclass(frozen=True)
class Prediction:
    """A test's stand time and the standard uncertainty it gives at each prior draw."""

    label: str
    n_steps: int
    stand_time_s: float
    std: np.ndarray  #: (draws, p)
    draws: np.ndarray  #: (draws, p)

    def relative_std(self, j: int) -> np.ndarray:
        return self.std[:, j] / np.abs(self.draws[:, j])


@dataclass(frozen=True)
class Plan:
    names: tuple[str, ...]
    targets: tuple[Target, ...]
    frequencies_hz: np.ndarray
    settle_s: np.ndarray
    record_s: np.ndarray
    planned: Prediction
    sweep: Prediction | None  #: the setup's own stepped sine, for comparison
    quantile: float
    reached: bool  #: the targets are met in ``quantile`` of held-out draws
    reached_design: bool = True  #: ... of the draws the design was chosen on


@dataclass(frozen=True)
class _Problem:
    """What every prediction of a plan shares: the setup, its model's parameter names and
    their box, the priors, the band (Hz), the noise, whether only |H| is fitted, and the
    frequencies of the setup's own sweep (Hz, none without an excitation)."""

    setup: Any
    names: tuple[str, ...]
    box: dict
    priors: dict
    band_hz: tuple[float, float]
    noise: float
    magnitude: bool
    sweep_hz: np.ndarray

    @classmethod
    def of(cls, setup, priors: dict, band_hz, noise: float, magnitude: bool) -> _Problem:
        """The problem of ``setup``; ``band_hz`` default the span of its sweep, an error
        unless 0 < low < high < Nyquist."""
        from vibid.identify.model.plate import plate_model

        model = plate_model(setup.identification.model)
        box = model.default_bounds(dict(setup.identification.bounds))
        exc = setup.excitation
        sweep_f = np.asarray(exc.frequencies_hz if exc is not None else (), float)
        if band_hz is None:
            if not sweep_f.size:
                raise VibidError("the setup has no excitation: give the band (--band LOW:HIGH)")
            band_hz = (float(sweep_f.min()), float(sweep_f.max()))
        lo, hi = band_hz
        fs = setup.daq.sample_rate_hz
        if not 0 < lo < hi < fs / 2:
            raise VibidError(
                f"--band {lo:g}:{hi:g}: needs 0 < low < high < {fs / 2:g} Hz (Nyquist)"
            )
        return cls(setup, tuple(model.names), box, priors, band_hz, noise, magnitude, sweep_f)

    def draws(self, n: int, seed: int) -> np.ndarray:
        """(n, p) draws of the prior."""
        return prior_draws(self.names, self.box, self.priors, n, seed)

    def information(self, draws: np.ndarray, extra_hz, **kw):
        """The :func:`~vibid.planner.information.information` at ``draws``."""
        return information(
            self.setup,
            self.names,
            draws,
            self.band_hz,
            noise=self.noise,
            extra_hz=extra_hz,
            magnitude=self.magnitude,
            **kw,
        )

    def prior_information(self, draws: np.ndarray) -> np.ndarray:
        """(draws, p, p) the prior's information, the same at every draw: its std at the
        draws' mean, diagonal."""
        P = np.diag(1.0 / prior_std(self.names, self.box, self.priors, draws.mean(axis=0)) ** 2)
        return np.broadcast_to(P, (len(draws),) + P.shape).copy()


def plan_test(
    setup,
    config: StandConfig,
    targets,
    *,
    priors=None,
    band_hz=None,
    noise: float | None = None,
    n_draws: int = 16,
    seed: int = 0,
    quantile: float = 0.9,
    settle_quantile: float = 0.5,
    max_stand_time_s: float = 3600.0,
    min_settle_s: float = 0.1,
    coarse_steps: int = 8,
    magnitude: bool = False,
    n_check: int = 64,
) -> Plan:
    """Plan the stepped sine of ``setup`` on the stand ``config`` (timing; ``noise``
    defaults to ``config.simulated.noise``, each channel's noise relative to the base
    amplitude). ``targets``/``priors``: parsed (:func:`parse_targets`, :func:`parse_prior`).
    ``band_hz``: (low, high), default the setup's frequency span. The plan starts from
    ``coarse_steps`` steps spread geometrically over the band (the identification's global
    search finds the resonances on them), then adds the steps of most information per
    second until the targets are met in ``quantile`` of ``n_draws`` prior draws. Each step
    settles as long as the ``settle_quantile`` of the draws needs (a step that is still ringing
    is recorded again by the campaign: the unsettled-record rule of
    :mod:`vibid.acquisition.plan`). The uncertainties it predicts, the plan's and the setup's
    sweep's, are those at ``n_check`` other draws of the prior (held out: a design fitted to
    its own draws flatters itself)."""
    check_stand_time_cap(max_stand_time_s)
    noise = config.simulated.noise if noise is None else noise
    problem = _Problem.of(setup, priors or {}, band_hz, noise, magnitude)
    names, sweep_f = problem.names, problem.sweep_hz
    draws = problem.draws(n_draws, seed)
    info = problem.information(draws, sweep_f)
    n_cand = info.frequency_hz.size - sweep_f.size
    targeted = [names.index(t.name) for t in targets]
    t_std = _targets_std(targets, targeted, draws)
    steps: Steps = greedy(
        info,
        np.arange(n_cand),
        _shortest_records(info.frequency_hz[:n_cand], setup.daq.sample_rate_hz, config),
        t_std,
        targeted,
        problem.prior_information(draws),
        floor_s=min_settle_s,
        cap_s=config.timing.max_settle_s,
        quantile=quantile,
        settle_quantile=settle_quantile,
        max_stand_time_s=max_stand_time_s,
        start=_coarse_start(info.frequency_hz[:n_cand], problem.band_hz, coarse_steps),
    )
    # judged on draws the design did not see: a design fitted to its own few draws puts a
    # step on each draw's resonance and promises, at those draws, what it cannot keep at a
    # specimen between them (the truth): the prediction printed is the held-out one
    fresh = problem.draws(n_check, seed + 1)
    plan_f = info.frequency_hz[steps.index]
    check = problem.information(fresh, np.concatenate([plan_f, sweep_f]), grid=False)
    planned_std = data_std(check, np.arange(plan_f.size), steps.record_s)
    planned = Prediction("plan", len(steps.index), steps.stand_time_s, planned_std, fresh)
    sweep = (
        _sweep_prediction(setup, config, info, check, plan_f.size, fresh, settle_quantile)
        if sweep_f.size
        else None
    )
    t_fresh = _targets_std(targets, targeted, fresh)
    return Plan(
        names,
        tuple(targets),
        plan_f,
        steps.settle_s,
        steps.record_s,
        planned,
        sweep,
        quantile,
        met(planned_std, t_fresh, targeted, quantile) <= 1.0,
        met(data_std(info, steps.index, steps.record_s), t_std, targeted, quantile) <= 1.0,
    )


def _targets_std(targets, targeted, draws: np.ndarray) -> np.ndarray:
    """(draws, targets) the standard uncertainty each target asks at each draw."""
    return np.array([[t.std_of(d[j]) for t, j in zip(targets, targeted)] for d in draws])


def _shortest_records(frequency_hz, fs: float, config: StandConfig) -> np.ndarray:
    """The stand's shortest record at each frequency, s."""
    return np.array([record_samples(f, fs, config.timing) / fs for f in frequency_hz])


def _coarse_start(frequency_hz, band_hz, coarse_steps: int) -> np.ndarray:
    """The candidates (positions in ``frequency_hz``, ascending) nearest above
    ``coarse_steps`` frequencies spread geometrically over the band: the coarse sweep."""
    lo, hi = band_hz
    coarse = np.searchsorted(frequency_hz, np.geomspace(lo, hi, coarse_steps))
    return np.minimum(coarse, frequency_hz.size - 1)


def _sweep_prediction(
    setup, config: StandConfig, info, check, n_plan: int, fresh, settle_quantile: float
) -> Prediction:
    """The setup's own stepped sine, predicted as the plan is: its stand time with the
    plan's settle rule (the campaign re-records a step that rings), and its std at the
    held-out draws ``fresh`` (``check``: their information, the plan's ``n_plan`` steps
    first, then the sweep's; ``info``: the design draws', the sweep's steps last)."""
    exc = setup.excitation
    n_sweep = len(exc.frequencies_hz)
    idx = info.frequency_hz.size - n_sweep + np.arange(n_sweep)
    rec = np.array([c.record_s for c in plan_summary(setup, config).commands])
    ringing = sequence_settle(
        info, idx, rec, floor_s=0.0, cap_s=config.timing.max_settle_s, quantile=settle_quantile
    )
    settle = np.maximum([exc.settle_at(i) for i in range(n_sweep)], ringing)
    return Prediction(
        "setup's sweep",
        n_sweep,
        float(rec.sum() + settle.sum()),
        data_std(check, n_plan + np.arange(n_sweep), rec),
        fresh,
    )


def planned_setup(setup, plan: Plan):
    """``setup`` with the plan's stepped sine: frequencies, per-step settle and record times."""
    from vibid.setup_model import Excitation

    r = lambda a: tuple(round(float(x), 6) for x in a)  # noqa: E731 - microsecond/µHz: plenty
    return replace(
        setup, excitation=Excitation(r(plan.frequencies_hz), r(plan.settle_s), r(plan.record_s))
    )
