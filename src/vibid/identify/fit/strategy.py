"""Identify the parameters of a plate model from a measured AFC: :func:`identify`.

The strategy is a pipeline of small steps over immutable values, each a list of
:class:`Fit` (a local run and the problem it ran on) in, a list out (paper sections 5-6,
with the changes that make it work from a vague prior):

1. the data are checked and weighted (:mod:`~vibid.identify.fit.problem`); the parameters
   are mapped to coordinates ``u`` in which the prior box is [-1, 1]
   (:mod:`~vibid.identify.fit.space`);
2. :func:`search`: differential evolution over the whole prior box, several restarts
   (:mod:`~vibid.identify.fit.global_search`), on chi2, and the polish of every restart's
   best point, each on a model rebuilt around it, by continuation in the loss factor
   (:mod:`~vibid.identify.fit.local`); if the best of those does not fit the data
   (:func:`vibid.identify.fit.noise.fits`), and the model gives its modes, a second search
   on the match of the measured resonance peaks (:mod:`~vibid.identify.fit.peaks`), which
   finds the basin where chi2's needle-like minima defeat the search (orthotropic plates),
   unless the best's modes already lie on the measured peaks to the grid's resolution
   (then the misfit is not a wrong basin: an effect the model lacks, say);
   or, with ``method="local"``, one local run from the caller's start; or, with
   ``peaks_only`` (the closed loop's search of an orthotropic plate from an isotropic fit),
   :func:`search_peaks_only`: a small search on the peaks alone, the loss factor held;
3. :func:`walk_valley`: local fits from steps along the flattest direction of chi2 at the
   best minimum (:mod:`~vibid.identify.fit.minima`), which find a lower one the search
   missed, or rivals the std must cover; :func:`prefer_inside_prior`: a best minimum
   outside the prior box gives way to the best inside it unless it fits significantly
   better;
4. :func:`polish_on_local_model`: the best polished once more on a model rebuilt around it;
   :func:`weigh_model_error`: the forward model's own error at the estimate is split
   (:mod:`~vibid.identify.model.model_error`): the part no parameter change explains
   enters the weights (and the polish is repeated if that changed them); the part the
   parameters absorb is a bias that enters the covariance as a systematic term;
5. :func:`~vibid.identify.fit.summary.summarise`: the covariance from the Fisher
   information (:mod:`~vibid.identify.fit.uncertainty`), every minimum compared under the
   final weights, and warnings.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

import numpy as np

from vibid.errors import VibidError
from vibid.identify.engine.profile import timed
from vibid.identify.engine.threads import in_order
from vibid.identify.fit.data import FitData, fit_data
from vibid.identify.fit.global_search import differential_evolution, robust_score
from vibid.identify.fit.inputs import Measurement, ModelChoice, Progress, SearchOptions
from vibid.identify.fit.local import LOCAL_METHODS, SMOOTHING_PARAMETER, polish_by_continuation
from vibid.identify.fit.minima import best_inside_prior, distinct, valley_starts
from vibid.identify.fit.noise import fits
from vibid.identify.fit.peaks import grid_heights, measured_peaks, peak_score, peaks_matched
from vibid.identify.fit.problem import (
    GivesModes,
    LeastSquaresProblem,
    PlateForwardModel,
    SplitsModelError,
)
from vibid.identify.fit.result import (
    DiscretisationInfo,
    GlobalResult,
    IdentificationResult,
    LocalResult,
)
from vibid.identify.fit.space import ParameterSpace, box_covers
from vibid.identify.fit.summary import summarise
from vibid.identify.model.model_error import ModelErrorSplit, split_model_error

log = logging.getLogger(__name__)

#: Weight of ln chi2 in the peak-matching score: a change of chi2 by a factor e counts as
#: much as a 0.3 % mismatch of one peak frequency.
PEAK_CHI2_WEIGHT = 1e-5
#: A change of the weights by more than this (relative) calls for one more polish.
REWEIGH_TOL = 1e-3


@dataclass(frozen=True)
class Fit:
    """One local run and the problem (model, data, weights) it ran on."""

    run: LocalResult
    problem: LeastSquaresProblem

    @property
    def loss(self) -> float:
        return self.run.loss


def _by_loss(fits_: list[Fit]) -> list[Fit]:
    return sorted(fits_, key=lambda f: (not np.isfinite(f.loss), f.loss))


@dataclass(frozen=True)
class Options:
    """How to identify: the local method, global-search restarts and seed, refreshes, and
    whether the global search is on the resonance peaks alone."""

    local: str = "newton"
    restarts: int = 5
    refresh: bool = True
    rng: np.random.Generator | None = None
    progress: Progress | None = None
    #: values (by name) of the parameters the resonance peaks do not fix, for a search on
    #: the peaks alone instead of chi2 (:func:`search_peaks_only`); None: chi2's search
    peaks_only: dict | None = None


# -- the steps ------------------------------------------------------------------------------
def polish(
    problem: LeastSquaresProblem, starts, opts: Options, *, continuation: bool = True
) -> list[Fit]:
    """Local fits from each start, each on a model rebuilt around its start (the search's
    model only has to find basins; models of one shape share their compiled functions).
    The starts are independent: the next one's runs on the second core
    (:mod:`vibid.identify.engine.threads`), the fits come back in the starts' order."""

    def from_start(u0):
        p = refreshed(problem, problem.space.theta(u0)) if opts.refresh else problem
        runs = (
            polish_by_continuation(p, u0, opts.local)
            if continuation
            else [LOCAL_METHODS[opts.local](p, u0)]
        )
        return [Fit(r, p) for r in runs]

    return [fit for fits in in_order(from_start, starts) for fit in fits]


