"""Identify the parameters of a plate model from a measured AFC: :func:`identify`.

The pipeline (paper sections 5-6, with the changes that make it work from a vague prior):

1. the data are checked and weighted (:mod:`~vibid.identify.loss`); the parameters are
   mapped to coordinates ``u`` in which the prior box is [-1, 1]
   (:mod:`~vibid.identify.params`);
2. global: differential evolution over the whole prior box, several restarts
   (:mod:`~vibid.identify.global_search`), on chi2; if the best of those minima (after
   the polish of step 3) does not fit the data (:func:`_convincing`), and the model gives
   its modes, a second search on the match of the measured resonance peaks
   (:mod:`~vibid.identify.peaks`), which finds the basin where chi2's needle-like minima
   defeat the search (orthotropic plates); or local: a start given by the caller;
3. polish of every restart's best point, each on a model rebuilt around it (not only the
   best: a restart in the right basin may score worse than one in a wrong basin at its
   loose tolerance) by
   continuation in the loss factor: fit the other
   parameters with beta held at a decreasing ladder of values (half a decade apart), and
   from each rung fit all parameters freely, until the free fit's beta lies above the
   rung; the lowest chi2 of all free fits wins. The local method is the paper's
   trust-region Newton with the exact Hessian (or BFGS, or Levenberg-Marquardt); then a
   walk along the flattest direction of chi2 at the best minimum (:func:`_valley_starts`)
   polishes the neighbouring minima of the valley the data leave open, which finds a lower
   one the search missed, or rivals the std must cover; a best minimum outside the prior
   box gives way to the best inside it unless it fits significantly better
   (:func:`_best_inside_prior`);
4. the forward model's own error at the estimate is split
   (:mod:`~vibid.identify.model_error`): the part no parameter change explains enters the
   weights, and the polish is repeated once if that changed them (and once more if the
   model was rebuilt around the estimate); the part the parameters absorb is a bias that
   enters the covariance as a systematic term;
5. the covariance from the Fisher information (:mod:`~vibid.identify.uncertainty`), and
   warnings: points dropped, estimates on their prior bounds, parameters the data cannot
   separate, a fit worse than the noise.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable

import numpy as np

from vibid.errors import VibidError
from vibid.identify.fit_result import IdentificationResult, LocalResult, Status
from vibid.identify.global_search import differential_evolution
from vibid.identify.loss import FitData, ForwardModel, LeastSquaresProblem, fit_data
from vibid.identify.model_error import ModelErrorSplit, split_model_error
from vibid.identify.params import ParameterSpace
from vibid.identify.peaks import measured_peaks, peak_score
from vibid.identify.trust_region import gauss_newton, trust_region
from vibid.identify.uncertainty import fisher_uncertainty

log = logging.getLogger(__name__)

#: Local methods by name.
LOCAL_METHODS: dict[str, Callable[..., LocalResult]] = {
    "newton": lambda problem, u0, max_iter=200: trust_region(problem, u0, hessian="exact",
                                                             max_iter=max_iter),
    "bfgs": lambda problem, u0, max_iter=200: trust_region(problem, u0, hessian="bfgs",
                                                           max_iter=2 * max_iter),
    "lm": lambda problem, u0, max_iter=200: gauss_newton(problem, u0,
                                                         max_evaluations=2 * max_iter),
}
#: Iteration limit of each rung of the continuation (the winner is then run to the end).
RUNG_MAX_ITER = 30

#: The parameter that smooths the landscape when large (the loss factor).
SMOOTHING_PARAMETER = "beta"
#: Weight of ln chi2 in the peak-matching score: a change of chi2 by a factor e counts as
#: much as a 0.3 % mismatch of one peak frequency.
PEAK_CHI2_WEIGHT = 1e-5
#: The peak-matching search runs only when the chi2 search's best polished minimum fits
#: worse than this (reduced chi2 with a known noise; RMS residual over RMS |H| without).
CONVINCING_CHI2_RED = 2.0
CONVINCING_REL_RMS = 1e-2
#: Two converged runs closer than this (relative, per parameter) found the same minimum:
#: runs that stop at the rounding level of chi2 in a flat valley (one resonance in the
#: band, noiseless data) still differ by some 1e-6.
SAME_MINIMUM_REL = 1e-5
#: Steps of the valley walk (:func:`_valley_starts`), in Delta-chi2 = 1 lengths.
VALLEY_STEPS = (3.0, 6.0, 12.0, 24.0, 48.0)
#: Ratio between rungs of the continuation ladder (half a decade).
LADDER_RATIO = 10**-0.5


# -- a problem with some coordinates held --------------------------------------------------
class _HeldSpace:
    def __init__(self, space: ParameterSpace, free: np.ndarray, u_base: np.ndarray):
        self._space, self._free, self._base = space, free, u_base

    def full(self, u_free):
        u = self._base.copy()
        u[self._free] = u_free
        return u

    def theta(self, u_free):
        return self._space.theta(self.full(np.asarray(u_free, float)))


class HeldProblem:
    """``problem`` with the coordinates not in ``free`` held at ``u_base``; same interface
    as LeastSquaresProblem for the local optimisers (derivatives sliced from the full ones,
    so nothing is recompiled)."""

    def __init__(self, problem: LeastSquaresProblem, free, u_base):
        self.problem = problem
        self.free = np.asarray(free, dtype=int)
        self.space = _HeldSpace(problem.space, self.free, np.asarray(u_base, float).copy())
        self.n_points = problem.n_points

    def value_and_grad(self, u_free):
        f, g = self.problem.value_and_grad(self.space.full(u_free))
        return f, g[self.free]

    def hessian(self, u_free):
        H = self.problem.hessian(self.space.full(u_free))
        return H[np.ix_(self.free, self.free)]

    def chi2(self, u_free):
        return self.problem.chi2(self.space.full(u_free))

    def residuals(self, u_free):
        return self.problem.residuals(self.space.full(u_free))

    def jacobian(self, u_free):
        return self.problem.jacobian(self.space.full(u_free))[:, self.free]


def _as_full(result: LocalResult, held: HeldProblem) -> LocalResult:
    u = held.space.full(result.u)
    return LocalResult(result.method, u, held.problem.space.theta(u), result.loss,
                       result.status, result.message, result.n_iterations,
                       result.n_evaluations, result.history)


def polish_by_continuation(problem: LeastSquaresProblem, u_start, local: str = "newton",
                           ) -> list[LocalResult]:
    """Local fits from ``u_start`` with the loss factor released step by step.

    Returns every free fit, best (lowest chi2) first. Without a loss-factor parameter, one
    local run from ``u_start``.
    """
    run = LOCAL_METHODS[local]
    space = problem.space
    u = np.asarray(u_start, dtype=float).copy()
    if SMOOTHING_PARAMETER not in space.names:
        return [run(problem, u)]
    ib = space.names.index(SMOOTHING_PARAMETER)
    t = space.transforms[ib]
    beta = float(space.theta(u)[ib])
    low = max(t.low, 1e-6) if t.kind == "log" else t.low
    ladder = []
    b = beta
    while b > low * 1.0001:
        ladder.append(b)
        b *= LADDER_RATIO
    ladder.append(low)
    free = np.array([i for i in range(space.size) if i != ib], dtype=int)
    results: list[LocalResult] = []
    for b in ladder:
        u[ib] = float(t.to_u(b))
        held = HeldProblem(problem, free, u)
        r_held = run(held, u[free], RUNG_MAX_ITER)
        u = held.space.full(r_held.u)
        r_free = run(problem, u, RUNG_MAX_ITER)
        results.append(r_free)
        log.debug("continuation beta=%.3g: held chi2 %.6g, free chi2 %.6g beta %.3g",
                  b, r_held.loss, r_free.loss, r_free.theta[ib])
        if r_free.theta[ib] >= b * math.sqrt(LADDER_RATIO):
            break  # the free fit's loss factor lies above the rung: lower rungs are useless
    results.sort(key=lambda r: (not np.isfinite(r.loss), r.loss))
    if not results[0].converged:  # finish the best rung's free fit
        results.insert(0, run(problem, results[0].u))
    return results


# -- the entry point ----------------------------------------------------------------------
def identify(
    setup,
    frequency_hz,
    H,
    std=None,
    *,
    model: str | None = None,
    forward_model: ForwardModel | None = None,
    bounds: dict | None = None,
    method: str = "global",
    local: str = "newton",
    start: dict | np.ndarray | None = None,
    restarts: int = 5,
    seed: int | np.random.Generator | None = None,
    used=None,
    progress: bool = False,
    refresh: bool = True,
    throw: bool = False,
) -> IdentificationResult:
    """Identify the parameters of a material model from a measured AFC.

    Parameters
    ----------
    setup: the declared :class:`~vibid.setup_model.Setup` (specimen, sensor, bounds).
    frequency_hz: (n,) frequencies of the AFC points, Hz.
    H: (n,) complex AFC (response over base acceleration).
    std: (n,) standard uncertainty of Re H and Im H per point, or None if unknown (then
        the fit is the paper's plain mean square error and the noise is estimated from
        the residual).
    model: material model (default ``setup.identification.model``).
    forward_model: a ready ForwardModel for exactly these frequencies (or the used ones);
        by default one is built with ``vibid.identify.build_forward_model``.
    bounds: prior box per parameter (default ``setup.identification.bounds``).
    method: ``"global"`` (differential evolution over the box, then polish by
        continuation) or ``"local"`` (one run of the local method from ``start``).
    local: the local method: ``"newton"`` (trust region, exact Hessian), ``"bfgs"``
        (trust region, BFGS) or ``"lm"`` (Levenberg-Marquardt).
    start: start values for ``method="local"`` (dict by name or array in model order;
        default the centre of the prior box).
    restarts: restarts of the global search.
    seed: seed (or Generator) of the global search: same seed, same result.
    used: (n,) bool mask of the points to fit (default all finite points).
    progress: show a progress bar for the global search.
    refresh: rebuild the forward model around the estimate (``ForwardModel.refresh``) and
        polish once more on it; off, the model that searched also polishes.
    throw: raise VibidError if the final local run did not converge (else it is reported
        in ``status``/``message``/``warnings``).
    """
    t0 = time.perf_counter()
    model = model or setup.identification.model
    if method not in ("global", "local"):
        raise VibidError(f"unknown identification method {method!r}: use 'global' or 'local'")
    if local not in LOCAL_METHODS:
        raise VibidError(f"unknown local method {local!r}: use one of {', '.join(LOCAL_METHODS)}")
    data = fit_data(frequency_hz, H, std, used)
    warnings = list(data.warnings)

    if forward_model is None:
        from vibid.identify import build_forward_model

        forward_model = build_forward_model(setup, data.frequency_hz[data.used], model=model)
    names = tuple(forward_model.parameter_names)
    p = len(names)
    if 2 * data.n_used <= p:
        raise VibidError(
            f"too few AFC points: {data.n_used} usable point(s) give {2 * data.n_used} real "
            f"numbers, fewer than needed to fit the {p} parameters of model {model!r} and "
            "estimate their uncertainty"
        )
    if data.n_used < 3 * p:
        warnings.append(
            f"only {data.n_used} usable AFC points for {p} parameters: the estimate and its "
            "uncertainty are fragile"
        )
    space = ParameterSpace.from_bounds(names, bounds if bounds is not None
                                       else setup.identification.bounds)
    problem = LeastSquaresProblem(forward_model, data, space)

    global_result = None
    runs: list[LocalResult] = []
    problems: dict[int, LeastSquaresProblem] = {}  # id(run) -> the problem it ran on

    def polish(starts, continuation: bool = True):
        for u0 in starts:
            # each start is polished on a model built around it (the global search's model
            # only has to find basins); models of one shape share their compiled functions
            p_start = _refreshed(problem, space.theta(u0), data, space) if (
                refresh and method == "global") else problem
            new = (polish_by_continuation(p_start, u0, local) if continuation
                   else [LOCAL_METHODS[local](p_start, u0)])
            problems.update((id(r), p_start) for r in new)
            runs.extend(new)

    if method == "global":
        rng = np.random.default_rng(seed)
        global_result = differential_evolution(problem, restarts=restarts, rng=rng,
                                               progress=progress)
        polish(_distinct(global_result.u))
        if not _convincing(min(runs, key=_sort_key), problems, data):
            # the chi2 search missed the basin (its minima are needles when beta is small
            # and there are several stiffnesses): search on the resonance peaks too
            peak_starts = _peak_starts(problem, data, restarts, rng, progress)
            if peak_starts and SMOOTHING_PARAMETER in space.names:
                # the peak frequencies say little about the loss factor, which the chi2
                # search's narrow peaks pin down well: the polish starts from that estimate
                # (starting higher, at 10x, led the orthotropic plate into wrong basins)
                ib = space.names.index(SMOOTHING_PARAMETER)
                for u in peak_starts:
                    u[ib] = global_result.u[0][ib]
            polish(_distinct(peak_starts, against=global_result.u))
    else:
        polish([_start_u(space, start)], continuation=False)
    runs.sort(key=_sort_key)
    if method == "global":
        # neighbouring minima along the valley the data leave open: a lower one (the
        # global search missed it) or one about as low (then the std must cover both)
        walk = _valley_starts(problems[id(runs[0])], runs[0])
        n_before = len(runs)
        polish(walk, continuation=False)
        log.info("valley walk: %d starts, best chi2 %.6g -> %.6g", len(walk),
                 runs[0].loss, min(r.loss for r in runs[n_before:]) if walk else runs[0].loss)
        runs.sort(key=_sort_key)
        inside = _best_inside_prior(runs, space, problems, data)
        if inside is not None and inside is not runs[0]:
            log.info("prior box: chi2 %.6g inside it against %.6g outside", inside.loss,
                     runs[0].loss)
            runs.insert(0, runs.pop(next(i for i, r in enumerate(runs) if r is inside)))
    best = runs[0]
    problem = problems[id(best)]

    # a model rebuilt around the estimate (if it moved), and the model's own error
    refreshed = _refreshed(problem, best.theta, data, space) if refresh else problem
    if refreshed is not problem:
        problem = refreshed
        runs.insert(0, LOCAL_METHODS[local](problem, best.u))
        best = runs[0]
    forward_model = problem.model
    systematic = None
    if data.noise_known:
        best, systematic = _weigh_model_error(problem, best, runs, local)

    # minima found under other weights (or models) are compared under the final ones
    assert best is runs[0]
    compared = [best] + [_on_weights(r, problems.get(id(r), problem), problem.sigma)
                         for r in runs[1:]]
    return _result(problem, forward_model, data, model, best, runs, global_result, warnings,
                   t0, throw, systematic, compared)


def _valley_starts(problem: LeastSquaresProblem, best: LocalResult) -> list[np.ndarray]:
    """Starts for local fits along the flattest direction of chi2 at ``best``.

    When the data barely separate two parameters (D and nu with few resonances above the
    noise), chi2 has a long valley with a row of local minima along it, often a few
    per cent apart and tens of standard deviations of the best one's Fisher covariance:
    the global search lands in one of them, not always the lowest. Steps of VALLEY_STEPS
    times the Delta-chi2 = 1 length along the Hessian's weakest eigenvector, both ways,
    inside the prior box, reach the neighbours; each is then polished locally."""
    if not np.isfinite(best.loss):
        return []
    try:
        w, V = np.linalg.eigh(problem.hessian(best.u))
    except np.linalg.LinAlgError:
        return []
    if not (np.all(np.isfinite(w)) and w[0] > 0):
        return []
    v = V[:, 0]
    length = math.sqrt(2.0 / w[0])  # chi2 rises by 1 over this distance, in u
    starts = []
    for sign in (1.0, -1.0):
        for k in VALLEY_STEPS:
            u = best.u + sign * k * length * v
            if np.any(np.abs(u) > 1.0):
                break  # the prior box ends here
            starts.append(u)
    return starts


def _best_inside_prior(runs, space: ParameterSpace, problems: dict, data: FitData):
    """The best converged run inside the prior box, if the best of all lies outside it
    and fits the data not significantly better (chi2 lower by less than the 99 % quantile
    of chi-square with p degrees of freedom, in units of the noise variance): then the data
    leave the choice to the prior, which excludes the outside one. A minimum outside the
    box that fits significantly better stays the answer (and the report warns that the
    bounds may exclude the truth). None when there is nothing to choose."""
    best = runs[0]
    if not space.out_of_bounds(best.theta) or not np.isfinite(best.loss):
        return None
    inside = [r for r in runs if r.converged and np.isfinite(r.loss)
              and not space.out_of_bounds(r.theta)]
    if not inside:
        return None
    cand = min(inside, key=lambda r: r.loss)
    p = problems[id(best)]
    noise_var = 1.0 if data.noise_known else best.loss / max(p.dof, 1)
    return cand if cand.loss <= best.loss + _indistinct_chi2(space.size, noise_var) else None


def _sort_key(run: LocalResult):
    return (not np.isfinite(run.loss), run.loss)


def _convincing(run: LocalResult, problems: dict, data: FitData) -> bool:
    """Whether the chi2 search's best polished minimum fits the data well enough that a
    second search (on the resonance peaks) is not needed: with a known noise, a reduced
    chi2 up to CONVINCING_CHI2_RED; without, an RMS residual up to CONVINCING_REL_RMS of
    the RMS |H| (a wrong basin misses whole resonances: ratios of 10 and more, and
    relative residuals of order 1)."""
    if not np.isfinite(run.loss):
        return False
    problem = problems[id(run)]
    if data.noise_known:
        return run.loss / max(problem.dof, 1) <= CONVINCING_CHI2_RED
    # unknown noise: sigma is the RMS |H| at every point, so chi2 / n is the relative MSE
    return run.loss / (2 * problem.n_points) <= CONVINCING_REL_RMS**2


def _weigh_model_error(problem: LeastSquaresProblem, best: LocalResult, runs: list,
                       local: str) -> tuple[LocalResult, ModelErrorSplit | None]:
    """Put the model's own error where it belongs (:mod:`vibid.identify.model_error`):
    its unexplained part into the weights (then polish again if they changed), the part
    the parameters absorb into a systematic covariance term, taken with the final weights.
    Returns the best run and the split (None if the model estimates no error)."""
    model = problem.model
    if not hasattr(model, "model_error_parts"):
        me = problem.on_points(np.asarray(model.model_error(best.theta), dtype=float))
        if np.any(me > 0):
            problem.set_weights(me)
            best = _polish_again(problem, best, runs, local)
        return best, None
    d, red = model.model_error_parts(best.theta)
    d, red = problem.on_points(d), problem.on_points(red)
    if not (np.any(d != 0) or np.any(red > 0)):
        return best, None
    problem.set_weights()
    split = split_model_error(problem.jacobian_theta(best.theta), d, red, problem.sigma)
    old = problem.sigma.copy()
    problem.set_weights(split.point_std)
    if np.max(np.abs(problem.sigma / old - 1)) > 1e-3:
        best = _polish_again(problem, best, runs, local)
        split = split_model_error(problem.jacobian_theta(best.theta), d, red, problem.sigma)
    return best, split


def _on_weights(run: LocalResult, problem: LeastSquaresProblem, sigma) -> LocalResult:
    """``run`` with its loss evaluated on its own problem weighted with ``sigma``."""
    if problem.sigma.shape == np.shape(sigma) and np.array_equal(problem.sigma, sigma):
        return run
    problem.use_sigma(sigma)
    return dataclasses.replace(run, loss=problem.chi2(run.u))


def _polish_again(problem, best, runs, local) -> LocalResult:
    runs.insert(0, LOCAL_METHODS[local](problem, best.u))
    return runs[0]


def _peak_starts(problem: LeastSquaresProblem, data: FitData, restarts: int, rng,
                 progress: bool) -> list[np.ndarray]:
    """Starts from a global search that matches the measured resonance peaks
    (:mod:`vibid.identify.peaks`); none when the model cannot give its modes or the AFC
    shows no peak."""
    model = problem.model
    if not hasattr(model, "modes_batch") or not model.param.proportional:
        return []
    u = data.used
    peaks = measured_peaks(data.frequency_hz[u], data.H[u], None if data.std is None
                           else data.std[u])
    if peaks.count == 0:
        return []
    space = problem.space

    def score(U):
        # peak matching first; among parameter sets that match the peaks equally well
        # (fewer peaks in the band than stiffness parameters leave a family of them) the
        # AFC's chi2 decides, through a term too small to outweigh a visible mismatch
        f_hz, height = model.modes_batch(space.theta(U))
        chi2 = np.maximum(problem.chi2_batch(U), 1e-300)
        return np.asarray(peak_score(f_hz, height, peaks)) + PEAK_CHI2_WEIGHT * np.log(chi2)

    result = differential_evolution(problem, restarts=restarts, rng=rng, progress=progress,
                                    score=score, label="peak matching")
    log.info("peak matching: %d measured peaks, best score %.3g", peaks.count, result.loss[0])
    return list(result.u)


def _refreshed(problem: LeastSquaresProblem, theta, data: FitData,
               space: ParameterSpace) -> LeastSquaresProblem:
    """``problem`` on its model rebuilt around ``theta`` (itself if the model stays)."""
    model = problem.model.refresh(theta)
    return problem if model is problem.model else LeastSquaresProblem(model, data, space)


def _indistinct_chi2(p: int, noise_var: float) -> float:
    """How much higher a minimum's chi2 may lie and still fit the data about as well as
    the best: the 99 % quantile of chi-square with ``p`` degrees of freedom, in units of
    the noise variance."""
    from scipy.stats import chi2 as chi2_dist

    return float(chi2_dist.ppf(0.99, p)) * noise_var


def _rival_minima(runs, best, cov, chi2_red, noise_known, names):
    """Widen the covariance by the other minima that fit the data about as well.

    With noisy data the loss can have several minima whose chi2 differ by a few units:
    the data do not decide between them, and the Fisher covariance of the best one alone
    would be a confident answer that may be wrong. Each distinct converged minimum i with
    chi2_i <= chi2_best + DELTA (DELTA: the 99 % quantile of chi-square with p degrees of
    freedom, in units of the noise variance) is given the weight exp(-(chi2_i -
    chi2_best) / 2) of a Laplace approximation of the posterior around it; the returned
    covariance is the mixture's second moment about the best estimate,
    sum_i w_i (C + d_i d_i^T) / sum_i w_i with d_i = theta_i - theta_best (the Fisher C of
    the best minimum standing in for each). Returns (covariance, warning or None).
    """
    p = len(names)
    noise_var = 1.0 if noise_known else (chi2_red if np.isfinite(chi2_red) and chi2_red > 0 else 1.0)
    delta = _indistinct_chi2(p, noise_var)
    sd = np.sqrt(np.abs(np.diag(cov)))
    if not np.all(np.isfinite(sd)):
        return cov, None
    rivals = []
    for r in runs:
        if r is best or not r.converged or not np.isfinite(r.loss) or r.loss > best.loss + delta:
            continue
        d = r.theta - best.theta
        if not np.any((np.abs(d) > 2 * sd) & (np.abs(d) > SAME_MINIMUM_REL * np.abs(best.theta))):
            continue  # the same minimum (to its uncertainty, or to where the runs stopped)
        if any(np.all(np.abs(r.theta - q.theta) <= SAME_MINIMUM_REL * (np.abs(q.theta) + sd))
               for q, _ in rivals):
            continue
        rivals.append((r, d))
    if not rivals:
        return cov, None
    w = np.array([1.0] + [np.exp(-(r.loss - best.loss) / (2 * noise_var)) for r, _ in rivals])
    second = np.zeros_like(cov)
    for wi, (_, d) in zip(w[1:], rivals):
        second += wi * np.outer(d, d)
    wide = cov + second / w.sum()
    spans = ", ".join(
        f"{n} {min([best.theta[i]] + [r.theta[i] for r, _ in rivals]):.4g}.."
        f"{max([best.theta[i]] + [r.theta[i] for r, _ in rivals]):.4g}"
        for i, n in enumerate(names))
    return wide, (
        f"{len(rivals) + 1} distinct minima fit the data about equally well (chi2 within "
        f"{delta:.3g} of the best): the data do not single out one answer ({spans}); "
        "the standard deviations include this spread"
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


def _distinct(U, tol: float = 1e-3, against=()) -> list[np.ndarray]:
    """The points of ``U`` farther than ``tol`` (inf-norm) from each other and from every
    point of ``against``."""
    seen = [np.asarray(v, float) for v in against]
    out: list[np.ndarray] = []
    for u in U:
        if all(np.max(np.abs(u - v)) > tol for v in seen + out):
            out.append(np.asarray(u, float))
    return out


def _result(problem, forward_model, data: FitData, model, best: LocalResult, runs,
            global_result, warnings, t0, throw,
            systematic: ModelErrorSplit | None, compared: list) -> IdentificationResult:
    space = problem.space
    theta = best.theta
    if not np.all(np.isfinite(theta)):  # cannot happen for finite u; never report NaN
        raise VibidError("the identification produced non-finite parameters")
    r = problem.residuals(best.u)
    chi2 = float(r @ r)
    dof = problem.dof
    chi2_red = chi2 / dof if dof > 0 else math.nan
    unc = fisher_uncertainty(problem.jacobian_theta(theta), space.names,
                             chi2_reduced=chi2_red, noise_known=data.noise_known)
    warnings.extend(unc.warnings)
    cov, note = _rival_minima(compared, best, unc.covariance, chi2_red, data.noise_known,
                              space.names)
    if systematic is not None:
        cov = cov + systematic.covariance
    if note:
        warnings.append(note)
    std = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    Hm_used = problem.model_afc(theta)
    if Hm_used.size != data.n_used:
        Hm_used = problem.on_points(Hm_used)
    H_used = data.H[data.used]
    rel_rms = float(np.sqrt(np.mean(np.abs(Hm_used - H_used) ** 2) / np.mean(np.abs(H_used) ** 2)))
    chi2_red_data = math.nan
    if data.noise_known and dof > 0:
        rd = (Hm_used - H_used) / data.std[data.used]
        chi2_red_data = float(np.sum(rd.real**2 + rd.imag**2)) / dof
    model_afc = np.full(data.H.shape, np.nan + 1j * np.nan)
    model_afc[data.used] = Hm_used

    status, message = best.status, f"{best.method} {best.message}"
    if not status.ok:
        warnings.append(f"the local optimisation {message}")
    for name in space.out_of_bounds(theta):
        t = space.transforms[space.names.index(name)]
        v = theta[space.names.index(name)]
        warnings.append(
            f"{name} = {v:.6g} lies on or outside its prior bounds [{t.low:g}, {t.high:g}]: "
            "the bounds may exclude the true value; widen them and identify again"
        )
    for name, v, s in zip(space.names, theta, std):
        if np.isfinite(s) and abs(v) > 0 and s > 0.3 * abs(v):
            warnings.append(
                f"{name} is poorly determined by these data (std {s:.2g} = "
                f"{100 * s / abs(v):.0f} % of its value)"
            )
    if data.noise_known and np.isfinite(chi2_red) and chi2_red > 2.0:
        warnings.append(
            f"the model does not fit the data to their noise level (reduced chi2 = "
            f"{chi2_red:.3g}): the standard deviations understate the error"
        )
    if throw and not status.ok:
        raise VibidError(f"identification of model {model!r}: {message}")
    return IdentificationResult(
        model=model, parameter_names=space.names, values=np.asarray(theta, float),
        std=std, covariance=cov, correlation=corr, chi2=chi2,
        chi2_reduced=chi2_red, dof=dof, rel_rms_residual=rel_rms, status=status,
        message=message, noise_known=data.noise_known, frequency_hz=data.frequency_hz,
        H=data.H, H_std=data.std, used=data.used, model_afc=model_afc,
        global_result=global_result, local_results=tuple(runs), warnings=tuple(warnings),
        model_error_bias=None if systematic is None else systematic.bias,
        chi2_reduced_data_weights=chi2_red_data,
        seconds=time.perf_counter() - t0,
    )
