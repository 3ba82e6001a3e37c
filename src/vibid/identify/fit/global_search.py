"""Global search over the prior box: differential evolution with restarts.

scipy.optimize.differential_evolution (Storn & Price 1997, the paper's Algorithm 2) in
the coordinates ``u`` of the parameter space, where the prior box is [-1, 1]^p. The whole
population of a generation is one vectorised model call (``afc_batch``). Settings follow
the paper's section 6.3: population 15 per searched parameter, mutation factor drawn in
(0.7, 1.0), a loose tolerance of 1e-2 (the result only has to land in the right basin),
several restarts with different initial populations, which stop early once three of them
have ended on one point (the others would find it again).

All parameters are searched, the loss factor too (over its log box): the loss is very
multimodal in D (each model peak sliding past a data peak makes a local minimum), and
holding beta at a large value to smooth it (tried: ``fixed={"beta": 0.1}``) biases the
smoothed minimum along the D-nu valley to a wrong basin at 1000-1500 Hz, while the
search with beta free lands in the right basin in most restarts. Every restart's best is
polished (vibid.identify.fit), not only the best one. ``fixed`` holds parameters at a
physical value during the search when wanted. The initial population is a Latin
hypercube that is uniform in each parameter's natural scale (log for log parameters)
over its prior box, mapped to ``u``.
"""

from __future__ import annotations

import logging

import numpy as np

from vibid.identify.engine.profile import timed
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.result import GlobalResult

log = logging.getLogger(__name__)

#: The restarts stop once this many have ended within :data:`AGREE_TOL` of the best.
AGREE = 3
#: ... in the coordinates ``u`` of the prior box ([-1, 1]: 1 % of its width).
AGREE_TOL = 0.02


def latin_hypercube_u(space, n: int, rng: np.random.Generator, free: np.ndarray) -> np.ndarray:
    """(n, len(free)) initial population: a Latin hypercube uniform in each parameter's
    natural scale (log for log parameters, linear otherwise) over its prior box, in ``u``."""
    k = len(free)
    cells = (np.argsort(rng.random((k, n)), axis=1).T + rng.random((n, k))) / n
    out = np.empty((n, k))
    for j, i in enumerate(free):
        t = space.transforms[i]
        lo, hi = t.low, t.high
        if t.kind == "log":
            lo = max(lo, hi * 1e-3)
            theta = np.exp(np.log(lo) + cells[:, j] * (np.log(hi) - np.log(lo)))
        else:
            theta = lo + cells[:, j] * (hi - lo)
        out[:, j] = np.clip(t.to_u(theta), -1.0, 1.0)
    return out


@timed("global search")
def differential_evolution(
    problem: LeastSquaresProblem,
    *,
    fixed: dict[str, float] | None = None,
    restarts: int = 5,
    popsize: int = 15,
    mutation: tuple[float, float] = (0.7, 1.0),
    recombination: float = 0.7,
    tol: float = 1e-2,
    max_generations: int = 60,
    rng: np.random.Generator | int | None = None,
    progress=None,
    score=None,
    label: str = "global search",
    agree: int | None = AGREE,
    agree_tol: float = AGREE_TOL,
    agree_rtol: float | None = None,
) -> GlobalResult:
    """Search the prior box for the minimum of chi2, ``restarts`` times.

    Parameters
    ----------
    problem: the weighted least-squares problem (its ``chi2_batch`` is called once per
        generation on the whole population).
    fixed: parameters held at a physical value during the search, e.g. ``{"beta": 0.1}``.
    restarts: independent runs with different initial populations.
    popsize, mutation, recombination, tol, max_generations: scipy's settings (popsize per
        searched parameter).
    rng: seed or Generator; the same seed gives the same result.
    progress: ``progress(label, done, total, best)`` after every generation (``done`` of
        ``total`` generations over all restarts; ``best`` the restart's best objective), or
        None. The search itself prints nothing.
    score: another population score ``score(U (S, p)) -> (S,)`` to minimise instead of
        chi2 (e.g. :func:`vibid.identify.fit.peaks.peak_score`); ``loss`` then holds it.
    label: the progress report's and the log's name of this search.
    agree, agree_tol: the restarts stop early once ``agree`` of them (None: never) have
        ended within ``agree_tol`` (inf-norm in ``u``) of the best one: independent
        populations converging on one point say the box holds no better basin they could
        reach, and the rest would find it again.
    agree_rtol: where given, the restarts agree by their ``loss`` instead, within this
        fraction of the best one: a score that leaves a family of equally good points
        (the peak match of fewer peaks than stiffnesses) spreads equal ends over ``u``.

    Returns
    -------
    GlobalResult: best point of each restart, sorted by their loss (best first), with
    the fixed parameters filled in.
    """
    rng = np.random.default_rng(rng)
    space = problem.space
    free, u_fixed = _held(space, fixed)
    objective = _Objective(problem, free, u_fixed, score)
    generations = _Generations(progress, label, restarts * max_generations)
    settings = dict(mutation=mutation, recombination=recombination, tol=tol)
    us, losses, messages = [], [], []
    for r in range(restarts):
        init = latin_hypercube_u(space, popsize * len(free), rng, free)
        sol = _restart(objective, init, rng, generations, max_generations, settings)
        u = u_fixed.copy()
        u[free] = sol.x
        us.append(u)
        losses.append(float(sol.fun))
        messages.append(_restart_ended(label, r, sol, space, u))
        if agree and r + 1 < restarts and _agreeing(us, losses, agree_tol, agree_rtol) >= agree:
            log.info("%s: %d restarts agree, the other %d skipped", label, agree, restarts - r - 1)
            generations.finish(float(min(losses)))
            break
    order = np.argsort(losses)
    U = np.array(us)[order]
    return GlobalResult(
        U,
        space.theta(U),
        np.array(losses)[order],
        objective.evaluations,
        tuple(messages[i] for i in order),
    )


