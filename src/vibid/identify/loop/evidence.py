"""The loop's one criterion: each explanation's Bayesian evidence (Laplace's approximation).

Every explanation a round compares (the current model, "stop here", and the current model
with one more effect or a new material) is a model class ``M`` with parameters ``θ``. Its
evidence ``p(data | M)`` (Beck & Yuen 2004; Muto & Beck 2008) is approximated about its best
fit as

    log Z = log L(θ̂) + ½ log det(2π Σ) − log V + log P(inside)

under one noise model for the whole round (:class:`Noise`):

* the weighted residuals are Gaussian with a variance ``s`` no lower than the measured
  noise's (``s ≥ 1`` in the weights' units; each model's ``s`` its own maximum-likelihood
  value ``max(1, χ²/n)``: a misfit the model leaves is part of its noise, not a free
  lunch for the next parameter), and ``tau`` neighbouring residuals along frequency carry
  one independent one (the current fit's residual correlation,
  :func:`~vibid.identify.fit.noise.misfit_scale`): ``log L = −(χ²/s + n log s) / (2 tau)``;
* each parameter's prior is uniform over its physical box in the coordinate its fit
  uses (log-uniform for a stiffness, a mass or a loss, uniform for a signed delay; the
  box includes a lossless or rigid end where the physics has one), so ``V`` is the box's
  volume in those coordinates and ``Σ`` the posterior covariance there (the fit's
  covariance times ``s tau``), each of its widths no wider than the box;
* ``P(inside)``: the posterior's mass inside the box, parameter by parameter (a fit that
  reaches the data only with a parameter outside its physical range is improbable by
  exactly that much).

The Occam factor ``½ log det(2π Σ) − log V`` is what a parameter costs: a new effect wins
when the misfit it removes outweighs the prior volume its parameters leave unused. The
round's explanations then have posterior probabilities under the model prior of the
:class:`~vibid.identify.loop.policy.Policy` (half on "the model is complete", the other
half spread over the library's explanations: a library of ``k`` explanations must beat
stopping by a Bayes factor ``k``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.special import log_ndtr

from vibid.identify.fit.noise import misfit_scale
from vibid.identify.fit.space import ParameterSpace

if TYPE_CHECKING:
    from vibid.identify.fit.result import IdentificationResult

CRITERION = "log_evidence"
MEANING = (
    "the log of each explanation's Bayesian evidence (Laplace's approximation): its "
    "likelihood under Gaussian noise no smaller than the measured one, the misfit's "
    "correlation along frequency counted, times its Occam factor under uniform priors "
    "over each parameter's physical box"
)


@dataclass(frozen=True)
class Noise:
    """The round's noise model: ``n`` real residuals, ``tau`` of them per independent one."""

    n: int
    tau: float = 1.0

    @classmethod
    def of(cls, result, n: int) -> Noise:
        """The noise model of a round from its current fit ``result``."""
        _, tau = misfit_scale(result)
        return cls(int(n), max(1.0, float(tau)))

    def scale(self, chi2: float) -> float:
        """The residual's variance per point in the weights' units (at least the noise's)."""
        return max(1.0, float(chi2) / max(self.n, 1))

    def log_likelihood(self, chi2: float) -> float:
        s = self.scale(chi2)
        return -(float(chi2) / s + self.n * math.log(s)) / (2.0 * self.tau)


@dataclass(frozen=True)
class Evidence:
    """An explanation's log evidence and its parts (nats)."""

    log_z: float
    log_likelihood: float
    occam: float
    inside: float

    @property
    def parts(self) -> tuple:
        return (
            ("log_likelihood", self.log_likelihood),
            ("occam", self.occam),
            ("log_p_inside", self.inside),
        )


def prior_space(result, box: dict) -> ParameterSpace:
    """The coordinates of ``result``'s parameters in which their priors are uniform:
    each one's fit coordinate over its physical box (``box``, the loop's: the setup's
    bounds and the library's)."""
    model = result.plate_model
    bounds = model.default_bounds(box)
    return ParameterSpace.from_bounds(
        result.parameter_names, bounds, {q.name: q.kind for q in model.parameters}
    )


