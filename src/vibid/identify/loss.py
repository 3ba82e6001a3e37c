"""Weighted least squares on the complex AFC, as a function of the coordinates ``u``.

With H_k the measured AFC at frequency f_k (k over the points kept), H(theta)_k the
model's, sigma_m,k the standard uncertainty of each of Re H_k and Im H_k from the signal
stage and sigma_f,k the forward model's own error estimate there (the part of it that no
parameter change explains, :mod:`vibid.identify.model_error`),

    r_k = (H(theta)_k - H_k) / sigma_k,     sigma_k^2 = sigma_m,k^2 + sigma_f,k^2,
    chi2(theta) = sum_k |r_k|^2 = sum_k (Re r_k)^2 + (Im r_k)^2,

so that for a correct model chi2 / (2 n - p) (the reduced chi-square, n points, p
parameters) is near 1. When the measurement uncertainty is not known, every sigma_k is
the RMS of |H| (the paper's plain mean square error, eq. (5.1), made dimensionless): the
minimiser is the same, and the uncertainty module then estimates the noise from the
residual instead.

The optimisers see ``chi2(theta(u))`` (:mod:`vibid.identify.params`); all derivatives are
exact (JAX), jit-compiled once per problem.
"""

from __future__ import annotations

import logging
import weakref
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np

from vibid.errors import VibidError
from vibid.identify.params import ParameterSpace

log = logging.getLogger(__name__)


@runtime_checkable
class ForwardModel(Protocol):
    """What the identification needs of a forward model (vibid.identify.forward)."""

    parameter_names: tuple[str, ...]
    frequencies_hz: np.ndarray

    def afc(self, theta):
        """(nf,) complex AFC at the sensor for physical parameters ``theta`` (jit-able)."""

    def afc_batch(self, thetas):
        """(npop, nf) complex AFC of a population of parameter vectors."""

    def model_error(self, theta) -> np.ndarray:
        """(nf,) standard deviation of the model's own error, per Re/Im part. A model may
        also offer ``model_error_parts(theta) -> (signed complex error (nf,), reduction
        std)``, which the identification then splits (:mod:`vibid.identify.model_error`)."""

    def refresh(self, theta) -> "ForwardModel":
        """The model rebuilt around ``theta`` if it moved far from its expansion point."""


@dataclass(frozen=True)
class FitData:
    """The measured AFC the fit uses: points kept, their weights, and what was dropped.

    Attributes
    ----------
    frequency_hz: (n,) frequencies of all points given.
    H: (n,) complex measured AFC (dimensionless acceleration ratio).
    std: (n,) standard uncertainty of Re H and Im H, or None when not known.
    used: (n,) bool, points that enter the fit (finite, and not excluded by the caller).
    warnings: sentences about points dropped or uncertainties repaired.
    """

    frequency_hz: np.ndarray
    H: np.ndarray
    std: np.ndarray | None
    used: np.ndarray
    warnings: tuple[str, ...] = field(default=())

    @property
    def n_used(self) -> int:
        return int(self.used.sum())

    @property
    def noise_known(self) -> bool:
        return self.std is not None


def fit_data(frequency_hz, H, std=None, used=None) -> FitData:
    """Check and clean a measured AFC; raise :class:`VibidError` when nothing usable is left."""
    f = np.asarray(frequency_hz, dtype=float).ravel()
    H = np.asarray(H).astype(complex).ravel()
    if f.shape != H.shape:
        raise VibidError(
            f"frequency_hz has {f.size} points but H has {H.size}: give one H per frequency"
        )
    mask = np.ones(f.shape, bool) if used is None else np.asarray(used, bool).ravel().copy()
    if mask.shape != f.shape:
        raise VibidError(f"'used' has {mask.size} entries for {f.size} points")
    warnings = []
    bad = ~(np.isfinite(f) & np.isfinite(H.real) & np.isfinite(H.imag)) & mask
    s = None
    if std is not None:
        s = np.asarray(std, dtype=float).ravel()
        if s.shape != f.shape:
            raise VibidError(f"std has {s.size} entries for {f.size} points")
        bad |= ~np.isfinite(s) & mask
    if bad.any():
        warnings.append(
            f"{int(bad.sum())} of {f.size} AFC points are not finite (NaN/inf in frequency, H "
            "or std) and were left out of the fit"
        )
    mask &= ~bad
    if s is not None:
        pos = s[mask] > 0
        if not pos.any():
            warnings.append(
                "every standard uncertainty of the AFC is zero: fitting without weights, "
                "the noise level is estimated from the residual"
            )
            s = None
        elif not pos.all():
            floor = float(np.min(s[mask][pos]))
            warnings.append(
                f"{int((~pos).sum())} AFC points had a zero standard uncertainty; "
                f"the smallest positive one ({floor:.3g}) was used for them"
            )
            s = np.where(s > 0, s, floor)
    if mask.sum() == 0:
        raise VibidError("no usable AFC point: every point is NaN or excluded")
    return FitData(f, H, s, mask, tuple(warnings))


