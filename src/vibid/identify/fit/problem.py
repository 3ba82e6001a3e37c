"""Weighted least squares on the complex AFC, as a function of the coordinates ``u``.

With H_k the measured AFC at frequency f_k (k over the points kept), H(theta)_k the
model's, sigma_m,k the standard uncertainty of each of Re H_k and Im H_k from the signal
stage and sigma_f,k the forward model's own error estimate there (the part of it that no
parameter change explains, :mod:`vibid.identify.model.model_error`),

    r_k = (H(theta)_k - H_k) / sigma_k,     sigma_k^2 = sigma_m,k^2 + sigma_f,k^2,
    chi2(theta) = sum_k |r_k|^2 = sum_k (Re r_k)^2 + (Im r_k)^2,

so that for a correct model chi2 / (2 n - p) (the reduced chi-square, n points, p
parameters) is near 1. A magnitude-only fit (:attr:`FitData.magnitude`, for stands whose
phase is not trusted) sees ``r_k = (|H(theta)_k| - |H_k|) / sigma_k`` instead: one real
number per point, chi2 / (n - p). When the measurement uncertainty is not known, every sigma_k is
the RMS of |H| (the paper's plain mean square error, eq. (5.1), made dimensionless): the
minimiser is the same, and the uncertainty module then estimates the noise from the
residual instead.

The optimisers see ``chi2(theta(u))`` (:mod:`vibid.identify.fit.space`); all derivatives
are exact (JAX). A :class:`LeastSquaresProblem` is an immutable value: other weights or
other data make a new problem (:meth:`~LeastSquaresProblem.with_sigma`,
:meth:`~LeastSquaresProblem.with_data`) that shares the compiled functions.
"""

from __future__ import annotations

import functools
import logging
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import jax
import numpy as np

from vibid.errors import VibidError
from vibid.heartbeat import beat
from vibid.identify.engine.runtime import require_x64
from vibid.identify.fit.data import FitData
from vibid.identify.fit.space import ParameterSpace

log = logging.getLogger(__name__)


@runtime_checkable
class ForwardModel(Protocol):
    """What the identification needs of a forward model (vibid.identify.model.forward)."""

    parameter_names: tuple[str, ...]
    frequencies_hz: np.ndarray

    def afc(self, theta):
        """(nf,) complex AFC at the sensor for physical parameters ``theta`` (jit-able)."""

    def afc_batch(self, thetas):
        """(npop, nf) complex AFC of a population of parameter vectors."""

    def model_error(self, theta) -> np.ndarray:
        """(nf,) standard deviation of the model's own error, per Re/Im part. A model may
        also split it (:class:`SplitsModelError`); its other optional abilities are
        :class:`PlateForwardModel`, :class:`GivesModes` and :class:`SharedStructure`."""

    def refresh(self, theta) -> ForwardModel:
        """The model rebuilt around ``theta`` if it moved far from its expansion point."""


#: A problem's parameter vector is padded to one of these lengths (then to multiples of the
#: last) inside the compiled functions: problems of 1-4 parameters share one compilation,
#: 5-8 another, and a Hessian costs what the padded length costs, not the structure's.
PARAMETER_SIZES = (4, 8)


