"""What :func:`~vibid.identify.fit.strategy.identify` is asked: the measured AFC, the model
to fit to it, and how to search. Three frozen values, each with the defaults a plain
identification uses::

    identify(setup, Measurement(f, H, std))
    identify(setup, Measurement(f, H, std), search=SearchOptions(restarts=1, seed=0))
    identify(
        setup,
        Measurement(f, H, std, used=used),
        ModelChoice(forward_model=fm, bounds=box),
        SearchOptions(method="local", start=start),
    )
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from vibid.identify.fit.problem import ForwardModel

#: ``progress(label, done, total, best)``: how far a search is (generations), and its best.
Progress = Callable[[str, int, int, float], None]


@dataclass(frozen=True, eq=False)
class Measurement:
    """The measured AFC and how its points are weighed.

    Attributes
    ----------
    frequency_hz: (n,) frequencies of the AFC points, Hz.
    H: (n,) complex AFC (response over base acceleration).
    std: (n,) standard uncertainty of Re H and Im H per point, or None if unknown (then
        the fit is the paper's plain mean square error and the noise is estimated from
        the residual).
    used: (n,) bool mask of the points to fit (default all finite points).
    magnitude: fit |H| alone (the phase is not trusted): chi2 on the magnitudes, n - p
        degrees of freedom (:class:`~vibid.identify.fit.data.FitData`); the result carries
        ``magnitude_only_std_ratio``, how much each standard deviation grows against the
        complex fit of the same points.
    weights: (n_used,) standard uncertainties of Re and Im per used point to weigh chi2
        with, in place of the data's std and the model's own error (which is then not
        estimated): where the model's error barely changes chi2, the closed loop polishes
        each refit under the current fit's weights and weighs only the refit it adds with
        its own model error (:attr:`vibid.identify.loop.policy.Policy.model_error_share`).
    """

    frequency_hz: np.ndarray
    H: np.ndarray
    std: np.ndarray | None = None
    used: np.ndarray | None = None
    magnitude: bool = False
    weights: np.ndarray | None = None

    @classmethod
    def of(cls, data, *, weights: np.ndarray | None = None) -> Measurement:
        """The measurement a :class:`~vibid.identify.fit.data.FitData` holds (its points,
        std, used points and magnitude flag), to identify again."""
        return cls(data.frequency_hz, data.H, data.std, data.used, data.magnitude, weights)


@dataclass(frozen=True)
class ModelChoice:
    """The model fitted and the prior box it is searched over.

    Attributes
    ----------
    name: material model (default ``setup.identification.model``).
    forward_model: a ready ForwardModel for exactly these frequencies (or the used ones);
        by default one is built with ``vibid.identify.build_forward_model`` on the searched
        box. A wide model must have been built on a box that covers the searched one.
    bounds: prior box per parameter (default ``setup.identification.bounds``).
    kinds: transforms by parameter name that replace the catalogue's
        (:func:`~vibid.identify.fit.space.make_transform`'s ``kind``): the closed loop holds
        a resonance it placed at a diagnosed pole inside the pole's span with a logit.
    """

    name: str | None = None
    forward_model: ForwardModel | None = None
    bounds: dict | None = None
    kinds: dict | None = None


@dataclass(frozen=True)
class SearchOptions:
    """How the minimum is searched, and what a failure does.

    Attributes
    ----------
    method: ``"global"`` (differential evolution over the box, then polish by
        continuation) or ``"local"`` (one run of the local method from ``start``).
    local: the local method: ``"newton"`` (trust region, exact Hessian), ``"bfgs"``
        (trust region, BFGS) or ``"lm"`` (Levenberg-Marquardt).
    start: start values for ``method="local"`` (dict by name or array in model order;
        default the centre of the prior box).
    restarts: restarts of the global search.
    seed: seed (or Generator) of the global search: same seed, same result.
    progress: ``progress(label, done, total, best)`` called after every generation of a
        global search (a progress bar's update; the core prints nothing).
    refresh: rebuild the forward model around the estimate (``ForwardModel.refresh``) and
        polish once more on it; off, the model that searched also polishes.
    peaks_only: with ``method="global"``, search the resonance peaks alone instead of chi2
        (:func:`~vibid.identify.fit.strategy.search_peaks_only`), with the parameters that
        move no stiffness or inertia held at these values (by name; every parameter): the
        closed loop's cheap search of an orthotropic plate from an isotropic fit. The peaks
        may not tell neighbouring basins apart on a coarse grid: judge the result, and
        search chi2 (the default) when it does not fit. Falls back on chi2's search when
        the model gives no modes or the AFC no peak.
    throw: raise VibidError if the final local run did not converge (else it is reported
        in ``status``/``message``/``warnings``).
    """

    method: str = "global"
    local: str = "newton"
    start: dict | np.ndarray | None = None
    restarts: int = 5
    seed: int | np.random.Generator | None = None
    progress: Progress | None = None
    refresh: bool = True
    peaks_only: dict | None = None
    throw: bool = False
