"""Refit a candidate's extended model from the current fit.

Local fits from the current estimate, with several starts along the new parameters (a
parameter the diagnosis placed, a resonance's frequency and Q, is not varied), then the full
identification (covariance) from the best, under the current fit's weights where the model's
own error barely changes them
(:attr:`~vibid.identify.loop.policy.Policy.model_error_share`). The starts are exploratory:
each stops once its remaining Newton step is a twentieth of a standard deviation (scaled by
the misfit), on a long AFC each runs on the compressed problem the previous one ended on
(its end confirmed on every point), and a start that moves a stiffness gets its own basis.
Where the current estimate lies outside its prior box (the declared model bent a parameter
to mimic what it lacks) the starts also move those parameters just inside the box and to its
centre; where the diagnosis reads a pole as a mode the model hides and the candidate can
show it (a sensor off its node line), they also start from the material moved to place that
mode on the pole. With ``search`` (a new material: the loop's rounds decide), the extended
model is first searched globally over its box (the current estimate may lie in a wrong basin
of it: an orthotropic plate fitted as isotropic): on the resonance peaks, then on chi2
unless the best's modes already lie on the measured peaks or it fits the noise; such a
search settles the refit, and only where it does not are the local fits run and the better
of the two kept (a local refit beside a search that found the basin cost an orthotropic
plate 8 s for a chi2 a million times the search's).

Where the polished refit takes a parameter the current fit has inside its prior box
outside it, and the misfit's own error cannot tell that excursion from what a parameter
that explains nothing gains, the refit is run again with that parameter held at its
current value (:func:`~vibid.identify.loop.held.held_inside`; the report's note says so):
Poisson's ratio of a strip wanders to a face of its box with every new effect, and the
effect is judged on what it explains, not on where the ratio wandered.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np

from vibid.identify.engine.profile import timed
from vibid.identify.fit.compress import TOL_STD
from vibid.identify.fit.local import run_local
from vibid.identify.fit.minima import best_inside_prior
from vibid.identify.fit.noise import fits_noise
from vibid.identify.fit.result import IdentificationResult
from vibid.identify.fit.strategy import (
    Measurement,
    ModelChoice,
    SearchOptions,
    gives_modes,
    identify,
    peaks_already_matched,
)
from vibid.identify.loop.held import Held, held_inside
from vibid.identify.loop.policy import DEFAULT, Policy
from vibid.identify.loop.scoring import extended_problem

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Refit:
    """A refitted candidate: its result, its likelihood ratio ``gain`` = Δχ² under the
    current fit's weights, and whether it was searched globally. A local refit's result is
    polished under the current fit's weights (``polish``: what :func:`weighed` needs to
    polish it under its own model's error; None where it already was)."""

    result: IdentificationResult
    gain: float
    searched: bool
    polish: tuple | None = None  # (forward model, prior box, transforms by name)
    held: Held | None = None  # parameters held inside their prior box (held_inside)


def weighed(plate, data, fit: Refit, local: str) -> IdentificationResult:
    """``fit``'s result weighed with its own model's error and polished once more (the
    full identification), for the refit the loop adds; ``fit.result`` itself where it
    already weighed its own (:attr:`Policy.model_error_share`). Its rivals were judged under the
    current fit's weights, whose model error is the current model's (on a real strip's AFC
    the weights lie at most 5.2 % above the data's std)."""
    if fit.polish is None:
        return fit.result
    fm, box, kinds = fit.polish
    return polish(
        plate, data, fm.refresh(fit.result.values), fit.result.parameters, box, kinds, local
    )


def polish(plate, data, fm, start: dict, box, kinds, local: str, weights=None):
    """The full identification from ``start`` on the forward model ``fm`` (one local
    run, the covariance), under ``weights`` or, None, the data's and the model's error."""
    return identify(
        plate.setup,
        Measurement.of(data, weights=weights),
        ModelChoice(name=fm.param.model, forward_model=fm, bounds=box, kinds=kinds),
        SearchOptions(method="local", local=local, start=start),
    )


