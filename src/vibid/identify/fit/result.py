"""Typed results of the identification: why each optimiser stopped, its history, the answer.

Every status maps to a sentence that tells the person at the stand what happened and what
to do (the shape of optimistix's ``RESULTS``; the words are the report's,
:mod:`vibid.report.wording`); nothing is returned without one, and a run that did not
converge says so.

A run the optimiser calls converged is no converged estimate where it stopped at the end of
a parameter's physical range (:func:`physical_ends`: a positive stiffness at ~0, Poisson's
ratio at −1 or 0.5): no plate is there, so the data do not hold the model's structure (an
AFC without the plate's response, a wrong setup); its status is then
:attr:`Status.AT_PHYSICAL_LIMIT`. The end of the physical range is not the prior box's edge:
an estimate on or outside its box is a warning of its own (the box may exclude the truth),
and may well be converged.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


class Status(enum.Enum):
    """Why a local optimiser stopped."""

    CONVERGED = "converged"
    MAX_ITERATIONS = "max_iterations"
    STALLED = "stalled"
    NOT_FINITE = "not_finite"
    AT_PHYSICAL_LIMIT = "at_physical_limit"
    FAILED = "failed"

    @property
    def ok(self) -> bool:
        return self is Status.CONVERGED

    def sentence(self, detail: str = "") -> str:
        """What this status says (:func:`vibid.report.wording.status_sentence`)."""
        from vibid.report.wording import status_sentence

        return status_sentence(self, detail)


#: A parameter in an interval (Poisson's ratio in (−1, 0.5)) within this fraction of the
#: interval's width from one of its ends is at that end: where an optimiser ran its logit
#: coordinate off to infinity (no fit of a plate puts ν within 1.5e-6 of −1 or 0.5).
INTERVAL_END_RTOL = 1e-6
#: A positive parameter at most this fraction of its prior box's lower edge is at 0: three
#: decades softer than the softest the box allows is no plate (an all-zero AFC ran a strip's
#: D, box 1-100 N m, to 2.7e-5 N m in a toy model, 3e-12 N m in the plate model:
#: ``tests/test_fit_status.py``).
POSITIVE_END_RTOL = 1e-3


def physical_end(rule, value: float, low: float, high: float) -> float | None:
    """The end of the physical range that ``value`` lies at (or beyond), or None: for the
    rule ``"positive"`` (:attr:`vibid.parameters.Parameter.rule`) 0 where ``value`` is at
    most :data:`POSITIVE_END_RTOL` of the prior box ``[low, high]``'s lower edge (of its
    upper edge where the lower is not positive); for ``("interval", a, b)`` a or b where
    ``value`` lies within :data:`INTERVAL_END_RTOL` of the interval's width of it; None for
    any other rule (a non-negative loss factor or mass at 0 is a possible plate)."""
    if rule == "positive":
        scale = low if low > 0 else high
        return 0.0 if value <= POSITIVE_END_RTOL * abs(scale) else None
    if isinstance(rule, tuple) and rule and rule[0] == "interval":
        a, b = float(rule[1]), float(rule[2])
        tol = INTERVAL_END_RTOL * (b - a)
        return a if value <= a + tol else b if value >= b - tol else None
    return None


def physical_ends(space, theta) -> dict[str, float]:
    """name -> the end of its physical range, for the parameters of ``space`` (a
    :class:`~vibid.identify.fit.space.ParameterSpace`: its transforms' names and prior
    boxes) whose value in ``theta`` lies at it (:func:`physical_end`, the rule of the
    parameter catalogue, :mod:`vibid.parameters`)."""
    from vibid.parameters import known_parameter

    out = {}
    for t, v in zip(space.transforms, np.asarray(theta, float)):
        q = known_parameter(t.name)
        end = None if q is None else physical_end(q.rule, float(v), t.low, t.high)
        if end is not None:
            out[t.name] = end
    return out


def final_status(best, space, theta, chi2: float) -> tuple[Status, str]:
    """(status, sentence) of the identification whose best local run is ``best`` and whose
    estimate ``theta`` has the loss ``chi2``: the run's own, unless its estimate or loss is
    not finite (:attr:`Status.NOT_FINITE`) or a converged run stopped at the end of a
    parameter's physical range (:attr:`Status.AT_PHYSICAL_LIMIT`, naming each)."""
    theta = np.asarray(theta, float)
    if not (np.all(np.isfinite(theta)) and np.isfinite(chi2)):
        bad = [n for n, v in zip(space.names, theta) if not np.isfinite(v)]
        what = f"{', '.join(bad)} not finite" if bad else f"chi2 = {chi2}"
        return Status.NOT_FINITE, f"{best.method}: {Status.NOT_FINITE.sentence(what)}"
    if best.status.ok and (ends := physical_ends(space, theta)):
        at = ", ".join(
            f"{n} = {v:.6g} at {ends[n]:g}" for n, v in zip(space.names, theta) if n in ends
        )
        return (Status.AT_PHYSICAL_LIMIT, f"{best.method} {Status.AT_PHYSICAL_LIMIT.sentence(at)}")
    return best.status, f"{best.method} {best.message}"


