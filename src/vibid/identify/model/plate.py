"""The declared plate: one object, built once from the setup, that the loop and the report ask.

A fit's later steps keep asking the model the same few things about the specimen they fit:
its natural frequencies, which of its modes the sensor sees and where they lie in the band,
a forward model rebuilt on another grid, around another estimate or with one more effect.
:class:`Plate` answers them from the declared setup, read once (its geometry: the clamp,
the sensor, the specimen's size), instead of each caller rebuilding that from the setup::

    plate = Plate(setup)
    fm = plate.forward_model(frequencies_hz, effects=("clamp_compliance",))
    modes = plate.modes(result.parameters)          # frequencies, decays, peak heights
    modes.seen, modes.q, modes.in_band(f_lo, f_hi)

:func:`build_forward_model`, :func:`natural_frequencies` and :func:`natural_mode_heights`
ask a plate built for the one question; :func:`plate_model` and :func:`plate_model_for` say
which :class:`~vibid.identify.model.terms.PlateModel` a material name or a set of parameter
names means.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from vibid.errors import VibidError
from vibid.identify.model.assembly import Geometry, model_matrices
from vibid.identify.model.forward import ForwardModel
from vibid.identify.model.materials import Material, infer_material
from vibid.identify.model.mesh import discretisation
from vibid.identify.model.modal import (
    frequencies_and_decays,
    mode_heights,
    model_eigenvalues,
    seen,
)
from vibid.identify.model.terms import PlateModel, theta_from_dict


@dataclass(frozen=True)
class Modes:
    """The first modes of a plate at one estimate: natural frequency (Hz) and decay factor
    (1/s) of the complex eigenproblem, and each real mode's peak height in |H| times the
    loss factor (:func:`~vibid.identify.model.modal.mode_heights`), in the same order."""

    frequency_hz: np.ndarray
    decay_1_per_s: np.ndarray
    height: np.ndarray

    @property
    def q(self) -> np.ndarray:
        """Each mode's quality factor ``π f / γ``."""
        return np.pi * self.frequency_hz / np.maximum(self.decay_1_per_s, 1e-30)

    @property
    def seen(self) -> np.ndarray:
        """Which modes the sensor sees (:func:`~vibid.identify.model.modal.seen`)."""
        return seen(self.height)

    def in_band(self, lo_hz: float, hi_hz: float) -> int:
        """How many of the modes lie within ``[lo_hz, hi_hz]``."""
        f = self.frequency_hz
        return int(np.count_nonzero((f >= lo_hz) & (f <= hi_hz)))


@dataclass(frozen=True)
class Plate:
    """The setup's plate (module doc): ``setup`` as declared, its geometry read once."""

    setup: object
    geometry: Geometry = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "geometry", Geometry.from_setup(self.setup))

    def forward_model(
        self,
        frequencies_hz=None,
        *,
        model=None,
        effects=(),
        theta0=None,
        bounds: dict | None = None,
        accuracy: str = "default",
        per_modulus_loss: bool = False,
        basis: str | None = None,
    ) -> ForwardModel:
        """The forward model of this plate.

        Parameters
        ----------
        frequencies_hz : (nf,) frequencies in Hz (default: the setup's excitation
            frequencies).
        model : ``"isotropic"``, ``"orthotropic"`` or ``"monoclinic"`` (default: the
            setup's), or a ready :class:`~vibid.identify.model.terms.PlateModel` (then
            ``effects`` and ``per_modulus_loss`` are its own).
        effects : effect terms or their report names (:data:`vibid.identify.effects.EFFECTS`),
            added to the material.
        theta0 : dict name -> value where the basis is built (default: the centre of the
            prior box, geometric for positive bounds).
        bounds : the prior box the basis must cover (default: the setup's, and each
            effect's default box for effect parameters the setup does not name).
        accuracy : ``"fast"``, ``"default"`` or ``"fine"``
            (:mod:`vibid.identify.model.forward`).
        per_modulus_loss : one loss factor per modulus (``beta11``, ...) instead of ``beta``.
        basis : ``"wide"`` or ``"local"`` (default: wide without ``theta0``, local with it).
        """
        setup = self.setup
        if frequencies_hz is None:
            frequencies_hz = setup.excitation.frequencies_hz
        freqs = np.asarray(frequencies_hz, float)
        if (
            freqs.ndim != 1
            or freqs.size == 0
            or not np.all(np.isfinite(freqs))
            or np.any(freqs < 0)
        ):
            raise VibidError(
                "frequencies_hz must be a non-empty list of finite frequencies >= 0 Hz"
            )
        if not isinstance(model, PlateModel):
            model = plate_model(model or setup.identification.model, per_modulus_loss, effects)
        box = model.default_bounds(dict(setup.identification.bounds if bounds is None else bounds))
        model = model.for_geometry(self.geometry)
        if theta0 is None:
            missing = [n for n in model.names if n not in box]
            if missing:
                raise VibidError(f"no bounds for {', '.join(missing)}: give theta0 or the bounds")
            th0 = _box_centre(box, model.names)
            kind = basis or "wide"
        else:
            try:
                th0 = theta_from_dict(model, theta0)
            except KeyError as exc:
                raise VibidError(str(exc.args[0])) from None
            kind = basis or "local"
        D = np.asarray(model.moduli(th0), float)
        softest = float(min(D[0], D[3]))  # D11, D22: the shorter bending wavelength
        disc = discretisation(
            self.geometry, accuracy, f_max_hz=float(freqs.max()), rigidity_n_m=softest
        )
        return ForwardModel(self.geometry, freqs, model, box, disc, th0, kind)

    def _at(self, params: dict, effects=(), accuracy: str = "default"):
        """(the plate model ``params`` name, its theta, its matrices)."""
        model = plate_model_for(params, effects).for_geometry(self.geometry)
        theta = theta_from_dict(model, params)
        disc = discretisation(self.geometry, accuracy)
        return model, theta, model_matrices(self.geometry, disc, tuple(model.effects))

    def natural_frequencies(self, params: dict, n: int = 6, *, accuracy="default", effects=()):
        """``(frequency_hz (n,), decay_1_per_s (n,))`` of the plate (with its sensor) at
        ``params``: ``√Λ = 2π f + i γ`` (paper eq. 4.1.13).

        ``params``: dict name -> value; the model follows from the names (``D, nu, beta``
        is isotropic, ``D11, D12, D22, D66, beta`` orthotropic, ...; ``beta11`` ... for one
        loss per modulus; any effect's parameters add that effect, e.g.
        ``k_theta_N_per_rad``)."""
        model, theta, mats = self._at(params, effects, accuracy)
        return frequencies_and_decays(model_eigenvalues(mats, model, theta, n))

    def mode_heights(self, params: dict, n: int = 6, *, accuracy: str = "default"):
        """``(frequency_hz (n,), height (n,))`` at ``params`` (as
        :meth:`natural_frequencies`): each real mode's peak in |H| times the loss factor
        (:func:`vibid.identify.model.modal.mode_heights`), near zero for a mode the sensor
        does not see."""
        model, theta, mats = self._at(params, (), accuracy)
        return mode_heights(mats, model, theta, n)

    def modes(self, params: dict, n: int = 12) -> Modes:
        """The first ``n`` :class:`Modes` at ``params``: :meth:`natural_frequencies` and
        :meth:`mode_heights` on one plate model and its matrices."""
        model, theta, mats = self._at(params)
        f_hz, decay = frequencies_and_decays(model_eigenvalues(mats, model, theta, n))
        _, height = mode_heights(mats, model, theta, n)
        return Modes(np.asarray(f_hz, float), np.asarray(decay, float), np.asarray(height))