#: Compiled functions of models that split into a static kernel and arrays
#: (``model.kernel(model.arrays, theta)``, vibid's ForwardModel), keyed by (kernel,
#: points used, parameter space): every model of one kernel and array shape (a model
#: rebuilt around a new estimate, another restart's local model) shares one compilation.
_COMPILED_KERNELS: dict = {}
#: Compiled functions of other models (a closure over the model), weakly keyed by model.
_COMPILED: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _compile(afc, space, model_idx):
    """jit-compiled residuals, Jacobians, chi2, its value and gradient, its Hessian, batch chi2,
    each a function of (u or theta, arrays, H, sig) with ``afc(arrays, theta) -> H``."""
    idx = jnp.asarray(model_idx)

    def residuals_theta(theta, arrays, H, sig):
        r = (afc(arrays, theta)[idx] - H) / sig
        return jnp.concatenate([r.real, r.imag])

    def residuals_u(u, arrays, H, sig):
        return residuals_theta(space.from_u(u), arrays, H, sig)

    def chi2_u(u, arrays, H, sig):
        r = residuals_u(u, arrays, H, sig)
        return jnp.sum(r * r)

    def chi2_batch(U, arrays, H, sig):
        A = jax.vmap(afc, in_axes=(None, 0))(arrays, space.from_u(U))[:, idx]
        r = (A - H[None, :]) / sig[None, :]
        c = jnp.sum(r.real**2 + r.imag**2, axis=1)
        return jnp.where(jnp.isfinite(c), c, jnp.inf)

    return (jax.jit(residuals_u), jax.jit(jax.jacfwd(residuals_u)),
            jax.jit(jax.jacfwd(residuals_theta)), jax.jit(chi2_u),
            jax.jit(jax.value_and_grad(chi2_u)), jax.jit(jax.hessian(chi2_u)),
            jax.jit(chi2_batch))


def _kernel_and_arrays(model):
    """``(afc(arrays, theta), arrays, cache, key)`` for any ForwardModel."""
    kernel = getattr(model, "kernel", None)
    if kernel is not None:
        return kernel, model.arrays, _COMPILED_KERNELS, kernel
    try:  # a plain model: close over it weakly, so that the cache does not keep it alive
        model_ref = weakref.ref(model)
        cache = _COMPILED.setdefault(model, {})
    except TypeError:
        model_ref, cache = (lambda: model), {}  # noqa: E731
    return (lambda _arrays, theta: model_ref().afc(theta)), {}, cache, None