@dataclass(frozen=True)
class HistoryEntry:
    """One iteration of a local optimiser.

    ``loss`` is chi2 at ``theta`` (the current iterate, physical units); ``step`` the norm
    of the trial step in ``u``; ``radius`` the trust radius it was taken in (None where
    the method has none); ``ratio`` actual over predicted decrease; ``accepted`` whether
    the iterate moved.
    """

    iteration: int
    loss: float
    theta: tuple[float, ...]
    step: float | None
    radius: float | None
    ratio: float | None = None
    accepted: bool | None = None


@dataclass(frozen=True)
class LocalResult:
    """The result of one local optimisation in the coordinates of a ParameterSpace."""

    method: str
    u: np.ndarray
    theta: np.ndarray
    loss: float
    status: Status
    message: str
    n_iterations: int
    n_evaluations: int
    history: tuple[HistoryEntry, ...] = field(default=())

    @property
    def converged(self) -> bool:
        return self.status.ok


@dataclass(frozen=True)
class GlobalResult:
    """Differential evolution: the best point of each restart (sorted, best first)."""

    u: np.ndarray  # (restarts, p)
    theta: np.ndarray  # (restarts, p)
    loss: np.ndarray  # (restarts,) the search objective at each
    n_evaluations: int
    messages: tuple[str, ...]


@dataclass(frozen=True)
class DiscretisationInfo:
    """How the model's discretisation error (the one ``model_error_bias`` comes from) was
    estimated: ``meshes``, the labels of the next coarser, the model's and the next finer
    mesh; ``order``, the measured ``p`` of ``C h^p``; ``factor``, the model's error over the
    finer step alone; ``limited``, whether the order was held at the slowest one trusted
    (:class:`~vibid.identify.model.model_error.Extrapolation`)."""

    meshes: tuple[str, ...]
    order: float
    factor: float
    limited: bool = False

    @classmethod
    def of(cls, error) -> DiscretisationInfo:
        """From a forward model's
        :class:`~vibid.identify.model.forward.DiscretisationError`."""
        ext = error.extrapolation
        return cls(
            tuple(str(m) for m in error.meshes),
            float(ext.order),
            float(ext.factor),
            bool(ext.limited),
        )