def refreshed(problem: LeastSquaresProblem, theta) -> LeastSquaresProblem:
    """``problem`` on its model rebuilt around ``theta`` (itself if the model stays)."""
    return problem.with_model(problem.model.refresh(theta))


#: The global search looks at no more than about this many points: on a long AFC (an FFT
#: grid of 12 000 bins) it evaluates every resonance region and a thinned rest, and the
#: polish that follows fits every point.
SEARCH_POINTS = 2000


def search_problem(problem: LeastSquaresProblem) -> LeastSquaresProblem:
    """``problem`` on at most about :data:`SEARCH_POINTS` of its points (itself when it has
    no more): the half with the largest ``|H|`` (the resonance regions, where the minima
    are narrow) and every k-th of the others, with their weights, on the same basis."""
    d, n = problem.data, problem.n_points
    if n <= SEARCH_POINTS:
        return problem
    idx = np.flatnonzero(d.used)
    keep = np.zeros(n, bool)
    keep[:: int(np.ceil(2 * n / SEARCH_POINTS))] = True
    mag = np.abs(d.H[idx])
    keep |= mag >= np.sort(mag)[n - SEARCH_POINTS // 2]
    used = np.zeros_like(d.used)
    used[idx[keep]] = True
    thin = FitData(d.frequency_hz, d.H, d.std, used, d.warnings, d.magnitude)
    return LeastSquaresProblem(
        problem.model.on_frequencies(d.frequency_hz[used]), thin, problem.space, problem.sigma[keep]
    )


def search(problem: LeastSquaresProblem, opts: Options):
    """Global search on chi2 (on at most :data:`SEARCH_POINTS` points) and the polish of
    each restart's best on every point, then, if the best does not fit the data and its
    modes are not on the measured peaks (the basin may be wrong, not the model), a search
    on the resonance peaks and, if that does not fit either and the grid is too coarse to
    resolve the resonances (:func:`resolves_resonances`), a search on a robust score
    (:func:`~vibid.identify.fit.global_search.robust_score`: a few precise points at the
    resonances, as an adaptive campaign records, make chi2 a needle). Returns
    (GlobalResult, fits)."""
    global_result = differential_evolution(
        search_problem(problem), restarts=opts.restarts, rng=opts.rng, progress=opts.progress
    )
    found = _by_loss(polish(problem, distinct(global_result.u), opts))
    best = found[0]
    if fits(best.loss, best.problem.dof, best.problem.n_residuals, problem.data.noise_known):
        return global_result, found
    # the chi2 search may have missed the basin (its minima are needles when beta is small
    # and there are several stiffnesses): search on the resonance peaks too, unless the
    # best already puts its modes on the measured peaks (the misfit is something else)
    if peaks_already_matched(problem, best.run.theta):
        log.info("peak matching skipped: the best fit's modes already lie on the measured peaks")
        return global_result, found
    starts = peak_starts(problem, opts)
    if starts and SMOOTHING_PARAMETER in problem.space.names:
        # the peak frequencies say little about the loss factor, which the chi2 search's
        # narrow peaks pin down well: the polish starts from that estimate (starting higher,
        # at 10x, led the orthotropic plate into wrong basins)
        ib = problem.space.names.index(SMOOTHING_PARAMETER)
        for u in starts:
            u[ib] = global_result.u[0][ib]
    found = _by_loss(found + polish(problem, distinct(starts, against=global_result.u), opts))
    best = found[0]
    if fits(best.loss, best.problem.dof, best.problem.n_residuals, problem.data.noise_known):
        return global_result, found
    if resolves_resonances(problem, best.run.theta):
        log.info(
            "robust search skipped: the grid resolves every resonance (chi2 is no needle there)"
        )
        return global_result, found
    thin = search_problem(problem)
    robust = differential_evolution(
        thin,
        restarts=opts.restarts,
        rng=opts.rng,
        progress=opts.progress,
        score=robust_score(thin),
        label="robust search",
    )
    found += polish(problem, distinct(robust.u, against=global_result.u), opts)
    return global_result, _by_loss(found)


def resolves_resonances(problem: LeastSquaresProblem, theta) -> bool:
    """Whether the grid's typical step (the median of ``Δf / f`` between neighbouring used
    frequencies) is under half the narrowest half-power band the model at ``theta`` has
    (``β f``, ``β`` its smallest loss factor): every resonance then spans several points,
    and chi2 is no needle that a few points at the resonances make (the robust search's
    case, an adaptive campaign's 18 steps 30 % apart). An FFT AFC of 0.12 Hz bins (a real
    strip's, β 0.009-0.02) resolves them: the robust search there cost 6 s and found
    nothing the chi2 search had not (BENCHMARKS.md)."""
    f = _grid(problem)
    f = f[f > 0]
    if f.size < 3:
        return False
    param = getattr(problem.model, "param", None)
    if param is None:  # a model without loss factors: no such judgement
        return False
    losses = np.asarray(param.losses(np.asarray(theta, float), np), float)
    losses = losses[np.isfinite(losses) & (losses > 0)]
    if losses.size == 0:
        return False
    return bool(np.median(np.diff(f) / f[1:]) < 0.5 * float(losses.min()))


def _measured_peaks(problem: LeastSquaresProblem):
    data, u = problem.data, problem.data.used
    return measured_peaks(
        data.frequency_hz[u], data.H[u], None if data.std is None else data.std[u]
    )


def gives_modes(model) -> bool:
    """Whether a forward model has real modes to match with resonance peaks (a reduced
    plate model with one loss factor for every modulus)."""
    return isinstance(model, GivesModes) and model.param.proportional


def peaks_already_matched(problem: LeastSquaresProblem, theta, *, by_grid: bool = False) -> bool:
    """Whether the model at ``theta`` has its modes on the measured resonance peaks, to the
    frequency grid's resolution (:func:`vibid.identify.fit.peaks.peaks_matched`; with
    ``by_grid``, a mode the grid would not show need not match: :func:`peak_search`)."""
    model = problem.model
    if not gives_modes(model):
        return False
    thetas = np.asarray(theta)[None, :]
    f_hz, height = model.modes_batch(thetas)
    if by_grid:
        height = _shown(model, thetas, f_hz, height, _grid(problem))
    return peaks_matched(np.asarray(f_hz)[0], np.asarray(height)[0], _measured_peaks(problem))


def _shown(model, thetas, f_hz, height, grid):
    """How high the grid shows each mode (:func:`vibid.identify.fit.peaks.grid_heights`),
    at the proportional model's common loss factor of each parameter vector."""
    beta = [float(model.param.common_loss(np.asarray(t, float), np)) for t in thetas]
    return grid_heights(f_hz, height, beta, grid)


def _grid(problem: LeastSquaresProblem) -> np.ndarray:
    """The measured frequencies the fit uses, ascending."""
    return np.sort(problem.data.frequency_hz[problem.data.used])


def peak_starts(problem: LeastSquaresProblem, opts: Options) -> list[np.ndarray]:
    """Starts from a global search that matches the measured resonance peaks
    (:mod:`vibid.identify.fit.peaks`), with the AFC's chi2 as a tie-breaker; none when the
    model cannot give its modes or the AFC shows no peak."""
    result = peak_search(problem, opts, tie_break=True, agree_rtol=PEAKS_AGREE_RTOL)
    return [] if result is None else list(result.u)


#: The peak search's restarts agree (and the rest are skipped) once three end within this
#: fraction of the best score: they matched the same modes to the same peaks. Peaks fewer
#: than the parameters leave a family of them open, along which restarts end at nearly the
#: same score (a real strip's two peaks: nu 0.28-0.36, scores within 5e-4 of each other);
#: two more restarts cost 3 s, and the five polishes all ended in the valley the first
#: three reach (BENCHMARKS.md).
PEAKS_AGREE_RTOL = 1e-3


#: The peaks-only search's population per searched parameter, generations and restarts
#: (None: the caller's): the small search, one restart (its first lands in an orthotropic
#: strip's basin), then, where it misses, the wide one (a 150 x 100 mm plate's four
#: stiffnesses: each of three small restarts ended short of the basin).
PEAKS_ONLY_SMALL = (8, 40, 1)
PEAKS_ONLY_WIDE = (15, 60, None)


def peak_search(
    problem: LeastSquaresProblem,
    opts: Options,
    *,
    tie_break: bool,
    fixed: dict | None = None,
    popsize: int = 15,
    max_generations: int = 60,
    by_grid: bool = False,
    agree_rtol: float | None = None,
):
    """Differential evolution on the match of the measured resonance peaks (None when the
    model cannot give its modes or the AFC shows no peak). With ``tie_break``, the AFC's
    chi2 decides among parameter sets that match the peaks equally well, through a term too
    small to outweigh a visible mismatch (fewer peaks in the band than stiffness
    parameters leave a family of them); it costs a second evaluation of the population.
    With ``by_grid``, a model mode counts as visible by how high the measured grid would
    show it, not by its resonance peak (:func:`vibid.identify.fit.peaks.grid_heights`: a
    narrow resonance between two steps shows none). The closed loop's search of a new
    material asks for it; the declared fit's search does not yet: with it, the
    orthotropic plate of ``tests/test_identify_orthotropic.py`` ended one restart near
    the truth whose polish fell into the neighbouring minimum (chi2_red 1.95). With
    ``agree_rtol``, the restarts stop once three end at scores that close to the best
    (:func:`~vibid.identify.fit.global_search.differential_evolution`)."""
    model, space = problem.model, problem.space
    if not gives_modes(model):
        return None
    peaks = _measured_peaks(problem)
    if peaks.count == 0:
        return None
    thin = search_problem(problem) if tie_break else None
    grid = _grid(problem) if by_grid else None

    def score(U):
        thetas = space.theta(U)
        if thin is problem:  # one modal decomposition gives the modes and chi2
            f_hz, height, H = model.modes_afc_batch(thetas)
            chi2 = problem.chi2_of_afc(H)
        else:
            f_hz, height = model.modes_batch(thetas)
            chi2 = None if thin is None else thin.chi2_batch(U)
        if by_grid:
            height = _shown(model, thetas, f_hz, height, grid)
        s = np.asarray(peak_score(f_hz, height, peaks))
        if chi2 is not None:
            s = s + PEAK_CHI2_WEIGHT * np.log(np.maximum(chi2, 1e-300))
        return s

    result = differential_evolution(
        problem,
        restarts=opts.restarts,
        rng=opts.rng,
        progress=opts.progress,
        score=score,
        fixed=fixed,
        popsize=popsize,
        max_generations=max_generations,
        label="peak matching",
        agree_rtol=agree_rtol,
    )
    log.info("peak matching: %d measured peaks, best score %.3g", peaks.count, result.loss[0])
    return result


@timed("global search")
def search_peaks_only(problem: LeastSquaresProblem, opts: Options):
    """Search the resonance peaks alone, the parameters that move no stiffness or inertia
    (a delay, a gain, and at first the loss factor: the peak frequencies do not fix them)
    held at ``opts.peaks_only``, polishing each restart's best as it ends; a model mode
    counts as one the data lack only where the grid would show it. A small search first
    (:data:`PEAKS_ONLY_SMALL`); where its polished fit does not put its modes on the
    measured peaks, a wider one (:data:`PEAKS_ONLY_WIDE`) that also searches the loss
    factor, with chi2 to break the ties among parameter sets that match the peaks equally
    (four peaks leave an orthotropic plate's D12 open; with the loss factor held at an
    isotropic fit's, twice the plate's, chi2 would point the wrong way), over the caller's
    restarts, stopping at the first whose polished fit sits on the peaks: the basin is
    found, and the other restarts would cost a search each (12 s on a simulated orthotropic
    plate) to find it again.
    Returns (GlobalResult of the restarts run, fits), or (None, []) when the model cannot
    give its modes or the AFC shows no peak.

    Where a model with several stiffnesses starts far from its basin (an orthotropic plate
    from an isotropic fit) this finds the basin for a fraction of chi2's search, whose
    minima are needles when the loss factor is small. On a coarse grid the peaks do not
    tell neighbouring basins apart (a resonance anywhere between two steps matches): the
    caller judges the fit, and searches chi2 when it does not fit the data."""
    from vibid.identify.model.reduced import moving_parameters

    model, space = problem.model, problem.space
    if not gives_modes(model):
        return None, []
    theta = np.array([float(opts.peaks_only[n]) for n in space.names])
    moving = moving_parameters(model.param, theta)
    single = replace(opts, restarts=1)  # the restarts one at a time, on opts' one rng
    found, results = [], []
    for wide, (popsize, generations, restarts) in (
        (False, PEAKS_ONLY_SMALL),
        (True, PEAKS_ONLY_WIDE),
    ):
        hold = {
            n: theta[i]
            for i, n in enumerate(space.names)
            if i not in moving and not (wide and n == SMOOTHING_PARAMETER)
        }
        for _ in range(restarts or opts.restarts):
            result = peak_search(
                problem,
                single,
                tie_break=wide,
                fixed=hold,
                by_grid=True,
                popsize=popsize,
                max_generations=generations,
            )
            if result is None:
                return None, []
            starts = distinct(list(result.u), against=[u for r in results for u in r.u])
            results.append(result)
            found = _by_loss(found + polish(problem, starts, opts))
            if peaks_already_matched(found[0].problem, found[0].run.theta, by_grid=True):
                return _joined(results), found
        if not wide:
            log.info(
                "peaks-only search: the small search does not end on the peaks; the "
                "wider one follows"
            )
    return _joined(results), found


def _joined(results) -> GlobalResult:
    """The restarts of several searches as one :class:`GlobalResult`, best first."""
    loss = np.concatenate([r.loss for r in results])
    order = np.argsort(loss)
    return GlobalResult(
        np.concatenate([r.u for r in results])[order],
        np.concatenate([r.theta for r in results])[order],
        loss[order],
        sum(r.n_evaluations for r in results),
        tuple(m for r in results for m in r.messages),
    )


def walk_valley(problem: LeastSquaresProblem, found: list[Fit], opts: Options) -> list[Fit]:
    """The neighbouring minima along the valley the data leave open: a lower one (the
    global search missed it) or one about as low (then the std must cover both). Each
    start is polished, like the search's, on a model built around it from ``problem``."""
    best = found[0]
    walk = valley_starts(best.problem, best.run)
    more = polish(problem, walk, opts, continuation=False)
    log.info(
        "valley walk: %d starts, best chi2 %.6g -> %.6g",
        len(walk),
        best.loss,
        min((f.loss for f in more), default=best.loss),
    )
    return _by_loss(found + more)


def prefer_inside_prior(found: list[Fit]) -> list[Fit]:
    """The best minimum inside the prior box first, where the data do not insist on one
    outside it (:func:`vibid.identify.fit.minima.best_inside_prior`)."""
    best = found[0]
    noise_var = 1.0 if best.problem.data.noise_known else best.loss / max(best.problem.dof, 1)
    inside = best_inside_prior([f.run for f in found], best.problem.space, noise_var)
    if inside is None or inside is best.run:
        return found
    log.info("prior box: chi2 %.6g inside it against %.6g outside", inside.loss, best.loss)
    first = next(f for f in found if f.run is inside)
    return [first] + [f for f in found if f is not first]


def polish_on_local_model(found: list[Fit], opts: Options) -> list[Fit]:
    """The best polished once more on a model rebuilt around it (if it moved)."""
    best = found[0]
    problem = refreshed(best.problem, best.run.theta) if opts.refresh else best.problem
    if problem is best.problem:
        return found
    return [Fit(LOCAL_METHODS[opts.local](problem, best.run.u), problem)] + found


def weigh_model_error(found: list[Fit], opts: Options) -> tuple[list[Fit], ModelErrorSplit | None]:
    """Put the model's own error where it belongs (:mod:`vibid.identify.model.model_error`):
    its unexplained part into the weights (then polish again if they changed), the part the
    parameters absorb into a systematic covariance term, taken with the final weights.
    Returns the fits (a new best first if polished again) and the split (None if the model
    estimates no signed error)."""
    best = found[0]
    problem, model = best.problem, best.problem.model

    def again(p: LeastSquaresProblem) -> list[Fit]:
        return [Fit(LOCAL_METHODS[opts.local](p, best.run.u), p)] + found

    if not isinstance(model, SplitsModelError):
        me = problem.on_points(np.asarray(model.model_error(best.run.theta), dtype=float))
        return (again(problem.with_weights(me)) if np.any(me > 0) else found), None
    d, red = model.model_error_parts(best.run.theta)
    d, red = problem.on_points(d), problem.on_points(red)
    if problem.magnitude:  # the error of |H|: the signed error's radial part
        A = problem.on_points(problem.model_afc(best.run.theta))
        d = (np.real(np.conj(A) * d) / np.maximum(np.abs(A), 1e-300)).astype(complex)
    if not (np.any(d != 0) or np.any(red > 0)):
        return found, None
    plain = problem.with_weights()
    split = split_model_error(plain.jacobian_theta(best.run.theta), d, red, plain.sigma)
    weighted = problem.with_weights(split.point_std)
    if np.max(np.abs(weighted.sigma / plain.sigma - 1)) <= REWEIGH_TOL:
        return [Fit(best.run, weighted)] + found[1:], split
    found = again(weighted)
    best = found[0]
    split = split_model_error(weighted.jacobian_theta(best.run.theta), d, red, weighted.sigma)
    return found, split


def on_final_weights(found: list[Fit]) -> list[LocalResult]:
    """Every run with its chi2 under the best's final weights, on its own model (minima
    found under other weights or models are compared under the final ones)."""
    sigma = found[0].problem.sigma
    out = [found[0].run]
    for f in found[1:]:
        same = np.array_equal(f.problem.sigma, sigma)
        out.append(
            f.run if same else replace(f.run, loss=f.problem.with_sigma(sigma).chi2(f.run.u))
        )
    return out


# -- the entry point ----------------------------------------------------------------------
def identify(
    setup,
    measured: Measurement,
    model: ModelChoice = ModelChoice(),
    search: SearchOptions = SearchOptions(),
) -> IdentificationResult:
    """Identify the parameters of a material model from a measured AFC.

    ``setup`` is the declared :class:`~vibid.setup_model.Setup` (specimen, sensor, bounds);
    ``measured`` the AFC and its weighing (:class:`~vibid.identify.fit.inputs.Measurement`),
    ``model`` the model fitted and its prior box
    (:class:`~vibid.identify.fit.inputs.ModelChoice`: by default the setup's), ``search``
    how the minimum is searched (:class:`~vibid.identify.fit.inputs.SearchOptions`: by
    default the global search, five restarts). The steps are the module's: the problem
    (:func:`problem_of`), the minima (:func:`minima`), their polish on a model around the
    best and under its own error (:func:`polished`), the answer
    (:func:`~vibid.identify.fit.summary.summarise`).
    """
    t0 = time.perf_counter()
    name = model.name or setup.identification.model
    _check_methods(search)
    problem, warnings = problem_of(setup, measured, model, name)
    opts = Options(
        search.local,
        search.restarts,
        search.refresh,
        np.random.default_rng(search.seed),
        search.progress,
        None if search.peaks_only is None else dict(search.peaks_only),
    )
    global_result, found = minima(problem, opts, asked=search)
    weighed = problem.data.noise_known and measured.weights is None
    found, split, disc = polished(found, opts, weighed=weighed)
    best = found[0]
    result = summarise(
        best.problem,
        problem.data,
        name,
        best.run,
        tuple(f.run for f in found),
        global_result,
        warnings,
        t0,
        search.throw,
        split,
        on_final_weights(found),
    )
    return result if disc is None else replace(result, discretisation=disc)


def _check_methods(search: SearchOptions) -> None:
    if search.method not in ("global", "local"):
        raise VibidError(
            f"unknown identification method {search.method!r}: use 'global' or 'local'"
        )
    if search.local not in LOCAL_METHODS:
        raise VibidError(
            f"unknown local method {search.local!r}: use one of {', '.join(LOCAL_METHODS)}"
        )


def problem_of(
    setup, measured: Measurement, model: ModelChoice, name: str
) -> tuple[LeastSquaresProblem, list[str]]:
    """The weighted least-squares problem of ``measured`` on the chosen model (built on the
    searched box unless given) over its prior box, and the warnings about the data."""
    data = fit_data(
        measured.frequency_hz, measured.H, measured.std, measured.used, magnitude=measured.magnitude
    )
    box = dict(setup.identification.bounds if model.bounds is None else model.bounds)
    forward_model = model.forward_model
    if forward_model is None:
        from vibid.identify.model.plate import build_forward_model

        forward_model = build_forward_model(
            setup, data.frequency_hz[data.used], model=name, bounds=box
        )
    names = tuple(forward_model.parameter_names)
    _check_point_count(data, len(names), name)
    warnings = list(data.warnings)
    if data.n_used < 3 * len(names):
        warnings.append(
            f"only {data.n_used} usable AFC points for {len(names)} parameters: "
            "the estimate and its uncertainty are fragile"
        )
    if isinstance(forward_model, PlateForwardModel):  # a PlateModel fills derived boxes
        box = forward_model.param.default_bounds(box)
    _check_basis_covers(forward_model, box, names)
    space = ParameterSpace.from_bounds(names, box, model.kinds)
    return LeastSquaresProblem(forward_model, data, space, measured.weights), warnings


def minima(
    problem: LeastSquaresProblem, opts: Options, asked: SearchOptions
) -> tuple[GlobalResult | None, list[Fit]]:
    """The minima found, best first, with the global search that found them (None for
    ``method="local"``: one run from ``asked.start``)."""
    if asked.method != "global":
        run = LOCAL_METHODS[asked.local](problem, _start_u(problem.space, asked.start))
        return None, [Fit(run, problem)]
    global_result, found = None, []
    if opts.peaks_only is not None:
        global_result, found = search_peaks_only(problem, opts)
    if not found:
        global_result, found = search(problem, opts)
    return global_result, prefer_inside_prior(walk_valley(problem, found, opts))


def polished(found: list[Fit], opts: Options, *, weighed: bool):
    """The best polished on a model rebuilt around it and, where ``weighed`` (a known noise,
    no weights given), under the model's own error (:func:`weigh_model_error`). Returns
    (fits, model-error split, discretisation), the last two None where the model's error
    was not weighed."""
    found = polish_on_local_model(found, opts)
    split = disc = None
    if weighed:
        at = found[0]
        found, split = weigh_model_error(found, opts)
        if split is not None:
            disc = discretisation_of(at.problem.model, at.run.theta)
    return found, split, disc


def discretisation_of(model, theta) -> DiscretisationInfo | None:
    """How ``model`` estimated its discretisation error at ``theta`` (the meshes, the
    measured order: :class:`DiscretisationInfo`), from the estimate
    :func:`weigh_model_error` asked for there (the model keeps it: no new solve); None for
    a model without one."""
    estimate = getattr(model, "discretisation_error", None)
    return None if estimate is None else DiscretisationInfo.of(estimate(theta))


def _check_point_count(data: FitData, p: int, model: str) -> None:
    if data.n_residuals <= p:
        raise VibidError(
            f"too few AFC points: {data.n_used} usable point(s) give {data.n_residuals} real "
            f"numbers, fewer than needed to fit the {p} parameters of model {model!r} and "
            "estimate their uncertainty"
        )


def _check_basis_covers(forward_model, box: dict, names) -> None:
    """A wide reduced basis is accurate only over the box it was built for."""
    if not isinstance(forward_model, PlateForwardModel) or forward_model.kind != "wide":
        return
    built = forward_model.bounds
    if not box_covers(built, box, names):
        raise VibidError(
            "the forward model's reduced basis was built for the prior box "
            f"{ {n: tuple(built[n]) for n in names if n in built} }, which does not cover the "
            f"searched box { {n: tuple(box[n]) for n in names} }: build it with the same bounds"
        )


def _start_u(space: ParameterSpace, start) -> np.ndarray:
    if start is None:
        return np.zeros(space.size)
    if isinstance(start, dict):
        missing = [n for n in space.names if n not in start]
        if missing:
            raise VibidError(f"start values missing for {', '.join(missing)}")
        theta = np.array([float(start[n]) for n in space.names])
    else:
        theta = np.asarray(start, dtype=float).ravel()
        if theta.size != space.size:
            raise VibidError(f"start has {theta.size} values for {space.size} parameters")
    if not space.inside_domain(theta):
        raise VibidError(f"start values {space.as_dict(theta)} are outside the physical range")
    return space.to_u(theta)
