"""Which minimum: the valley the data leave open, the prior box, and rival minima.

With few resonances above the noise, chi2 has a long valley (D against nu) with a row of
local minima along it. :func:`valley_starts` gives starts along it for more local fits;
:func:`best_inside_prior` lets the prior box decide between minima the data do not;
:func:`rival_minima` widens the covariance by the minima that fit about as well.
"""

from __future__ import annotations

import math

import numpy as np

from vibid.identify.fit.space import ParameterSpace

#: Two converged runs closer than this (relative, per parameter) found the same minimum:
#: runs that stop at the rounding level of chi2 in a flat valley (one resonance in the
#: band, noiseless data) still differ by some 1e-6.
SAME_MINIMUM_REL = 1e-5
#: Steps of the valley walk (:func:`valley_starts`), in Delta-chi2 = 1 lengths.
VALLEY_STEPS = (3.0, 6.0, 12.0, 24.0, 48.0)


def valley_starts(problem, best) -> list[np.ndarray]:
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


def best_inside_prior(runs, space: ParameterSpace, noise_var: float):
    """The best converged run inside the prior box, if the best of all (``runs[0]``) lies
    outside it and fits the data not significantly better (chi2 lower by less than the 99 %
    quantile of chi-square with p degrees of freedom, in units of the noise variance
    ``noise_var``): then the data leave the choice to the prior, which excludes the outside
    one. A minimum outside the box that fits significantly better stays the answer (and the
    report warns that the bounds may exclude the truth). None when there is nothing to
    choose."""
    best = runs[0]
    if not space.out_of_bounds(best.theta) or not np.isfinite(best.loss):
        return None
    inside = [
        r for r in runs if r.converged and np.isfinite(r.loss) and not space.out_of_bounds(r.theta)
    ]
    if not inside:
        return None
    cand = min(inside, key=lambda r: r.loss)
    return cand if cand.loss <= best.loss + indistinct_chi2(space.size, noise_var) else None


def indistinct_chi2(p: int, noise_var: float) -> float:
    """How much higher a minimum's chi2 may lie and still fit the data about as well as
    the best: the 99 % quantile of chi-square with ``p`` degrees of freedom, in units of
    the noise variance."""
    from scipy.stats import chi2 as chi2_dist

    return float(chi2_dist.ppf(0.99, p)) * noise_var


def rival_minima(runs, best, cov, chi2_red, noise_known, names):
    """Widen the covariance by the other minima that fit the data about as well.

    With noisy data the loss can have several minima whose chi2 differ by a few units:
    the data do not decide between them, and the Fisher covariance of the best one alone
    would be a confident answer that may be wrong. Each distinct converged minimum i with
    chi2_i <= chi2_best + DELTA (DELTA: the 99 % quantile of chi-square with p degrees of
    freedom, in units of the noise variance) is given the weight exp(-(chi2_i -
    chi2_best) / 2) of a Laplace approximation of the posterior around it; the returned
    covariance is the mixture's second moment about the best estimate,
    sum_i w_i (C + d_i d_i^T) / sum_i w_i with d_i = theta_i - theta_best (the Fisher C of
    the best minimum standing in for each). Returns (covariance, warning or None, the
    rivals' parameter vectors).
    """
    p = len(names)
    noise_var = (
        1.0 if noise_known else (chi2_red if np.isfinite(chi2_red) and chi2_red > 0 else 1.0)
    )
    delta = indistinct_chi2(p, noise_var)
    sd = np.sqrt(np.abs(np.diag(cov)))
    if not np.all(np.isfinite(sd)):
        return cov, None, ()
    rivals = []
    for r in runs:
        if r is best or not r.converged or not np.isfinite(r.loss) or r.loss > best.loss + delta:
            continue
        d = r.theta - best.theta
        if not np.any((np.abs(d) > 2 * sd) & (np.abs(d) > SAME_MINIMUM_REL * np.abs(best.theta))):
            continue  # the same minimum (to its uncertainty, or to where the runs stopped)
        if any(
            np.all(np.abs(r.theta - q.theta) <= SAME_MINIMUM_REL * (np.abs(q.theta) + sd))
            for q, _ in rivals
        ):
            continue
        rivals.append((r, d))
    if not rivals:
        return cov, None, ()
    # weights relative to the lowest chi2 (under the final weights a rival may lie lower
    # than the best, which was chosen under earlier ones): no overflow
    losses = np.array([best.loss] + [r.loss for r, _ in rivals])
    w = np.exp(-(losses - losses.min()) / (2 * noise_var))
    second = np.zeros_like(cov)
    for wi, (_, d) in zip(w[1:], rivals):
        second += wi * np.outer(d, d)
    wide = cov + second / w.sum()
    spans = ", ".join(
        f"{n} {min([best.theta[i]] + [r.theta[i] for r, _ in rivals]):.4g}.."
        f"{max([best.theta[i]] + [r.theta[i] for r, _ in rivals]):.4g}"
        for i, n in enumerate(names)
    )
    return (
        wide,
        (
            f"{len(rivals) + 1} distinct minima fit the data about equally well (chi2 within "
            f"{delta:.3g} of the best): the data do not single out one answer ({spans}); "
            "the standard deviations include this spread"
        ),
        tuple(np.asarray(r.theta, float).copy() for r, _ in rivals),
    )


def distinct(U, tol: float = 1e-3, against=()) -> list[np.ndarray]:
    """The points of ``U`` farther than ``tol`` (inf-norm) from each other and from every
    point of ``against``."""
    seen = [np.asarray(v, float) for v in against]
    out: list[np.ndarray] = []
    for u in U:
        if all(np.max(np.abs(u - v)) > tol for v in seen + out):
            out.append(np.asarray(u, float))
    return out
