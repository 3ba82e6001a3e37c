"""The forward model of identification: declared setup + material parameters → AFC ``H(f)``.

Interface (a setup's forward model is built by :class:`vibid.identify.model.plate.Plate`,
``Plate(setup).forward_model(frequencies_hz, ...)`` or ``build_forward_model(setup, ...)``)::

    class ForwardModel:
        parameter_names: tuple[str, ...]   # physical names, in theta order
        frequencies_hz: np.ndarray         # (nf,)
        afc(theta) -> jax.Array            # (nf,) complex128, reduced model; pure, jit-able,
                                           # differentiable to any order
        afc_batch(thetas) -> jax.Array     # (npop, nf), vmapped
        model_error(theta) -> np.ndarray   # (nf,) standard uncertainty per real/imag part
        model_error_parts(theta)           # (signed discretisation error, reduction std)
        discretisation_error(theta)        # its extrapolation: DiscretisationError
        afc_full(theta) -> np.ndarray      # (nf,) full sparse FE model, same discretisation
        afc_full_jax                       # JAX function theta -> H of the full model (1st
                                           # derivatives exact, for verification)
        check(theta) -> float              # a-posteriori reduced-vs-full error (see below)
        refresh(theta) -> ForwardModel     # local basis around theta unless this one is fine
        natural_frequencies(theta, n=6)    # full model, (frequency_hz, decay_1_per_s)

The model's physics is a :class:`~vibid.identify.model.terms.PlateModel` (``param``): the
declared material and any effects (:mod:`vibid.identify.effects`), whose parameters follow
the material's in ``theta``. Every evaluation below reads it: the reduced model, the full
sparse model and the modal solver alike.

Discretisation (``accuracy``): quintic C1 Argyris triangles on a uniform mesh refined
around the clamped corners (:mod:`vibid.identify.model.mesh`). "default" converges the first six
natural frequencies of the paper's strip to better than 1e-6 (measured against a much finer
mesh, ``benchmarks/plate.md``); "fast" to a few 1e-6; "fine" to 1e-7. A specimen larger
than the strip gets cells sized by its bending wavelength at the top of the band instead
(:func:`vibid.identify.model.mesh.discretisation`), at a similar accuracy of the modes in the band.

Reduced model (:mod:`vibid.identify.model.reduced`), two kinds of basis:

* ``"wide"`` (default when ``theta0`` is not given): modes at the centre of the prior box
  and at its faces (and its softest corner), static corrections and parameter
  sensitivities, sized to keep the whole box accurate (about 1e-7 of max |H| on the
  paper's strip; truncated to about 1e-4 for models with more than two stiffness
  parameters, see ``WIDE_TOL_MANY``); for global search.
* ``"local"`` (the default when ``theta0`` is given, and what :meth:`ForwardModel.refresh`
  builds): modes, static corrections and sensitivities at ``theta0`` only, about 20
  unknowns; error below 1e-6 of max |H| within a few per cent of ``theta0`` and 1e-5 within
  about 20 %; loss + exact Hessian in about 2 ms.

``refresh(theta)`` returns ``self`` when the basis is local and the a-posteriori check at
``theta`` (the full model at four frequencies: the two strongest resonances on the grid,
the middle and the top of the band) is within ``REFRESH_TOL`` of max |H|; otherwise a new
model with a local basis at ``theta``.

``model_error_parts(theta)``: per frequency, the discretisation error estimated as the
signed difference to a mesh-converged AFC, Richardson's extrapolation over three meshes
of one family (:meth:`ForwardModel.discretisation_error`: the next coarser, the model's,
the next finer; the order measured from the two steps, about h^6 on the paper's strip,
where the finer mesh still holds about a tenth of the model's error), and the reduction
error's standard uncertainty from the a-posteriori check (its largest relative error,
times |H|). The identification splits the first into a parameter bias and a remainder
(:mod:`vibid.identify.model.model_error`). ``model_error(theta)`` combines both into one
magnitude per frequency (divided by √2: a standard uncertainty per real and imaginary
part).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from vibid.errors import VibidError
from vibid.identify.model.assembly import Geometry, PlateMatrices, model_matrices
from vibid.identify.model.full import make_full_afc_jax, model_afc_full
from vibid.identify.model.machinery import handed, timed
from vibid.identify.model.mesh import (
    Discretisation,
    cell_ratio,
    coarser_discretisation,
    finer_discretisation,
)
from vibid.identify.model.modal import frequencies_and_decays, model_eigenvalues
from vibid.identify.model.model_error import Extrapolation, richardson
from vibid.identify.model.reduced import (
    ReducedAFC,
    ReducedBasis,
    cached_basis,
    moving_parameters,
    same_coefficients,
)
from vibid.identify.model.structure import embed, embedding
from vibid.identify.model.terms import PlateModel

log = logging.getLogger(__name__)

#: Up to this many parameters that change the mode shapes or scale (isotropic: D, nu) the
#: wide basis is kept to rounding (about 1e-7 of max |H| over the whole box: a local fit
#: on it without refresh is exact); with more (orthotropic, monoclinic, effects) it would
#: grow to some 440 unknowns, and each global-search evaluation is an eigenproblem of that
#: size, so it is truncated at a relative Gram eigenvalue of WIDE_TOL_MANY: about 1e-4 of
#: max |H| over the box, enough to find the basin; the polish runs on local bases
#: (``refresh``), accurate to 1e-6.
WIDE_FEW_PARAMETERS = 2
WIDE_TOL_MANY = 1e-6
#: The a-posteriori check's tolerance (fraction of max |H|) below which refresh keeps a basis.
REFRESH_TOL = 1e-6
#: How much softer than theta0 a local basis stays complete (stiffness ratio).
LOCAL_SCALE_RATIO = 4.0


@dataclass(frozen=True)
class DiscretisationError:
    """A model's discretisation error at one point, extrapolated over three meshes.

    ``d``: (nf,) complex, ``H_inf - H`` (the error of the model's AFC: the finer step times
    ``extrapolation.factor``); ``finer``: (nf,) the finer step ``H_f - H`` alone;
    ``meshes``: the labels of the coarser, the model's and the finer discretisation;
    ``extrapolation``: the measured ratio, order and factor
    (:class:`~vibid.identify.model.model_error.Extrapolation`)."""

    d: np.ndarray
    finer: np.ndarray
    meshes: tuple[str, str, str]
    extrapolation: Extrapolation


def _f64(x):
    """``x`` as float64 (numpy input stays numpy, so that no conversion is compiled per
    shape; JAX arrays and tracers are cast: the model is differentiable)."""
    import jax
    import jax.numpy as jnp

    return jnp.asarray(x, jnp.float64) if isinstance(x, jax.Array) else np.asarray(x, float)


@dataclass(frozen=True, eq=False)
class ForwardModel:
    """Forward model of one setup on one frequency grid; see the module docstring.

    An immutable value: its matrices and reduced basis are built (or found in their caches,
    keyed by what they depend on: :func:`~vibid.identify.model.assembly.model_matrices`,
    :func:`~vibid.identify.model.reduced.cached_basis`) when it is made, and what it
    computes later on demand (the a-posteriori check, the finer model of the error
    estimate, the full model's JAX function) is kept in small caches outside it, keyed by
    the model and the point. ``basis`` may be given (a model of the same basis on other
    frequencies, :meth:`on_frequencies`).
    """

    geometry: Geometry
    frequencies_hz: np.ndarray
    param: PlateModel
    bounds: dict
    discretisation: Discretisation
    theta0: np.ndarray
    kind: str
    basis: ReducedBasis | None = None
    mats: PlateMatrices = field(init=False, repr=False)
    _reduced: ReducedAFC = field(init=False, repr=False)
    #: ``(base, index)``: this model's parameters in its kernel's structure
    #: (:func:`vibid.identify.model.structure.embedding`), made once: every evaluation uses it
    embedding: tuple = field(init=False, repr=False)

    def __post_init__(self):
        handed().require_x64()
        set_ = functools.partial(object.__setattr__, self)
        set_("frequencies_hz", np.asarray(self.frequencies_hz, float))
        set_("theta0", np.asarray(self.theta0, float))
        set_("param", self.param.for_geometry(self.geometry))
        set_("mats", model_matrices(self.geometry, self.discretisation, tuple(self.param.effects)))
        f_max = float(self.frequencies_hz.max())
        if self.kind not in ("wide", "local"):
            raise ValueError(f"unknown basis kind {self.kind!r}")
        if self.basis is None and self.kind == "wide":
            many = len(moving_parameters(self.param, self.theta0)) > WIDE_FEW_PARAMETERS
            set_(
                "basis",
                cached_basis(
                    self.mats,
                    self.param,
                    self.theta0,
                    self.bounds,
                    f_max,
                    snapshots=True,
                    tol=WIDE_TOL_MANY if many else 1e-13,
                ),
            )
        elif self.basis is None:
            set_(
                "basis",
                cached_basis(
                    self.mats,
                    self.param,
                    self.theta0,
                    self.bounds,
                    f_max,
                    snapshots=False,
                    scale_ratio=LOCAL_SCALE_RATIO,
                ),
            )
        set_("_reduced", ReducedAFC(self.basis, self.param, 2 * np.pi * self.frequencies_hz))
        set_("embedding", embedding(self.param, self._reduced.kernel.model))

    # -- the interface ----------------------------------------------------------------
    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.param.names

    @property
    def kernel(self):
        """The reduced map's static code: ``kernel(arrays, theta) -> H`` (hashable)."""
        return self._reduced.kernel

    @property
    def arrays(self) -> dict:
        """The reduced map's arrays (a pytree): models of one kernel and shape share code."""
        return self._reduced.arrays

    def afc(self, theta):
        """(nf,) complex128 AFC of the reduced model at ``theta`` (``parameter_names``)."""
        return handed().compile(self.kernel).afc(self.arrays, embed(self.embedding, _f64(theta)))

    def afc_batch(self, thetas):
        """(npop, nf) AFCs of a population of parameter vectors."""
        return (
            handed()
            .compile(self.kernel)
            .afc_batch(self.arrays, embed(self.embedding, _f64(thetas)))
        )

    def modes_batch(self, thetas):
        """(npop, n) natural frequencies (Hz) and (npop, n) resonance peak heights in |H| of
        the reduced model for a population of parameter vectors (proportional loss), as
        numpy arrays."""
        f_hz, height = (
            handed()
            .compile(self.kernel)
            .modes_batch(self.arrays, embed(self.embedding, _f64(thetas)))
        )
        return np.asarray(f_hz), np.asarray(height)

    def modes_afc_batch(self, thetas):
        """:meth:`modes_batch` and :meth:`afc_batch` from one evaluation of each member:
        ``(f_hz, height, H)``, numpy arrays."""
        f_hz, height, H = (
            handed()
            .compile(self.kernel)
            .modes_afc_batch(self.arrays, embed(self.embedding, _f64(thetas)))
        )
        return np.asarray(f_hz), np.asarray(height), np.asarray(H)

    def afc_full(self, theta) -> np.ndarray:
        """(nf,) AFC of the full sparse FE model (same discretisation) at ``theta``."""
        return model_afc_full(self.mats, self.param, theta, self.frequencies_hz)

    @property
    def afc_full_jax(self):
        """JAX ``theta -> H`` of the full model (first derivatives exact)."""
        return _full_afc_jax(self.mats, self.param, self.frequencies_hz.tobytes())

    def check_frequencies(self, theta, H=None) -> np.ndarray:
        """Indices of the grid frequencies used by the a-posteriori check: the two highest
        local maxima of ``|H|`` (``H``: the reduced AFC at ``theta``, computed if not
        given), the middle of the grid and its end."""
        mag = np.abs(np.asarray(self.afc(theta) if H is None else H))
        inner = np.arange(1, mag.size - 1)
        peaks = inner[(mag[1:-1] >= mag[:-2]) & (mag[1:-1] >= mag[2:])]
        peaks = peaks[np.argsort(-mag[peaks], kind="stable")][:2]
        return np.array(sorted(set(peaks.tolist()) | {mag.size // 2, mag.size - 1}))

    def _check_points(self, theta):
        """(reduced AFC on the grid, check indices, full AFC at them), kept for the last
        few (model, theta): ``refresh`` checks at the estimate and ``reduction_error`` then
        asks again at the same point, and each asks four sparse solves of the full model."""
        return _check_points(self, np.asarray(theta, float).tobytes())

    def check(self, theta) -> float:
        """Reduced-vs-full error at the check frequencies, as a fraction of max |H|."""
        Hr, idx, Hf = self._check_points(theta)
        return float(np.abs(Hr[idx] - Hf).max() / np.abs(Hr).max())

    def reduction_error(self, theta) -> np.ndarray:
        """(nf,) standard uncertainty of the reduction error per real and imaginary part:
        the check's largest relative error ``|H_r − H_full| / |H_full|`` over its
        frequencies, times ``|H|`` at each frequency, over √2 (its sign is unknown). On
        the paper's strip this bounds the true error at every frequency, where the
        check's absolute maximum, applied everywhere, exceeded the AFC's own noise away
        from the resonances by a factor of three."""
        Hr, idx, Hf = self._check_points(theta)
        rel = float(np.max(np.abs(Hr[idx] - Hf) / np.maximum(np.abs(Hf), 1e-300)))
        return rel * np.abs(Hr) / math.sqrt(2.0)

    def refresh(self, theta) -> ForwardModel:
        """A model whose basis is local to ``theta``: ``self`` if it already is (built at
        ``theta``'s stiffness and inertia coefficients, or passing the a-posteriori check
        there), else a new one built at ``theta``."""
        theta = np.asarray(theta, float)
        if self.kind == "local" and not self._built_at(theta):
            err = self.check(theta)
            if err <= REFRESH_TOL:
                return self
            log.info("refresh: reduced error %.1e at theta; rebuilding the basis", err)
        return self.rebuilt(theta)

    def rebuilt(self, theta) -> ForwardModel:
        """The model on a local basis built at ``theta``, without the a-posteriori check:
        ``self`` if its basis was built there (where a start moves a stiffness far, the
        check fails all but always and costs what the basis costs)."""
        theta = np.asarray(theta, float)
        if self._built_at(theta):
            return self
        return ForwardModel(
            self.geometry,
            self.frequencies_hz,
            self.param,
            self.bounds,
            self.discretisation,
            theta,
            "local",
        )

    def _built_at(self, theta) -> bool:
        """Whether this model's basis is local and built at ``theta``'s stiffness and
        inertia coefficients (a rebuild would give it again)."""
        return self.kind == "local" and same_coefficients(self.param, theta, self.theta0)

    def on_frequencies(self, frequencies_hz) -> ForwardModel:
        """The same model (same basis) on other frequencies inside this one's band, Hz."""
        f = np.asarray(frequencies_hz, float)
        if f.size == 0 or f.max() > self.frequencies_hz.max() * (1 + 1e-12):
            raise VibidError("on_frequencies: the new frequencies must lie in the model's band")
        return replace(self, frequencies_hz=f, basis=self.basis)

    @timed("model error")
    def model_error_parts(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """``(d, reduction)``: the signed discretisation error ``H_inf − H`` (nf,) complex
        (:meth:`discretisation_error`) and the reduction error's standard uncertainty per
        real and imaginary part (nf,) (:meth:`reduction_error`; its sign is unknown)."""
        return self.discretisation_error(theta).d, self.reduction_error(theta)

    def discretisation_error(self, theta) -> DiscretisationError:
        """The discretisation error of the AFC at ``theta`` against Richardson's
        extrapolation over the next coarser, this and the next finer mesh (each a local
        basis at ``theta``; :func:`~vibid.identify.model.model_error.richardson`): the
        finer step ``H_f − H`` alone leaves out the finer mesh's own error, about a tenth
        of the model's on the paper's strip. Kept for the last few (model, theta): the
        identification asks once after its fit, and the planner at its design's centre.
        The coarser mesh costs a tenth of the finer one (0.3 against 1 s on the strip)."""
        return _discretisation_error(self, np.asarray(theta, float).tobytes())

    def _level_afc(self, disc: Discretisation, theta) -> np.ndarray:
        """The AFC at ``theta`` of this model on another discretisation (a local basis)."""
        other = ForwardModel(
            self.geometry, self.frequencies_hz, self.param, self.bounds, disc, theta, "local"
        )
        return np.asarray(other.afc(theta))

    def model_error(self, theta) -> np.ndarray:
        """(nf,) standard uncertainty of the model error per real and imaginary part:
        ``|d|`` and the reduction error of :meth:`model_error_parts` combined in quadrature
        and divided by √2 (the error is shared by the two parts). The identification
        uses the parts instead (:mod:`vibid.identify.model.model_error`)."""
        d, red = self.model_error_parts(theta)
        return np.sqrt(np.abs(d) ** 2 / 2.0 + red**2)

    def natural_frequencies(self, theta, n: int = 6):
        """``(frequency_hz, decay_1_per_s)`` of the first ``n`` modes (full model)."""
        return frequencies_and_decays(model_eigenvalues(self.mats, self.param, theta, n))


#: How many (model, theta) a-posteriori checks are kept.
MAX_CHECKS = 8


@functools.lru_cache(maxsize=MAX_CHECKS)
def _check_points(model: ForwardModel, theta_bytes: bytes):
    theta = np.frombuffer(theta_bytes, float)
    Hr = np.asarray(model.afc(theta))
    idx = model.check_frequencies(theta, Hr)
    Hf = model_afc_full(model.mats, model.param, theta, model.frequencies_hz[idx])
    return Hr, idx, Hf


@functools.lru_cache(maxsize=4)
def _discretisation_error(model: ForwardModel, theta_bytes: bytes) -> DiscretisationError:
    theta = np.frombuffer(theta_bytes, float)
    own = model.discretisation
    fine, coarse = finer_discretisation(own), coarser_discretisation(own)
    H = np.asarray(model.afc(theta))
    H_fine = model._level_afc(fine, theta)
    # no coarser mesh (two cells a side): the slowest order trusted bounds the error
    H_coarse = None if coarse == own else model._level_afc(coarse, theta)
    ext = richardson(H_coarse, H, H_fine, cell_ratio(fine, own), cell_ratio(coarse, own))
    if ext.limited:
        log.warning(
            "the discretisation %s converges slower than h^%g between %s and %s: "
            "its error is bounded with that order",
            own.label,
            ext.order,
            coarse.label,
            fine.label,
        )
    log.info(
        "discretisation error of %s: order %.3g from %s and %s, the finer step times %.4g",
        own.label,
        ext.order,
        coarse.label,
        fine.label,
        ext.factor,
    )
    finer = H_fine - H
    d = ext.factor * finer
    for a in (d, finer):  # shared by every caller of the cache
        a.setflags(write=False)
    return DiscretisationError(d, finer, (coarse.label, own.label, fine.label), ext)


@functools.lru_cache(maxsize=4)
def _full_afc_jax(mats, param: PlateModel, frequencies_bytes: bytes):
    return make_full_afc_jax(mats, param, np.frombuffer(frequencies_bytes, float))
