"""Model terms: the plate model as a composable list of physical terms.

A term is one physical ingredient of the forward model: the material law (its moduli and
loss factors), an elastic clamp, a point mass, a delay between the channels, ... A term
declares its :class:`Parameter` s (name, unit, transform, default prior box, null value)
and what it contributes, any of:

* ``stiffness(p, xp) -> {matrix name: (storage coefficient, loss factor or None)}``: the
  term scales stiffness matrices affinely, ``K = Σ s_k (1 + i β_k) K_k``; a loss factor
  of None is the material's common one (the term dissipates like the plate, so the
  modes stay real);
* ``inertia(p, xp) -> {matrix name: coefficient}``: the same for inertia matrices (their
  rigid-translation load follows);
* ``assemble(ctx) -> {matrix name: sparse matrix on all dofs}``: its own matrices,
  assembled once with scikit-fem (:class:`~vibid.identify.model.assembly.AssemblyContext`);
* ``released``: names of the clamp's degrees of freedom that it frees;
* ``probe(p, xp) -> {probe name: coefficient}``: the term adds probe vectors (assembled by
  ``assemble``) to the declared sensor's, ``c = c_sensor + Σ_k c_k(p) c_k`` (a sensor
  that is not where the setup says);
* ``loss_factors(p, xp) -> {matrix name: loss factor}``: a loss factor of its own for
  another term's stiffness matrix (a clamp that dissipates unlike the plate); such a term
  sets ``proportional = False`` (the modes are then complex);
* ``scales(p, xp) -> {matrix name: factor}``: factors on other terms' stiffness or inertia
  coefficients (a stretch of the plate along x scales each bending matrix by a power of
  the stretch);
* ``loss_law(p, omega, xp) -> (nf,)``: a frequency law multiplying every loss factor;
* ``base_rotation(p, omega, xp) -> (nf,) complex``: a rotation of the base about the clamp
  line, in rad per metre of base translation (a stand's own resonance); such a term sets
  ``rotates_base = True`` and the AFC becomes ``H_translation + Σ θ(ω) H_rotation``;
* ``afc_map(p, omega, H, xp) -> H``: a map applied to the plate's AFC (delay, gain).

``p`` is the dict of every parameter of the model by name (values or JAX tracers) and
``xp`` the array namespace (numpy or jax.numpy), so one definition serves the full sparse
solver, the modal solver and the reduced JAX model alike.

:class:`PlateModel` composes a material with effects into one immutable (hashable) value:
the parameter vector ``theta`` is the material's parameters followed by each effect's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vibid.parameters import Parameter


class Term:
    """Base of every term: contributes nothing. Subclasses are frozen dataclasses (hashable:
    a model's compiled code is shared by every model of the same terms)."""

    name = ""
    #: what the term is, in a lab's words (the report's list of effects found)
    meaning = ""
    parameters: tuple[Parameter, ...] = ()
    #: names of the stiffness and inertia matrices it scales (keys of its contributions)
    stiffness_matrices: tuple[str, ...] = ()
    inertia_matrices: tuple[str, ...] = ()
    probe_vectors: tuple[str, ...] = ()
    released: tuple[str, ...] = ()
    #: False for a term that gives a stiffness matrix a loss factor of its own
    proportional = True
    #: True for a term with a ``base_rotation``
    rotates_base = False
    #: False for a term that costs its structure's code something even when absent (a
    #: non-proportional loss, a second load): only models that have it carry it
    #: (:mod:`vibid.identify.model.structure`)
    in_every_structure = True
    #: which instance of an effect that may occur more than once (None: it may not)
    instance = None
    #: the effect a model must have before this one can be added (a clamp's own loss
    #: needs the clamp's spring)
    requires = None
    #: effects it cannot share a model with (the shear field's mass would no longer be
    #: the plate's: a stretched mesh, a moved sensor disc)
    excludes: tuple[str, ...] = ()
    #: the residual's features (:mod:`vibid.identify.loop.diagnosis`) it can explain (the
    #: pole a resonance is placed at first, :meth:`placed_at`)
    explains: tuple[str, ...] = ("mode_shift",)
    #: True for an effect whose new parameters need a place to start (a resonance: its
    #: frequency and Q have no null): the loop tries it at each diagnosed pole and at the
    #: residual's maxima along the band
    needs_feature = False
    #: which of its parameters (unsuffixed names) the diagnosed feature places, and by
    #: which of the feature's values (``"f_hz"``, ``"q"``): the loop starts them there and
    #: holds them within its span of them
    feature_places: dict = {}
    #: True for an effect that changes only H's phase (a delay between the channels): a fit
    #: of |H| alone cannot see it, and its loop does not try it
    phase_only = False

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def stiffness(self, p: dict, xp) -> dict:
        return {}

    def inertia(self, p: dict, xp) -> dict:
        return {}

    def assemble(self, ctx) -> dict:
        return {}

    def probe(self, p: dict, xp) -> dict:
        return {}

    def loss_factors(self, p: dict, xp) -> dict:
        return {}

    def scales(self, p: dict, xp) -> dict:
        return {}

    def loss_law(self, p: dict, omega, xp):
        return None

    def base_rotation(self, p: dict, omega, xp):
        return None

    def afc_map(self, p: dict, omega, H, xp):
        return H

    def placed_at(self, diagnosis):
        """The diagnosed feature (:mod:`vibid.identify.loop.diagnosis`) that places a term that
        ``needs_feature``: the most significant one it explains, or None."""
        found = [f for f in diagnosis.features if set(f.kinds) & set(self.explains)]
        return max(found, key=lambda f: f.significance, default=None)

    def for_material(self, material) -> Term:
        """This term's form for a plate of ``material`` (a term whose parameters depend on
        the material, e.g. the transverse shear, returns its variant)."""
        return self

    def null_values(self, values: dict) -> dict:
        """Its parameters at which it vanishes, given the model's ``values``: each one's
        null (a parameter without a fixed null, a resonance's frequency, has none)."""
        return {q.name: q.null for q in self.parameters if q.null is not None}

    def for_geometry(self, geometry) -> Term:
        """This term bound to a plate's geometry (a term whose coefficients need the
        declared dimensions, e.g. a stretch of the free length, returns its bound form)."""
        return self


#: The six bending moduli (N·m), names of the plate's bending stiffness matrices
#: (:mod:`vibid.identify.model.forms`), in the order of the session format.
MODULI = ("D11", "D12", "D16", "D22", "D26", "D66")

#: The inertia matrices every plate has (coefficient 1): the plate's own, and the
#: declared sensor's (:mod:`vibid.identify.model.assembly`).
BASE_INERTIA = ("plate", "sensor")

#: The probe every plate has (coefficient 1): the declared sensor's centre.
BASE_PROBE = ("sensor",)


@dataclass(frozen=True)
class PlateModel:
    """The parameterised plate: a material term and effect terms, immutable.

    Attributes
    ----------
    material : the material term (:mod:`vibid.identify.model.materials`).
    effects : effect terms (:mod:`vibid.identify.effects`), in the order added.
    """

    material: Term
    effects: tuple = field(default=())

    # -- the catalogue ------------------------------------------------------------------
    @property
    def terms(self) -> tuple:
        return (self.material,) + tuple(self.effects)

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return tuple(q for t in self.terms for q in t.parameters)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(q.name for q in self.parameters)

    @property
    def model(self) -> str:
        """The material model's name (``"isotropic"``, ...)."""
        return self.material.model

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.effects)

    @property
    def proportional(self) -> bool:
        """True when every stiffness term shares one loss factor (real modes exist)."""
        return self.material.proportional and all(t.proportional for t in self.effects)

    @property
    def rotates_base(self) -> bool:
        """True when a term rotates the base (the AFC then needs the rotation's load)."""
        return any(t.rotates_base for t in self.effects)

    def with_effect(self, term: Term) -> PlateModel:
        """This model with one more effect (a new value; this one is unchanged). An effect
        it has already (the same instance of it) is not added twice."""
        if any((t.name, t.instance) == (term.name, term.instance) for t in self.effects):
            return self
        return PlateModel(self.material, tuple(self.effects) + (term.for_material(self.material),))

    def without_effect(self, term: Term) -> PlateModel:
        """This model less one effect (that instance of it)."""
        return PlateModel(
            self.material,
            tuple(t for t in self.effects if (t.name, t.instance) != (term.name, term.instance)),
        )

    def for_geometry(self, geometry) -> PlateModel:
        """This model with each term bound to ``geometry``
        (:class:`~vibid.identify.model.assembly.Geometry`; see :meth:`Term.for_geometry`)."""
        effects = tuple(t.for_geometry(geometry) for t in self.effects)
        return self if effects == tuple(self.effects) else PlateModel(self.material, effects)

    def with_material(self, material) -> PlateModel:
        """This model's effects on another material (each in its form for that material)."""
        return PlateModel(material, tuple(t.for_material(material) for t in self.effects))

    # -- matrices and their coefficients at theta ------------------------------------------
    @property
    def stiffness_names(self) -> tuple[str, ...]:
        """Stiffness matrices in the order of :meth:`moduli`: the material's six bending
        matrices, then the effects' own."""
        return tuple(dict.fromkeys(k for t in self.terms for k in t.stiffness_matrices))

    @property
    def inertia_names(self) -> tuple[str, ...]:
        return tuple(
            dict.fromkeys(BASE_INERTIA + tuple(k for t in self.effects for k in t.inertia_matrices))
        )

    @property
    def probe_names(self) -> tuple[str, ...]:
        return tuple(
            dict.fromkeys(BASE_PROBE + tuple(k for t in self.effects for k in t.probe_vectors))
        )

    def values(self, theta) -> dict:
        """``{name: theta[i]}`` (entries of a numpy or JAX vector)."""
        return {n: theta[i] for i, n in enumerate(self.names)}

    def _stiffness_terms(self, theta, xp):
        p = self.values(theta)
        common = self.material.common_loss(p)
        entries = {}
        for t in self.terms:
            for k, (s, b) in t.stiffness(p, xp).items():
                entries[k] = (s, common if b is None else b)
        for t in self.effects:
            for k, b in t.loss_factors(p, xp).items():
                if k in entries:
                    entries[k] = (entries[k][0], b)
        storage = self._scaled({k: v[0] for k, v in entries.items()}, p, xp)
        entries = {k: (storage[k], v[1]) for k, v in entries.items()}
        zero = 0.0 * theta[0]
        names = self.stiffness_names
        s = xp.stack([xp.asarray(entries[k][0]) + zero for k in names])
        b = xp.stack([xp.asarray(entries[k][1]) + zero for k in names])
        return s, b

    def moduli(self, theta, xp=np):
        """(T,) storage coefficients of :attr:`stiffness_names` (N·m for the moduli)."""
        return self._stiffness_terms(theta, xp)[0]

    def losses(self, theta, xp=np):
        """(T,) loss factors of :attr:`stiffness_names` (at the loss law's reference)."""
        return self._stiffness_terms(theta, xp)[1]

    def complex_moduli(self, theta, xp=np):
        """``s_k (1 + i β_k)``, the complex coefficients of the stiffness matrices."""
        s, b = self._stiffness_terms(theta, xp)
        return s * (1.0 + 1j * b)

    def common_loss(self, theta, xp=np):
        """The loss factor shared by every term of a proportional model."""
        return self.material.common_loss(self.values(theta)) + 0.0 * theta[0]

    def inertia(self, theta, xp=np):
        """(S,) coefficients of :attr:`inertia_names` (1 for the plate and the sensor)."""
        return self._effect_coefficients(theta, xp, BASE_INERTIA, self.inertia_names, "inertia")

    def probe(self, theta, xp=np):
        """(P,) coefficients of :attr:`probe_names` (1 for the declared sensor)."""
        return self._effect_coefficients(theta, xp, BASE_PROBE, self.probe_names, "probe")

    def _effect_coefficients(self, theta, xp, base, names, contribution):
        """Coefficients of ``names``: 1 for the ``base`` ones, then each effect's
        ``contribution`` (its method of that name) at ``theta``."""
        p = self.values(theta)
        entries = {k: 1.0 for k in base}
        for t in self.effects:
            entries.update(getattr(t, contribution)(p, xp))
        entries = self._scaled(entries, p, xp)
        zero = 0.0 * theta[0]
        return xp.stack([xp.asarray(entries[k]) + zero for k in names])

    def _scaled(self, coefficients: dict, p: dict, xp) -> dict:
        """``coefficients`` by matrix name times every term's :meth:`Term.scales` of them
        (a stretch of the mesh); a probe is never scaled (no term names one)."""
        out = dict(coefficients)
        for t in self.effects:
            for k, f in t.scales(p, xp).items():
                if k in out:
                    out[k] = out[k] * f
        return out

    def loss_law(self, theta, omega, xp=np):
        """(nf,) multiplier of every loss factor at ``omega`` (rad/s), or None (1)."""
        p = self.values(theta)
        law = None
        for t in self.terms:
            m = t.loss_law(p, omega, xp)
            if m is not None:
                law = m if law is None else law * m
        return law

    def base_rotation(self, theta, omega, xp=np):
        """(nf,) complex rotation of the base about the clamp line per unit base translation
        (rad/m) at ``omega`` (rad/s), the sum over the terms that rotate it, or None."""
        p = self.values(theta)
        out = None
        for t in self.effects:
            r = t.base_rotation(p, omega, xp)
            if r is not None:
                out = r if out is None else out + r
        return out

    def afc_map(self, theta, omega, H, xp=np):
        """The observed AFC from the plate's: each term's map in turn."""
        p = self.values(theta)
        for t in self.terms:
            H = t.afc_map(p, omega, H, xp)
        return H

    # -- priors -----------------------------------------------------------------------------
    def default_bounds(self, bounds: dict) -> dict:
        """Prior boxes for every parameter: the given ones, else the material's rule
        (:meth:`Material.bounds_from`), else the effect's default."""
        out = dict(self.material.bounds_from(bounds))
        for q in self.parameters[len(self.material.parameters) :]:
            if q.name in bounds:
                out[q.name] = tuple(bounds[q.name])
            elif q.bounds is not None:
                out[q.name] = tuple(q.bounds)
        return out


def clash(terms) -> tuple[str, str] | None:
    """The first pair of ``terms`` that cannot share a model (one names the other in its
    :attr:`Term.excludes`), as ``(the one that excludes, the one excluded)``; None if
    they can."""
    names = {t.name for t in terms}
    return next(((t.name, n) for t in terms for n in t.excludes if n in names), None)


def theta_from_dict(model: PlateModel, values: dict) -> np.ndarray:
    """The parameter vector in ``model.names`` order; KeyError naming what is missing."""
    missing = [n for n in model.names if n not in values]
    if missing:
        raise KeyError(f"model {model.model!r} needs {', '.join(missing)}")
    return np.array([float(values[n]) for n in model.names])