def starts(
    space, u0, new, current_names, placed=None, policy: Policy = DEFAULT
) -> list[np.ndarray]:
    """The current estimate, and it with the new parameters at :attr:`Policy.starts_u`; where
    current parameters lie outside their prior box, also those moved just inside it and to
    its centre (a physical value, far from the bent one), the new parameters at their
    null there, and the new parameters' spread taken from the centred estimate instead of
    the bent one: the bent parameter mimicked the effect, and the two must move together
    (a sensor 3 mm off the strip's centre line excites a torsion mode that the centred
    model places by bending nu to -0.17; spread from the bent estimate the refit stopped
    at 1.3 mm, chi2_red 960, from the centred one it found 2.98 mm, chi2_red 0.88; the
    real strip's loop's 253 runs took 51 s instead of 39 s, the same stages). With ``placed``
    (:func:`on_hidden_mode`: the material moved so that a mode the current model hides
    lies on the diagnosed pole), that too, and the spread from it."""
    out = set(space.out_of_bounds(space.theta(u0))) & set(current_names)
    outside = [i for i, n in enumerate(space.names) if n in out]
    bases = [u0]
    if outside:
        moved, centred = u0.copy(), u0.copy()
        moved[outside] = np.clip(moved[outside], -policy.inside_u, policy.inside_u)
        centred[outside] = 0.0
        bases += [moved, centred]
    if placed is not None:
        bases.append(placed)
    spread = bases[-1]  # the new parameters spread from the centred or placed estimate
    found = [u0]
    for v in policy.starts_u if new else ():
        u = spread.copy()
        u[new] = v
        found.append(u)
    return found + bases[1:]


@timed("loop refits")
def refit(
    plate,
    data,
    res,
    cand,
    box,
    diagnosis,
    local: str,
    search: bool = False,
    extended=None,
    policy: Policy = DEFAULT,
) -> Refit:
    """Refit ``cand``'s extended model from ``res`` (module doc) on the declared ``plate``
    (:class:`~vibid.identify.model.plate.Plate`); ``extended``:
    :func:`~vibid.identify.loop.scoring.extended_problem`'s, where the scoring built it."""
    problem, start, ext_box = extended or extended_problem(plate, data, res, cand, box, diagnosis)
    searched = _search(plate, data, cand, problem, start, ext_box, local) if search else None
    polish = held = None
    if searched is not None and searched.settled:
        result, loss = searched.result, searched.loss
    else:
        result, loss, polish, held = _local(
            plate, data, res, cand, problem, start, ext_box, diagnosis, local, policy
        )
        if searched is not None and searched.result.converged and searched.loss < loss:
            result, loss, polish, held = searched.result, searched.loss, None, None
    log.info("loop: %s refitted, chi2 %.6g -> %.6g", cand.name, res.chi2, loss)
    return Refit(result, float(res.chi2 - loss), search, polish, held)