class LeastSquaresProblem:
    """chi2(u) of a forward model against :class:`FitData`, with exact derivatives.

    All methods take and return numpy arrays; compiled functions are built once here and
    reused for every call (so a Monte Carlo over many data sets with ``with_data`` reuses
    one compilation as long as the shapes agree).
    """

    def __init__(self, model: ForwardModel, data: FitData, space: ParameterSpace):
        if tuple(model.parameter_names) != space.names:
            raise VibidError(
                f"the forward model's parameters {model.parameter_names} differ from the "
                f"fitted ones {space.names}"
            )
        fm_f = np.asarray(model.frequencies_hz, dtype=float)
        used_f = data.frequency_hz[data.used]
        if fm_f.shape == used_f.shape and np.allclose(fm_f, used_f, rtol=1e-9, atol=1e-9):
            self._model_idx = np.arange(used_f.size)  # model built on the kept points only
        elif fm_f.shape == data.frequency_hz.shape and np.allclose(
            fm_f[data.used], used_f, rtol=1e-9, atol=1e-9
        ):
            self._model_idx = np.flatnonzero(data.used)
        else:
            raise VibidError("the forward model was built for other frequencies than the data")
        self.model, self.data, self.space = model, data, space
        self._idx = np.flatnonzero(data.used)
        self.n_points = self._idx.size
        self.n_params = space.size
        self.set_weights()
        self._build()

    # -- weights ------------------------------------------------------------------------
    def set_weights(self, point_error: np.ndarray | None = None) -> None:
        """sigma_k from the data's std and the model's error estimate ``point_error``
        (n_points,) on the fitted points (see module doc and
        :mod:`vibid.identify.model_error`)."""
        d = self.data
        H = d.H[self._idx]
        if d.std is None:
            scale = float(np.sqrt(np.mean(np.abs(H) ** 2))) or 1.0
            sigma = np.full(self.n_points, scale)
        else:
            sigma = d.std[self._idx].copy()
            if point_error is not None:
                me = np.asarray(point_error, dtype=float).ravel()
                sigma = np.sqrt(sigma**2 + np.where(np.isfinite(me), me, 0.0) ** 2)
        self.sigma = sigma
        self._sig = jnp.asarray(sigma)
        self._H = jnp.asarray(H)

    def use_sigma(self, sigma: np.ndarray) -> None:
        """Weigh with ``sigma`` (n_points,) as given (another problem's final weights)."""
        self.sigma = np.asarray(sigma, float).copy()
        self._sig = jnp.asarray(self.sigma)

    @property
    def dof(self) -> int:
        """Degrees of freedom: 2 real numbers per point minus the parameters."""
        return 2 * self.n_points - self.n_params

    # -- compiled functions -------------------------------------------------------------
    def _build(self) -> None:
        afc, self._arrays, cache, kernel_key = _kernel_and_arrays(self.model)
        key = (kernel_key, self._model_idx.tobytes(), self.space)
        if key not in cache:
            cache[key] = _compile(afc, self.space, self._model_idx)
        (self._res_u, self._jac_u, self._jac_theta, self._chi2, self._vg, self._hess,
         self._batch) = cache[key]

    # -- public evaluations (numpy in, numpy out) ---------------------------------------
    def residuals(self, u) -> np.ndarray:
        return np.asarray(self._res_u(jnp.asarray(u, float), self._arrays, self._H, self._sig))

    def jacobian(self, u) -> np.ndarray:
        return np.asarray(self._jac_u(jnp.asarray(u, float), self._arrays, self._H, self._sig))

    def jacobian_theta(self, theta) -> np.ndarray:
        """d residuals / d theta (physical units), for the Fisher information."""
        return np.asarray(self._jac_theta(jnp.asarray(theta, float), self._arrays, self._H,
                                          self._sig))

    def chi2(self, u) -> float:
        v = float(self._chi2(jnp.asarray(u, float), self._arrays, self._H, self._sig))
        return v if np.isfinite(v) else np.inf

    def value_and_grad(self, u) -> tuple[float, np.ndarray]:
        v, g = self._vg(jnp.asarray(u, float), self._arrays, self._H, self._sig)
        return float(v), np.asarray(g)

    def hessian(self, u) -> np.ndarray:
        return np.asarray(self._hess(jnp.asarray(u, float), self._arrays, self._H, self._sig))

    def chi2_batch(self, U) -> np.ndarray:
        """chi2 of each row of ``U`` (npop, p) in one vectorised model call; inf if not finite."""
        return np.asarray(self._batch(jnp.asarray(U, float), self._arrays, self._H, self._sig))

    def on_points(self, model_values) -> np.ndarray:
        """The fitted points' entries of an array over the model's frequencies."""
        return np.asarray(model_values)[self._model_idx]

    def model_afc(self, theta) -> np.ndarray:
        return np.asarray(self.model.afc(jnp.asarray(theta, float)))

    def with_data(self, H, std=None) -> "LeastSquaresProblem":
        """The same problem (same compiled functions) on other measured values, same points."""
        new = object.__new__(LeastSquaresProblem)
        new.__dict__.update(self.__dict__)
        d = self.data
        new.data = FitData(d.frequency_hz, np.asarray(H, complex), None if std is None else
                           np.asarray(std, float), d.used, d.warnings)
        new.set_weights()
        return new