def _held(space, fixed: dict[str, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """The indices of the searched parameters, and the point ``u`` that holds the fixed
    ones at their values (zero elsewhere)."""
    fixed = dict(fixed or {})
    unknown = set(fixed) - set(space.names)
    if unknown:
        raise ValueError(
            f"differential_evolution: fixed names {sorted(unknown)} are not parameters"
        )
    free = np.array([i for i, n in enumerate(space.names) if n not in fixed], dtype=int)
    u_fixed = np.zeros(space.size)
    for n, v in fixed.items():
        i = space.names.index(n)
        u_fixed[i] = float(space.transforms[i].to_u(v))
    return free, u_fixed


class _Objective:
    """chi2 (or ``score``) of a population given in the searched coordinates (one column
    per member, scipy's vectorised layout), the fixed parameters filled in; counts the
    points it evaluated."""

    def __init__(self, problem, free, u_fixed, score):
        self.problem, self.free, self.u_fixed, self.score = problem, free, u_fixed, score
        self.evaluations = 0

    def full(self, U_free):  # (k, S) -> (S, p)
        U = np.repeat(self.u_fixed[None, :], U_free.shape[1], axis=0)
        U[:, self.free] = U_free.T
        return U

    def __call__(self, U_free):
        U_free = np.atleast_2d(U_free.T).T if U_free.ndim == 1 else U_free
        self.evaluations += U_free.shape[1]
        U = self.full(U_free)
        return self.problem.chi2_batch(U) if self.score is None else np.asarray(self.score(U))


class _Generations:
    """The progress report over every restart: ``done`` of ``total`` generations."""

    def __init__(self, progress, label: str, total: int):
        self.progress, self.label, self.total, self.done = progress, label, total, 0

    def report(self, best: float) -> None:
        if self.progress is not None:
            self.progress(self.label, self.done, self.total, best)

    def finish(self, best: float) -> None:
        """The restarts that will not run (they agree) count as done."""
        if self.progress is not None:
            self.done = self.total
            self.report(best)


def _restart(objective, init, rng, generations: _Generations, max_generations: int, settings):
    """One run of scipy's differential evolution from the population ``init``, reporting
    every generation; a run that converged early counts its remaining generations done."""
    from scipy.optimize import differential_evolution as scipy_de

    ran = [0]

    def callback(intermediate_result):
        ran[0] += 1
        generations.done += 1
        generations.report(float(intermediate_result.fun))

    sol = scipy_de(
        objective,
        [(-1.0, 1.0)] * init.shape[1],
        init=init,
        maxiter=max_generations,
        polish=False,
        vectorized=True,
        updating="deferred",
        rng=rng,
        callback=callback,
        **settings,
    )
    generations.done += max_generations - ran[0]  # a restart that converged early
    generations.report(float(sol.fun))
    return sol


def _restart_ended(label: str, r: int, sol, space, u) -> str:
    """Log restart ``r``'s end at ``u``; its message."""
    log.info(
        "%s, restart %d: %.6g at %s (%d generations)",
        label,
        r + 1,
        sol.fun,
        space.as_dict(space.theta(u)),
        sol.nit,
    )
    return f"{label}, restart {r + 1}: {sol.message} ({sol.nit} generations)"


def _agreeing(us, losses, agree_tol: float, agree_rtol: float | None) -> int:
    """How many restarts ended where the best did: within ``agree_tol`` of its ``u``
    (inf-norm), or with ``agree_rtol``, within that fraction of its loss."""
    b = int(np.argmin(losses))
    if agree_rtol is not None:
        return sum(abs(x - losses[b]) <= agree_rtol * abs(losses[b]) for x in losses)
    return sum(np.max(np.abs(v - us[b])) <= agree_tol for v in us)


def robust_score(problem: LeastSquaresProblem, scale: float = 1.0):
    """A population score that gives every point a bounded say: ``Σ_k log(1 + |r_k|² /
    scale²)`` over the fitted points (``r_k`` the weighted residual of chi2), for
    :func:`differential_evolution`'s ``score``.

    Where a few points are far more telling than the rest (an adaptive campaign's steps at
    the resonances, recorded long), chi2 is a needle: away from the one basin where the
    model's modes sit on those points they dominate it with a plateau of huge residuals,
    whose ripples (a mode of the model passing one of them) are the minima the search
    finds. Logarithmically, a point fitted badly counts about as much as any other, so the
    many points off resonance place the basin; the polish on chi2 then finds the needle."""
    H = problem.observed(problem.data.H[problem.data.used])
    sigma = problem.sigma
    space, model = problem.space, problem.model

    def score(U):
        thetas = np.array([space.theta(u) for u in np.atleast_2d(U)])
        A = problem.observed(problem.on_points(np.asarray(model.afc_batch(thetas)).T).T)
        r2 = np.abs((A - H[None, :]) / sigma[None, :]) ** 2
        s = np.log1p(r2 / scale**2).sum(axis=1)
        return np.where(np.isfinite(s), s, np.inf)

    return score