def _local(
    plate, data, res, cand, problem, start, ext_box, diagnosis, local: str, policy: Policy = DEFAULT
):
    """``(result, chi2 under the current weights, polish, held)``: local fits from the
    current estimate (:func:`starts`), the best polished by the full identification, under
    the current weights where the model's own error does not weigh in
    (:attr:`Policy.model_error_share`; ``polish``: :attr:`Refit.polish`, None where it weighed
    its own); where the polished refit leaves a parameter's prior box, the refit with it
    held inside if the misfit cannot tell the two apart (``held``:
    :func:`~vibid.identify.loop.held.held_inside`, else None)."""
    space = problem.space
    names = space.names
    with np.errstate(divide="ignore"):  # a null on a log parameter's edge: u = -inf
        u0 = space.to_u(np.array([start[n] for n in names]))
    placed = cand.placed(res.parameters)
    new = [i for i, n in enumerate(names) if n not in res.parameter_names and n not in placed]
    u0 = np.clip(u0, -5, 5)
    around = _on_own_basis(problem, space.theta(u0))
    placed = on_hidden_mode(plate, res, cand, diagnosis, space, u0, data)
    # each start on the last one's nodes, stopped where its remaining Newton step is under
    # TOL_STD of a standard deviation scaled by the misfit: the best is polished below
    scale = max(1.0, float(res.chi2_reduced))
    runs, near = [], None
    for u in starts(space, u0, new, res.parameter_names, placed, policy):
        r, near = run_local(local, around(u), u, near, tol=TOL_STD**2 * scale)
        runs.append(r)
    runs.sort(key=lambda r: r.loss if np.isfinite(r.loss) else np.inf)
    inside = best_inside_prior(runs, space, scale)
    best = inside if inside is not None else runs[0]
    kinds = cand.held(res.parameters, diagnosis)
    weights = None if model_error_weighs_in(res, policy.model_error_share) else problem.sigma

    def polished(run, kinds):
        # a basis built where the run ended (no a-posteriori check first: on a real
        # strip one costs four complex sparse LUs, 0.14 s, a basis 0.08 s, and the
        # polish's own end is checked all the same)
        fm = problem.model.rebuilt(run.theta)
        return fm, polish(
            plate, data, fm, dict(zip(names, run.theta)), ext_box, kinds, local, weights
        )

    fm, result = polished(best, kinds)
    held = held_inside(res, space, u0, space.to_u(result.values), around, local)
    if held is not None:
        best, kinds = held.run, kinds | held.kinds(space)
        fm, result = polished(best, kinds)
    return result, best.loss, (None if weights is None else (fm, ext_box, kinds)), held


def on_hidden_mode(plate, res, cand, diagnosis, space, u0, data):
    """``u0`` with the current material moved so that the mode of the model its sensor
    does not see lies on the diagnosed pole beside it, the modes it sees (in the data's
    band) where they are, for a candidate that shows hidden modes (a sensor off its
    declared node line); None where there is no such pole or no material places it.

    The declared model bends its material to place the modes it sees and leaves the
    hidden one where that puts it (a strip with its sensor 3 mm off the centre line:
    nu -0.17, its torsion at 1046 Hz against the data's 948 Hz); a refit spread from the
    bent material cannot reach the basin where the sensor's offset shows the torsion, and
    the estimate lies inside its prior box, so no centred start is made either."""
    from scipy.optimize import least_squares

    from vibid.identify.model.modal import seen

    poles = [f for f in getattr(diagnosis, "features", ()) if "hidden_mode" in f.kinds]
    if "hidden_mode" not in cand.explains or not poles:
        return None
    pole = max(poles, key=lambda f: f.significance)
    params, n = dict(res.parameters), 12
    f0, height = plate.mode_heights(params, n)
    k = int(np.argmin(np.abs(np.log(f0 / pole.hidden_mode_hz))))
    f_used = np.asarray(data.frequency_hz)[np.asarray(data.used)]
    shown = np.flatnonzero(seen(height) & (f0 >= f_used.min()) & (f0 <= f_used.max()))
    target = np.log(np.append(f0[shown], pole.f_hz))
    moving = [space.names.index(m) for m in res.plate_model.material.stiffness_names]

    def theta_at(x):
        u = u0.copy()
        u[moving] = x
        return u, dict(zip(space.names, space.theta(u)))

    def misfit(x):
        f, _ = plate.mode_heights({**params, **theta_at(x)[1]}, n)
        return np.log(np.append(f[shown], f[k])) - target

    try:
        fit = least_squares(
            misfit,
            np.clip(u0[moving], -0.99, 0.99),
            bounds=(-1.0, 1.0),
            x_scale=0.1,
            max_nfev=20 * (len(moving) + 1),
        )
    except Exception as exc:  # noqa: BLE001 - no placed start, the others remain
        log.info("loop: %s: the hidden mode could not be placed: %s", cand.name, exc)
        return None
    u, theta = theta_at(fit.x)
    f, height = plate.mode_heights({**params, **theta}, n)
    if seen(height)[k] or abs(np.log(f[k] / pole.f_hz)) > 0.02:
        return None  # the modes crossed, or the material cannot place it
    log.info(
        "loop: %s: the model's hidden mode at %.4g Hz placed on the pole at %.4g Hz (%s)",
        cand.name,
        f0[k],
        pole.f_hz,
        ", ".join(f"{m} {theta[m]:.4g}" for m in res.plate_model.material.stiffness_names),
    )
    return u


