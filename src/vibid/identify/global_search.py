"""Global search over the prior box: differential evolution with restarts.

scipy.optimize.differential_evolution (Storn & Price 1997, the paper's Algorithm 2) in
the coordinates ``u`` of the parameter space, where the prior box is [-1, 1]^p. The whole
population of a generation is one vectorised model call (``afc_batch``). Settings follow
the paper's section 6.3: population 15 per searched parameter, mutation factor drawn in
(0.7, 1.0), a loose tolerance of 1e-2 (the result only has to land in the right basin),
several restarts with different initial populations.

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

from vibid.identify.fit_result import GlobalResult
from vibid.identify.loss import LeastSquaresProblem

log = logging.getLogger(__name__)


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
    progress: bool = False,
    score=None,
    label: str = "global search",
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
    progress: show a progress bar (tqdm, on stderr) over all generations of all restarts.
    score: another population score ``score(U (S, p)) -> (S,)`` to minimise instead of
        chi2 (e.g. :func:`vibid.identify.peaks.peak_score`); ``loss`` then holds it.
    label: the progress bar's and the log's name of this search.

    Returns
    -------
    GlobalResult: best point of each restart, sorted by their loss (best first), with
    the fixed parameters filled in.
    """
    from scipy.optimize import differential_evolution as scipy_de

    rng = np.random.default_rng(rng)
    space = problem.space
    fixed = dict(fixed or {})
    unknown = set(fixed) - set(space.names)
    if unknown:
        raise ValueError(f"differential_evolution: fixed names {sorted(unknown)} are not parameters")
    free = np.array([i for i, n in enumerate(space.names) if n not in fixed], dtype=int)
    u_fixed = np.zeros(space.size)
    for n, v in fixed.items():
        i = space.names.index(n)
        u_fixed[i] = float(space.transforms[i].to_u(v))
    n_eval = [0]

    def full(U_free):  # (k, S) -> (S, p)
        U = np.repeat(u_fixed[None, :], U_free.shape[1], axis=0)
        U[:, free] = U_free.T
        return U

    def objective(U_free):
        U_free = np.atleast_2d(U_free.T).T if U_free.ndim == 1 else U_free
        n_eval[0] += U_free.shape[1]
        U = full(U_free)
        return problem.chi2_batch(U) if score is None else np.asarray(score(U))

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=restarts * max_generations, desc=label, unit="gen",
                   leave=False, dynamic_ncols=True)
    us, losses, messages = [], [], []
    n_pop = popsize * len(free)
    try:
        for r in range(restarts):
            init = latin_hypercube_u(space, n_pop, rng, free)
            gens = [0]

            def callback(intermediate_result):
                gens[0] += 1
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix(restart=f"{r + 1}/{restarts}",
                                    **{"chi2" if score is None else "score":
                                       f"{intermediate_result.fun:.4g}"})

            sol = scipy_de(
                objective, [(-1.0, 1.0)] * len(free), init=init, mutation=mutation,
                recombination=recombination, tol=tol, maxiter=max_generations, polish=False,
                vectorized=True, updating="deferred", rng=rng, callback=callback,
            )
            if bar is not None:
                bar.update(max_generations - gens[0])
            u = u_fixed.copy()
            u[free] = sol.x
            us.append(u)
            losses.append(float(sol.fun))
            messages.append(f"restart {r + 1}: {sol.message} ({sol.nit} generations)")
            log.info("%s, restart %d: %.6g at %s (%d generations)", label, r + 1, sol.fun,
                     space.as_dict(space.theta(u)), sol.nit)
    finally:
        if bar is not None:
            bar.close()
    order = np.argsort(losses)
    U = np.array(us)[order]
    return GlobalResult(U, space.theta(U), np.array(losses)[order], n_eval[0],
                        tuple(messages[i] for i in order))