def plate_model(model: str, per_modulus_loss: bool = False, effects=()) -> PlateModel:
    """The PlateModel of a material model name and effects (terms or report names)."""
    from vibid.identify.effects import EFFECTS

    try:
        material = Material(model, per_modulus_loss)
    except ValueError as exc:
        raise VibidError(str(exc)) from None
    terms = []
    for e in effects:
        if isinstance(e, str):
            if e not in EFFECTS:
                raise VibidError(f"unknown effect {e!r}, expected one of {', '.join(EFFECTS)}")
            e = EFFECTS[e]
        terms.append(e.for_material(material))
    return PlateModel(material, tuple(terms))


def plate_model_for(names, effects=()) -> PlateModel:
    """The PlateModel whose parameters are exactly ``names`` (material and effects), with
    the effects named in ``effects`` too (those without parameters of their own, such as
    ``transverse_shear`` on an isotropic plate, are added this way only). An effect that
    may occur more than once (a stand resonance) gets one instance per suffix ``_k`` among
    ``names`` (report format)."""
    from vibid.identify.effects import EFFECTS, effects_for
    from vibid.parameters import split_instance

    try:
        material = infer_material(names)
    except KeyError as exc:
        raise VibidError(str(exc.args[0])) from None
    unknown = sorted(set(effects) - set(EFFECTS))
    if unknown:
        raise VibidError(
            f"unknown effect {', '.join(unknown)}, expected one of {', '.join(EFFECTS)}"
        )
    found = {t.name for t in effects_for(names)} | set(effects)
    terms = []
    for t in EFFECTS.values():
        if t.instance is None:
            if t.name in found:
                terms.append(t.for_material(material))
            continue
        own = {split_instance(q.name)[0] for q in t.parameters}
        ks = sorted({k for base, k in map(split_instance, names) if base in own and k})
        if t.name in found and not ks:
            ks = [1]
        terms += [replace(t, instance=k) for k in ks]
    model = PlateModel(material, tuple(terms))
    unknown = sorted(set(names) - set(model.names))
    if unknown:
        raise VibidError(
            f"{', '.join(unknown)}: not a parameter of model {material.model!r} nor of any effect"
        )
    for t in model.effects:
        needs = getattr(t, "requires", None)
        if needs and needs not in model.effect_names:
            raise VibidError(f"{t.name} goes with {needs}: give its parameters too")
    return model


def _box_centre(bounds: dict, names) -> np.ndarray:
    out = []
    for n in names:
        lo, hi = bounds[n]
        out.append(math.sqrt(lo * hi) if lo > 0 and hi > 0 else 0.5 * (lo + hi))
    return np.array(out)


def build_forward_model(setup, frequencies_hz=None, **options) -> ForwardModel:
    """The forward model of a declared setup (:meth:`Plate.forward_model`)."""
    return Plate(setup).forward_model(frequencies_hz, **options)


def natural_frequencies(setup, params: dict, n: int = 6, **options):
    """Natural frequencies and decay factors of the setup's plate
    (:meth:`Plate.natural_frequencies`)."""
    return Plate(setup).natural_frequencies(params, n, **options)


def natural_mode_heights(setup, params: dict, n: int = 6, **options):
    """Mode frequencies and peak heights of the setup's plate (:meth:`Plate.mode_heights`)."""
    return Plate(setup).mode_heights(params, n, **options)