@dataclass(frozen=True)
class IdentificationResult:
    """The identified parameters of one model with their uncertainty and provenance.

    Attributes
    ----------
    parameter_names: the parameters, in order.
    values, std: (p,) estimates and standard deviations (physical units; nan if unknown).
    covariance, correlation: (p, p).
    chi2, chi2_reduced: weighted sum of squared residuals, and over its degrees of freedom.
    rel_rms_residual: RMS |H_model - H| over RMS |H|, on the points used.
    status: Status of the final local run; ``message`` the sentence for the user.
    noise_known: whether the AFC's standard uncertainty was given (else it was estimated
        from the residual, and ``chi2_reduced`` is 1 by construction of that estimate's
        scale: see vibid.identify.fit.uncertainty).
    global_result: the global search, if one ran.
    local_results: every local run (polishes of several candidates), best first.
    warnings: sentences about the data, bounds, identifiability.
    model_error_bias: (p,) the shift of the estimate that the forward model's own
        discretisation error causes, to first order (:mod:`vibid.identify.model.model_error`);
        ``covariance`` includes it as the systematic term bias bias^T. None when the model
        gives no signed error estimate or the noise is unknown.
    discretisation: how that error was estimated (:class:`DiscretisationInfo`: the three
        meshes, the measured order and factor); None where ``model_error_bias`` is, or the
        model gives no extrapolation.
    chi2_reduced_data_weights: the reduced chi2 with the signal stage's standard
        uncertainties alone as weights (``chi2_reduced`` also weighs the model's
        unexplained error); nan when they are unknown.
    model_afc: (n,) the model AFC at the estimate on all given frequencies (nan where a
        point was not used).
    weights: (n_used,) the standard uncertainties chi2 was weighted with on the used points
        (the data's, with the model's unexplained error).
    plate_model: the :class:`~vibid.identify.model.terms.PlateModel` fitted (None for a
        forward model that has none).
    magnitude: the fit saw |H| alone: ``H`` and ``model_afc`` then hold magnitudes (real,
        in complex arrays) and ``dof`` is n - p.
    magnitude_only_std_ratio: for a magnitude-only fit, each parameter's standard deviation
        over the complex fit's of the same points (both Fisher informations); else None.
    rivals: the other minima that fit the data about as well (parameter vectors in
        ``parameter_names`` order): the covariance includes their spread.
    """

    model: str
    parameter_names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    chi2: float
    chi2_reduced: float
    dof: int
    rel_rms_residual: float
    status: Status
    message: str
    noise_known: bool
    frequency_hz: np.ndarray
    H: np.ndarray
    H_std: np.ndarray | None
    used: np.ndarray
    model_afc: np.ndarray
    global_result: GlobalResult | None = None
    local_results: tuple[LocalResult, ...] = field(default=())
    warnings: tuple[str, ...] = field(default=())
    seconds: float = float("nan")
    model_error_bias: np.ndarray | None = None
    chi2_reduced_data_weights: float = float("nan")
    weights: np.ndarray | None = None
    plate_model: object = None
    magnitude: bool = False
    magnitude_only_std_ratio: dict[str, float] | None = None
    rivals: tuple = ()
    discretisation: DiscretisationInfo | None = None

    @property
    def weighted_residuals(self) -> np.ndarray:
        """(model - data) / weights on the used points, as the fit saw them: real parts,
        then imaginary parts; the magnitudes' alone for a magnitude-only fit."""
        u = np.asarray(self.used)
        r = (self.model_afc[u] - self.H[u]) / self.weights
        return r.real if self.magnitude else np.concatenate([r.real, r.imag])

    @property
    def converged(self) -> bool:
        return self.status.ok

    @property
    def chi2_reduced_reported(self) -> float:
        """The reduced chi2 a report prints: with the data's standard uncertainties alone as
        weights (the model's own error is reported beside it, not in it); the fit's own
        where the data's are unknown."""
        v = self.chi2_reduced_data_weights
        return float(v) if np.isfinite(v) else float(self.chi2_reduced)

    @property
    def parameters(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.parameter_names, self.values)}

    @property
    def parameter_std(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.parameter_names, self.std)}

    @property
    def history(self) -> tuple[HistoryEntry, ...]:
        """The history of the local run that gave the answer."""
        return self.local_results[0].history if self.local_results else ()

    def summary(self) -> str:
        """A few lines for the console."""
        lines = [f"model {self.model}: {self.message}"]
        for n, v, s in zip(self.parameter_names, self.values, self.std):
            lines.append(f"  {n:>6} = {v:.6g} +- {s:.2g}")
        lines.append(
            f"  chi2_reduced = {self.chi2_reduced:.4g}, rel_rms_residual = "
            f"{self.rel_rms_residual:.3g}"
        )
        if self.magnitude_only_std_ratio is not None:
            lines.append(
                "  fitted on |H| alone: each std against the complex fit's, "
                + ", ".join(f"{n} x{r:.2g}" for n, r in self.magnitude_only_std_ratio.items())
            )
        if self.model_error_bias is not None:
            lines.append(
                "  model's discretisation bias (in the std): "
                + ", ".join(
                    f"{n} {abs(b):.2g}" for n, b in zip(self.parameter_names, self.model_error_bias)
                )
            )
        lines.extend(f"  warning: {w}" for w in self.warnings)
        return "\n".join(lines)