def padded_count(p: int) -> int:
    """The length a problem's ``p`` parameters are padded to (:data:`PARAMETER_SIZES`)."""
    for n in PARAMETER_SIZES:
        if p <= n:
            return n
    return -(-p // PARAMETER_SIZES[-1]) * PARAMETER_SIZES[-1]


def compile_problem(afc, magnitude: bool = False):
    """The problem's compiled functions, each of ``(u or theta, arrays, H, sig, idx, place[,
    space])`` with ``afc(arrays, theta_s) -> H`` on the model's frequencies at its
    structure's parameter vector ``theta_s``, ``idx`` the fitted points among the
    frequencies, ``place`` where the problem's (padded) parameters go in ``theta_s``
    (``base`` (p_s + 1,): ``theta_s`` with a spare last slot, ``index`` (p_pad,): each
    parameter's slot, the padding's the spare one) and ``space`` the
    :meth:`ParameterSpace.coefficients` of the padded vector. Everything a problem holds is
    an argument, so one compilation serves every problem of the same shapes: the declared
    fit and every candidate of the loop with as many parameters after padding
    (:func:`padded_count`), on a basis of the same size. Four functions:

    * ``jacobian_and_residuals(theta, ...)``: the weighted residuals' Jacobian in the
      physical parameters (forward mode: a few parameters, many residuals) and the
      residuals, from which the Fisher information follows in numpy;
    * ``value_and_grad(u, ...)``: chi2 and its gradient in ``u`` (reverse mode: one
      backward pass, where the Jacobian costs one forward pass per padded parameter; a
      trust-region step needs no more, and on a real strip's compressed problem, 8
      padded parameters, it took 0.47 ms against 1.46 ms: BENCHMARKS.md);
    * ``hessian(u, ...)``: the exact Hessian of chi2 in ``u`` (trust-region Newton);
    * ``chi2_batch(U, ...)``: chi2 of a population (global search).

    With ``magnitude`` the residuals are ``(|model| - H) / sig``, ``H`` the measured |H|
    (module doc), one per point.
    """
    import jax
    import jax.numpy as jnp

    from vibid.identify.engine.runtime import over_population
    from vibid.identify.fit.space import from_u_coefficients

    def placed(place, theta):
        return place["base"].at[place["index"]].set(theta)[:-1]

    def residuals_theta(theta, arrays, H, sig, idx, place):
        A = afc(arrays, placed(place, theta))[idx]
        if magnitude:
            return (jnp.abs(A) - H.real) / sig
        r = (A - H) / sig
        return jnp.concatenate([r.real, r.imag])

    def with_residuals(theta, arrays, H, sig, idx, place):
        r = residuals_theta(theta, arrays, H, sig, idx, place)
        return r, r

    def chi2_u(u, arrays, H, sig, idx, place, space):
        r = residuals_theta(from_u_coefficients(space, u), arrays, H, sig, idx, place)
        return jnp.sum(r * r)

    def chi2_batch(U, arrays, H, sig, idx, place, space):
        thetas = jax.vmap(placed, in_axes=(None, 0))(place, from_u_coefficients(space, U))
        A = over_population(afc)(arrays, thetas)[:, idx]  # a loop: see over_population
        r = ((jnp.abs(A) if magnitude else A) - H[None, :]) / sig[None, :]
        c = jnp.sum(r.real**2 + r.imag**2, axis=1)
        return jnp.where(jnp.isfinite(c), c, jnp.inf)

    return ProblemFunctions(
        jax.jit(jax.jacfwd(with_residuals, has_aux=True)),
        jax.jit(jax.value_and_grad(chi2_u)),
        jax.jit(jax.hessian(chi2_u)),
        jax.jit(chi2_batch),
    )


@dataclass(frozen=True)
class ProblemFunctions:
    """The compiled functions of :func:`compile_problem`."""

    jacobian_and_residuals: Callable
    value_and_grad: Callable
    hessian: Callable
    chi2_batch: Callable


@runtime_checkable
class PlateForwardModel(Protocol):
    """A forward model of a plate: its :class:`~vibid.identify.model.terms.PlateModel`
    (``param``), the prior box its reduced basis was built for and the basis's kind
    (``"wide"`` or ``"local"``)."""

    param: object
    bounds: dict
    kind: str

    def rebuilt(self, theta) -> PlateForwardModel:
        """The model on a local basis built at ``theta`` (no a-posteriori check)."""


@runtime_checkable
class SplitsModelError(Protocol):
    """A forward model that estimates its own error as a signed part and a reduction
    part (:mod:`vibid.identify.model.model_error`)."""

    def model_error_parts(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """(signed complex error (nf,), reduction std (nf,))."""


@runtime_checkable
class GivesModes(Protocol):
    """A forward model that gives the natural frequencies and peak heights of a
    population (the peak search)."""

    param: object

    def modes_batch(self, thetas):
        """((npop, n) frequencies in Hz, (npop, n) peak heights in |H|)."""

    def modes_afc_batch(self, thetas):
        """:meth:`modes_batch` and the (npop, nf) AFCs, from one evaluation of each."""


#: How many fitted problems (a kernel, on the complex AFC or its magnitude) keep their
#: compiled code.
MAX_PROBLEMS = 16


@functools.lru_cache(maxsize=MAX_PROBLEMS)
def problem_functions(kernel, magnitude: bool = False):
    """The least-squares functions of a kernel, whatever the points fitted, the data, the
    weights and the parameter space (arguments of each function:
    :func:`compile_problem`); ``magnitude``: on |H| alone."""
    from dataclasses import fields, replace

    from vibid.identify.engine.persist import Persisted, identity_of

    functions = compile_problem(kernel, magnitude)
    identity = identity_of(kernel)
    prefix = "problem.magnitude" if magnitude else "problem"
    return replace(
        functions,
        **{
            f.name: Persisted(getattr(functions, f.name), f"{prefix}.{f.name}", identity)
            for f in fields(functions)
        },
    )


@runtime_checkable
class SharedStructure(Protocol):
    """A forward model whose compiled code is shared with others: a hashable ``kernel``
    ``kernel(arrays, theta_s) -> H`` over its structure's parameter vector ``theta_s``
    (:mod:`vibid.identify.model.structure`), its own ``arrays`` and the ``embedding``
    ``(base (p_s,), index (p,))`` of its parameters in ``theta_s``."""

    kernel: Callable
    arrays: dict
    embedding: tuple


def _functions(model, magnitude: bool = False):
    """``(compiled functions, arrays, (base, index))`` for any ForwardModel: shared through
    :func:`problem_functions` by every model of one structure (the functions then take
    the structure's whole parameter vector: one compilation serves every model of the
    structure, whatever parameters it fits), else compiled for this model."""
    if isinstance(model, SharedStructure):
        return problem_functions(model.kernel, magnitude), model.arrays, model.embedding
    p = len(model.parameter_names)
    return _own_functions(model, magnitude), {}, (np.zeros(p), np.arange(p))


#: The compiled functions of models that share no structure, kept while the model lives
#: (every problem on the same model, other data or weights, reuses them).
_OWN = weakref.WeakKeyDictionary()


def _own_functions(model, magnitude: bool) -> ProblemFunctions:
    try:
        ref = weakref.ref(model)  # the compiled code must not keep its model alive
        kept = _OWN.setdefault(model, {})
    except TypeError:  # a model that cannot be weakly referenced or hashed: no cache
        return compile_problem(lambda _arrays, theta: model.afc(theta), magnitude)
    if magnitude not in kept:
        kept[magnitude] = compile_problem(lambda _arrays, theta: ref().afc(theta), magnitude)
    return kept[magnitude]


def _model_points(model, data: FitData) -> np.ndarray:
    """Indices into the model's frequencies of the fitted points."""
    fm_f = np.asarray(model.frequencies_hz, dtype=float)
    used_f = data.frequency_hz[data.used]
    if fm_f.shape == used_f.shape and np.allclose(fm_f, used_f, rtol=1e-9, atol=1e-9):
        return np.arange(used_f.size)  # model built on the kept points only
    if fm_f.shape == data.frequency_hz.shape and np.allclose(
        fm_f[data.used], used_f, rtol=1e-9, atol=1e-9
    ):
        return np.flatnonzero(data.used)
    raise VibidError("the forward model was built for other frequencies than the data")


def data_sigma(data: FitData, point_error=None) -> np.ndarray:
    """sigma_k on the fitted points from the data's std and the model's error estimate
    ``point_error`` (n_points,) (see the module doc and
    :mod:`vibid.identify.model.model_error`)."""
    H = data.H[data.used]
    if data.std is None:
        scale = float(np.sqrt(np.mean(np.abs(H) ** 2))) or 1.0
        return np.full(H.size, scale)
    sigma = data.std[data.used].astype(float)
    if point_error is not None:
        me = np.asarray(point_error, dtype=float).ravel()
        sigma = np.sqrt(sigma**2 + np.where(np.isfinite(me), me, 0.0) ** 2)
    return sigma


class LeastSquaresProblem:
    """chi2(u) of a forward model against :class:`FitData`, with exact derivatives.

    Immutable once built: all methods take and return numpy arrays; the compiled functions
    are shared by every problem of the same model structure, points and parameter space.
    ``chi2_offset``: a constant added to chi2, the part of a long AFC's chi2 that its
    compressed problem (:mod:`~vibid.identify.fit.compress`) leaves out of the residuals.
    """

    def __init__(
        self,
        model: ForwardModel,
        data: FitData,
        space: ParameterSpace,
        sigma: np.ndarray | None = None,
        chi2_offset: float = 0.0,
    ):
        require_x64()
        if tuple(model.parameter_names) != space.names:
            raise VibidError(
                f"the forward model's parameters {model.parameter_names} differ from the "
                f"fitted ones {space.names}"
            )
        self._model_idx = _model_points(model, data)
        self.model, self.data, self.space = model, data, space
        self.n_points = int(data.used.sum())
        self.n_residuals = data.n_residuals
        self.magnitude = data.magnitude
        self.n_params = space.size
        self.sigma = data_sigma(data) if sigma is None else np.asarray(sigma, float).copy()
        self.sigma.setflags(write=False)
        self.chi2_offset = float(chi2_offset)
        self._fn, self._arrays, (base, index) = _functions(model, data.magnitude)
        self._H = np.asarray(data.H[data.used], complex)
        self._idx = np.asarray(self._model_idx, np.int64)
        self._p_pad = padded_count(self.n_params)
        spare = np.full(self._p_pad - self.n_params, base.size)  # the padding's slot
        self._place = jax.device_put(
            {
                "base": np.append(np.asarray(base, float), 0.0),
                "index": np.concatenate([index, spare]).astype(np.int64),
            }
        )
        self._space = space.coefficients(self._p_pad)

    # -- other weights, data or model: new problems ---------------------------------------
    def with_sigma(self, sigma) -> LeastSquaresProblem:
        """The same problem weighted with ``sigma`` (n_points,)."""
        if np.array_equal(sigma, self.sigma):
            return self
        return LeastSquaresProblem(self.model, self.data, self.space, sigma)

    def with_weights(self, point_error=None) -> LeastSquaresProblem:
        """The problem weighted with the data's std and the model error ``point_error``."""
        return self.with_sigma(data_sigma(self.data, point_error))

    def with_model(self, model: ForwardModel) -> LeastSquaresProblem:
        """The same data and weights on another model (one rebuilt around an estimate)."""
        return (
            self
            if model is self.model
            else LeastSquaresProblem(model, self.data, self.space, self.sigma, self.chi2_offset)
        )

    def with_data(self, H, std=None) -> LeastSquaresProblem:
        """The same problem (same compiled functions) on other measured values, same points."""
        d = self.data
        H = np.abs(H) if d.magnitude else H
        data = FitData(
            d.frequency_hz,
            np.asarray(H, complex),
            None if std is None else np.asarray(std, float),
            d.used,
            d.warnings,
            d.magnitude,
        )
        return LeastSquaresProblem(self.model, data, self.space)

    def as_complex(self) -> LeastSquaresProblem:
        """The complex fit of the same points, model and weights (for a magnitude-only
        problem, the Fisher information it gives up; the measured values there are |H|,
        which the Jacobian does not depend on)."""
        if not self.magnitude:
            return self
        d = self.data
        data = FitData(d.frequency_hz, d.H, d.std, d.used, d.warnings, False)
        return LeastSquaresProblem(self.model, data, self.space, self.sigma, self.chi2_offset)

    @property
    def dof(self) -> int:
        """Degrees of freedom: the real numbers fitted (2 per point, 1 for |H| alone) minus
        the parameters."""
        return self.n_residuals - self.n_params

    # -- public evaluations (numpy in, numpy out) ---------------------------------------
    def _args(self):
        beat()  # every evaluation of the fit is progress (vibid.heartbeat's watchdog)
        return self._arrays, self._H, self.sigma, self._idx, self._place

    def _padded(self, x):
        """``x`` (last axis: the parameters) padded with zeros to the compiled length."""
        x = np.asarray(x, float)
        pad = [(0, 0)] * (x.ndim - 1) + [(0, self._p_pad - self.n_params)]
        return np.pad(x, pad)

    def jacobian_and_residuals_theta(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """d residuals / d theta and the residuals at physical ``theta``, in one call."""
        J, r = self._fn.jacobian_and_residuals(self._padded(theta), *self._args())
        return np.asarray(J)[:, : self.n_params], np.asarray(r)

    def _residuals_and_jacobian_u(self, u) -> tuple[np.ndarray, np.ndarray]:
        u = np.asarray(u, float)
        J, r = self.jacobian_and_residuals_theta(self.space.theta(u))
        return r, J * self.space.dtheta_du(u)[None, :]

    def residuals(self, u) -> np.ndarray:
        return self.residuals_theta(self.space.theta(np.asarray(u, float)))

    def residuals_theta(self, theta) -> np.ndarray:
        """The weighted residuals (real parts, then imaginary; |H|'s alone for a magnitude
        fit) at physical ``theta`` (also where ``u`` is not finite: a null value on a log
        parameter's edge)."""
        r = (self.observed(self.on_points(self.model_afc(theta))) - self._H) / self.sigma
        return r.real if self.magnitude else np.concatenate([r.real, r.imag])

    def jacobian(self, u) -> np.ndarray:
        """d residuals / d u."""
        return self._residuals_and_jacobian_u(u)[1]

    def jacobian_theta(self, theta) -> np.ndarray:
        """d residuals / d theta (physical units), for the Fisher information."""
        return self.jacobian_and_residuals_theta(theta)[0]

    def chi2(self, u) -> float:
        r = self.residuals(u)
        v = float(r @ r) + self.chi2_offset
        return v if np.isfinite(v) else np.inf

    def value_and_grad(self, u) -> tuple[float, np.ndarray]:
        """chi2 and its gradient in ``u`` (exact: one reverse-mode pass)."""
        f, g = self._fn.value_and_grad(self._padded(u), *self._args(), self._space)
        return float(f) + self.chi2_offset, np.asarray(g)[: self.n_params]

    def hessian(self, u) -> np.ndarray:
        B = self._fn.hessian(self._padded(u), *self._args(), self._space)
        return np.asarray(B)[: self.n_params, : self.n_params]

    def chi2_batch(self, U) -> np.ndarray:
        """chi2 of each row of ``U`` (npop, p) in one vectorised model call; inf if not finite."""
        c = np.asarray(self._fn.chi2_batch(self._padded(U), *self._args(), self._space))
        return c + self.chi2_offset

    def chi2_of_afc(self, A) -> np.ndarray:
        """chi2 of each row of ``A`` (npop, nf): model AFCs over the model's frequencies
        (what :meth:`chi2_batch` computes from ``U``, for AFCs evaluated already)."""
        A = self.observed(np.asarray(A)[:, self._model_idx])
        r = (A - self._H[None, :]) / self.sigma[None, :]
        with np.errstate(invalid="ignore", over="ignore"):
            c = np.sum(r.real**2 + r.imag**2, axis=1)
        return np.where(np.isfinite(c), c, np.inf) + self.chi2_offset

    def on_points(self, model_values) -> np.ndarray:
        """The fitted points' entries of an array over the model's frequencies."""
        return np.asarray(model_values)[self._model_idx]

    def observed(self, model_values) -> np.ndarray:
        """What the fit compares with the data: the model AFC, or its magnitude (complex
        dtype either way)."""
        v = np.asarray(model_values)
        return np.abs(v).astype(complex) if self.magnitude else v

    def model_afc(self, theta) -> np.ndarray:
        return np.asarray(self.model.afc(np.asarray(theta, float)))