def model_error_weighs_in(res, share: float = DEFAULT.model_error_share) -> bool:
    """Whether the model's own error changes ``res``'s chi2 by ``share``
    or more (its chi2 under the data's weights alone against the one under its weights)."""
    return not (res.chi2_reduced_data_weights <= (1 + share) * res.chi2_reduced)


def _on_own_basis(problem, theta0):
    """``u -> problem`` on its model rebuilt at ``u``, one basis per value of the parameters
    that move a stiffness or inertia (found at ``theta0``): a basis is built from those
    alone, so starts that differ only in a gain, a delay or a loss share their model (on
    a real strip's AFC, 163 bases and checks for 236 runs). A start that moves one of them
    gets its own basis without the a-posteriori check, which on the beam failed at 95 of
    96 starts and cost what the basis costs (the best run's end is refreshed and checked)."""
    from vibid.identify.model.reduced import moving_parameters

    space, models = problem.space, {}
    moving = moving_parameters(problem.model.param, theta0)

    def at(u):
        theta = space.theta(u)
        key = tuple(theta[moving])
        if key not in models:
            models[key] = problem.model.rebuilt(theta)
        return problem.with_model(models[key])

    return at


def _fits(r) -> bool:
    """Whether a refit fits the data's noise, with the data's own weights: a refit that did
    not converge fits nothing, and a model that is far from the data has a large error of
    its own, which in the weights would swamp the misfit (an orthotropic plate's local
    refit from an isotropic fit, its basis stretched, "fitted" that way)."""
    return r.converged and bool(fits_noise(r.chi2_reduced_reported * r.dof, r.dof, True))


@dataclass(frozen=True)
class Searched:
    """A candidate's global search: its best result, that result's chi2 under the current
    fit's weights, and whether it settles the refit (its modes on the measured peaks, or
    a fit to the noise): then no local refit is run beside it."""

    result: IdentificationResult
    loss: float
    settled: bool


def _search(plate, data, cand, problem, start, ext_box, local) -> Searched | None:
    """The extended model searched over its whole box: on the resonance peaks first for a
    candidate that moves every resonance its own way, then on chi2 unless the best's modes
    already lie on the measured peaks (its misfit is not a wrong basin) or it fits the
    noise. None when no search converged."""
    space, param = problem.space, problem.model.param
    log.info("loop: %s searched over its box", cand.name)
    wide = plate.forward_model(data.frequency_hz[data.used], model=param, bounds=ext_box)
    peaks = cand.peaks_first and gives_modes(wide)
    best = None
    for peaks_only in ([start] if peaks else []) + [None]:
        found = identify(
            plate.setup,
            Measurement.of(data),
            ModelChoice(name=param.model, forward_model=wide, bounds=ext_box),
            SearchOptions(local=local, restarts=3, seed=0, peaks_only=peaks_only),
        )
        at = problem.with_model(problem.model.refresh(found.values))
        loss = at.chi2(space.to_u(found.values))
        log.info(
            "loop: %s searched globally%s, chi2 %.6g",
            cand.name,
            " on its peaks" if peaks_only else "",
            loss,
        )
        if found.converged and (best is None or loss < best.loss):
            best = Searched(found, loss, False)
        if best is not None and _fits(best.result):
            return replace(best, settled=True)
        if (
            peaks_only is not None
            and best is not None
            and best.result is found
            and peaks_already_matched(at, found.values, by_grid=True)
        ):  # its modes on the measured peaks to the grid's resolution: chi2's search
            # would find this basin again (identify's own rule)
            log.info(
                "loop: %s's modes lie on the measured peaks: no search on chi2 (its "
                "misfit is not a wrong basin)",
                cand.name,
            )
            return replace(best, settled=True)
    return best