def log_evidence(result, box: dict, noise: Noise, chi2: float | None = None) -> Evidence:
    """``result``'s log evidence under ``noise`` (module doc); ``chi2``: its chi2 under the
    round's weights where they differ from its own."""
    chi2 = float(result.chi2 if chi2 is None else chi2)
    theta = np.asarray(result.values, float)
    C = np.asarray(result.covariance, float)
    s = noise.scale(chi2)
    space = prior_space(result, box)
    g = space.du_dtheta(theta)
    free = np.isfinite(g) & np.isfinite(np.diag(C)) & (np.diag(C) > 0)
    Cu = (g[free, None] * C[np.ix_(free, free)] * g[None, free]) * s * noise.tau
    occam = _occam(Cu)
    with np.errstate(all="ignore"):
        u = space.to_u(theta)[free]
    inside = (
        float(np.sum([_log_mass_inside(m, math.sqrt(v)) for m, v in zip(u, np.diag(Cu))]))
        if Cu.size
        else 0.0
    )
    ll = noise.log_likelihood(chi2)
    return Evidence(ll + occam + inside, ll, occam, inside)


def _occam(Cu: np.ndarray) -> float:
    """``½ log det(2π Σ) − log V`` in box coordinates (each box [-1, 1], V = 2^k), each
    posterior width capped at the box's: data that do not determine a parameter leave its
    prior as it was, at no cost and no gain."""
    if Cu.size == 0:
        return 0.0
    lam = np.linalg.eigvalsh(0.5 * (Cu + Cu.T))
    cap = 4.0 / (2 * math.pi)  # sqrt(2 pi lam) <= 2, the box's width
    lam = np.clip(lam, 1e-300, cap)
    return float(0.5 * np.sum(np.log(2 * math.pi * lam)) - len(lam) * math.log(2.0))


def _log_mass_inside(mu: float, sd: float) -> float:
    """log of the mass of N(mu, sd²) inside [-1, 1] (stable far outside)."""
    if not (np.isfinite(mu) and np.isfinite(sd)) or sd <= 0:
        return 0.0 if -1.0 <= mu <= 1.0 else -math.inf
    a, b = (-1.0 - mu) / sd, (1.0 - mu) / sd
    if a > 0:  # all of it above: mirror
        a, b = -b, -a
    la, lb = float(log_ndtr(a)), float(log_ndtr(b))
    return lb + math.log1p(-math.exp(la - lb)) if lb > la else -math.inf


def approximate(log_z_now: float, noise: Noise, chi2_now: float, lm: float, information) -> float:
    """A candidate's log evidence before its refit, from its score test at the current
    fit (``log_z_now``: the current model's): one Gauss-Newton step lowers chi2 by the
    score ``lm``, and its new parameters cost their Occam factor, their posterior the
    inverse of ``information`` (the Fisher information of the new parameters given the
    others, in box coordinates, unit noise; scaled as :func:`log_evidence` scales). It
    ranks the refits only: the refit's own evidence decides."""
    chi2_new = max(chi2_now - lm, 0.0)
    gain = noise.log_likelihood(chi2_new) - noise.log_likelihood(chi2_now)
    info = np.atleast_2d(np.asarray(information, float))
    if info.size == 0:
        return log_z_now + gain
    lam = np.linalg.eigvalsh(0.5 * (info + info.T))
    var = noise.scale(chi2_new) * noise.tau / np.maximum(lam, 1e-300)
    return log_z_now + gain + _occam(np.diag(var))


def probabilities(log_z: dict, prior: dict) -> dict:
    """name -> posterior probability among the explanations compared (``log_z``: name ->
    log evidence, -inf for one that failed; ``prior``: name -> prior probability)."""
    keys = [k for k in log_z if np.isfinite(log_z[k])]
    if not keys:
        return {k: 0.0 for k in log_z}
    lp = np.array([log_z[k] + math.log(prior[k]) for k in keys])
    w = np.exp(lp - lp.max())
    w /= w.sum()
    out = {k: 0.0 for k in log_z}
    out.update(dict(zip(keys, map(float, w))))
    return out


def with_prior(prior: dict, cand, values: dict) -> dict:
    """The physical prior box ``prior`` of the current model's parameters with ``cand``'s
    new ones (the evidence's prior of the model extended by it)."""
    return prior | cand.prior_bounds(prior, values)


def outside_prior(result: IdentificationResult, box: dict) -> list[str]:
    """Names of ``result``'s parameters outside (or on a face of) their prior box."""
    return prior_space(result, box).out_of_bounds(result.values)
