"""Candidates: the ways the loop may extend a model, behind one small protocol.

A candidate is an effect term (:class:`EffectCandidate`) or a change of material
(:class:`MaterialCandidate`: the isotropic plate replaced by the orthotropic one). The loop
asks each the same questions: does it apply to this model (a structural fact: the effect it
refines is there, it may share the model, an instance is left), what is the extended model,
where does the extended model equal the current one (its null), what are its new
parameters' prior boxes and starts, how far from its null did a refit leave it.

A resonance of the stand or the fixture has no null for its frequency and Q: it is proposed
once per place it may start from (:meth:`EffectCandidate.placements`), each diagnosed pole
and the residual's largest maxima along the band, and the place that scores best is the
one refitted. The diagnosis never decides which effects are tried.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from vibid.identify.loop.policy import DEFAULT, Policy
from vibid.identify.model.materials import Material
from vibid.identify.model.terms import PlateModel, clash


@dataclass(frozen=True)
class Place:
    """Where a resonance is tried: a frequency and a quality factor (a diagnosed pole's,
    or a maximum of the residual's with the policy's Q), and what found it."""

    f_hz: float
    q: float
    source: str = "pole"


class Candidate(Protocol):
    """What the loop needs of a way to extend a model."""

    name: str
    #: its name, and where a resonance is tried (the report's words)
    label: str
    #: where a resonance is tried (None: an effect without one, or not placed)
    at: Place | None
    #: the diagnosis's feature kinds it can explain (:mod:`vibid.identify.loop.diagnosis`)
    explains: tuple[str, ...]
    #: whether the extended model's best basin may lie away from the current fit's (a new
    #: material moves every resonance its own way): only such a candidate is searched
    #: globally over its box
    moves_basin: bool
    #: whether its global search matches the resonance peaks first
    peaks_first: bool
    #: whether it changes H's phase alone (a fit of |H| cannot see it)
    phase_only: bool

    def applies(self, model: PlateModel) -> bool: ...

    def modes_needed(self, model: PlateModel) -> int: ...

    def extend(self, model: PlateModel) -> PlateModel: ...

    def at_null(self, values: dict, box: dict, thickness_m: float, diagnosis) -> dict: ...

    def bounds(self, box: dict, values: dict, diagnosis=None) -> dict: ...

    def prior_bounds(self, box: dict, values: dict) -> dict: ...

    def held(self, values: dict, diagnosis) -> dict: ...

    def placed(self, values: dict) -> set[str]: ...

    def resonances_hz(self, fitted: dict, values: dict) -> tuple[float, ...]: ...

    def directions(self, J, names, values: dict, current_names): ...

    def distance_from_null(self, result) -> float: ...


@dataclass(frozen=True)
class EffectCandidate:
    """An effect of :mod:`vibid.identify.effects`, added as a term; a resonance, at
    ``at`` (a :class:`Place`; None: the diagnosis's own pole for it, if any)."""

    name: str
    at: Place | None = None
    policy: Policy = DEFAULT
    moves_basin = False
    peaks_first = False

    @property
    def label(self) -> str:
        """Its name, and where a resonance was tried."""
        return self.name if self.at is None else f"{self.name} at {self.at.f_hz:.4g} Hz"

    @property
    def term(self):
        from vibid.identify.effects import EFFECTS

        return EFFECTS[self.name]

    @property
    def explains(self) -> tuple[str, ...]:
        return self.term.explains

    @property
    def phase_only(self) -> bool:
        return self.term.phase_only

    def applies(self, model: PlateModel) -> bool:
        term = self.term
        if term.requires and term.requires not in model.effect_names:
            return False  # a clamp's own loss needs the clamp's spring first
        if clash((*model.effects, term)):
            return False  # the shear field beside a stretched mesh or a moved sensor
        if term.instance is not None:
            return model.effect_names.count(self.name) < self.policy.max_instances
        return self.name not in model.effect_names

    def placements(self, diagnosis, peaks: tuple = ()) -> tuple[EffectCandidate, ...]:
        """This candidate once per place to try it: itself for an effect without a
        resonance; for a resonance, every diagnosed pole (whatever the diagnosis read it
        as: a pole beside a model's antiresonance may be read as a misplaced mode) and
        ``peaks`` (:class:`Place`: the residual's maxima along the band), one per
        :attr:`Policy.pole_span` of frequency, the term's own choice of pole first."""
        if not self.term.needs_feature:
            return (self,)
        places = []
        own = self.term.placed_at(diagnosis) if diagnosis is not None else None
        for f in ([own] if own is not None else []) + list(getattr(diagnosis, "features", ())):
            if np.isfinite(f.f_hz) and f.f_hz > 0 and f.kind != "trend":
                q = f.q if np.isfinite(f.q) and f.q > 0 else self.policy.trial_q
                places.append(Place(float(f.f_hz), float(q), f.kind))
        places += list(peaks)
        span = math.log(self.policy.pole_span)
        kept = []
        for p in places:
            if all(abs(math.log(p.f_hz / k.f_hz)) > span for k in kept):
                kept.append(p)
        return tuple(replace(self, at=p) for p in kept)

    def modes_needed(self, model: PlateModel) -> int:
        """An effect asks nothing of the modes' pattern."""
        return 0

    def feature(self, diagnosis):
        """The place of its new parameters: :attr:`at`, else the diagnosed feature the
        term chooses (``Term.placed_at``), or None."""
        if not self.term.needs_feature:
            return None
        if self.at is not None:
            return self.at
        return None if diagnosis is None else self.term.placed_at(diagnosis)

    def extend(self, model: PlateModel) -> PlateModel:
        return model.with_effect(self.term_after(model.names))

    def term_after(self, names):
        """The term it adds to a model of parameters ``names`` (the next instance of one
        that may occur more than once: a model with ``f_hz_1`` gets instance 2)."""
        term = self.term
        if term.instance is None:
            return term
        k = 1
        while any(n in names for n in replace(term, instance=k).names):
            k += 1
        return replace(term, instance=k)

    def bounds(self, box: dict, values: dict, diagnosis=None) -> dict:
        """The prior box of its new parameters (the setup's where it names them); a
        resonance placed on a pole, within :attr:`Policy.pole_span` of its frequency and
        :attr:`Policy.q_span` of its Q."""
        return self.prior_bounds(box, values) | self._pole_span(values, diagnosis)

    def prior_bounds(self, box: dict, values: dict) -> dict:
        """The physical prior box of its new parameters (the setup's where it names them),
        whatever place it is tried at: the evidence's prior."""
        term = self.term_after(values)
        return {q.name: tuple(box.get(q.name, q.bounds)) for q in term.parameters}

    def held(self, values: dict, diagnosis) -> dict:
        """The transforms (:func:`~vibid.identify.fit.space.make_transform`'s ``kind``) that
        hold a resonance the diagnosis placed inside its pole's span, so that a refit finds
        the best resonance near the pole rather than sliding to another structure."""
        return {n: ("logit", *span) for n, span in self._pole_span(values, diagnosis).items()}

    def _pole_span(self, values: dict, diagnosis) -> dict:
        feature = self.feature(diagnosis)
        if feature is None or not np.isfinite(feature.f_hz):
            return {}
        from vibid.parameters import split_instance

        spans = {
            "f_hz": (feature.f_hz, self.policy.pole_span),
            "q": (feature.q, self.policy.q_span),
        }
        places = self.term.feature_places
        out = {}
        for name in self.placed(values):
            centre, factor = spans.get(places.get(split_instance(name)[0]), (math.nan, 1.0))
            if np.isfinite(centre) and centre > 0:
                out[name] = (centre / factor, centre * factor)
        return out

    def at_null(self, values: dict, box: dict, thickness_m: float, diagnosis) -> dict:
        """The extended model's parameters where it equals the current one: each new
        parameter at its null value (a stand-in far beyond the box for a null at
        infinity); one without a null (a resonance's frequency and Q) where the diagnosed
        feature places it."""
        out = dict(values)
        term = self.term_after(values)
        own = self.bounds(box, values, diagnosis)
        nulls = term.null_values(values)
        feature = self.feature(diagnosis)
        for q in term.parameters:
            if q.name in nulls:
                null = nulls[q.name]
                out[q.name] = 100.0 * own[q.name][1] if math.isinf(null) else null
                continue
            lo, hi = own[q.name]
            placed = _from_feature(q.name, feature, term.feature_places)
            out[q.name] = (
                min(max(placed, lo), hi)
                if placed is not None
                else math.sqrt(lo * hi)
                if lo > 0
                else 0.5 * (lo + hi)
            )
        return out

    def placed(self, values: dict) -> set[str]:
        """Its new parameters that have no null of their own (started from the diagnosis,
        not varied by the refit's starts)."""
        term = self.term_after(values)
        return set(term.names) - set(term.null_values(values))

    def resonances_hz(self, fitted: dict, values: dict) -> tuple[float, ...]:
        """Where a refit (``fitted``, from the current ``values``) put the resonances the
        diagnosis placed (Hz; none for an effect without one): the poles it can explain
        lie around them."""
        from vibid.parameters import split_instance

        places = self.term.feature_places
        return tuple(
            float(fitted[n])
            for n in sorted(self.placed(values))
            if places.get(split_instance(n)[0]) == "f_hz" and n in fitted
        )

    def directions(self, J, names, values: dict, current_names):
        """The current model's sensitivities inside the extended model's (its tangent space
        at the null), and the indices of the new directions."""
        i = {n: k for k, n in enumerate(names)}
        shared = [i[n] for n in current_names if n in i]
        return J[:, shared], [k for k in range(len(names)) if k not in shared]

    def distance_from_null(self, result) -> float:
        """How many standard deviations the fitted effect lies from its null (Wald z; for
        a null at infinity, in the compliance 1/k: z = k / std k)."""
        return distance_from_null(self._fitted(result), result)

    def _fitted(self, result):
        """Its term in ``result``'s model (the last instance added)."""
        return next(t for t in reversed(result.plate_model.effects) if t.name == self.name)


def distance_from_null(term, result) -> float:
    """How many standard deviations ``term``'s parameters lie from their null in
    ``result`` (the largest Wald z; inf for a term without parameters: the likelihood
    ratio alone decides)."""
    p, sd = result.parameters, result.parameter_std
    z = [
        abs(p[n] if math.isinf(null) else p[n] - null) / sd[n]
        if np.isfinite(sd[n]) and sd[n] > 0
        else math.inf
        for n, null in term.null_values(p).items()
    ]
    return max(z) if z else math.inf


def _from_feature(name: str, feature, places: dict) -> float | None:
    """A resonance's frequency or Q from a diagnosed pole: the value ``places`` (a term's
    ``feature_places``) names for ``name`` (any instance suffix), or None."""
    if feature is None:
        return None
    from vibid.parameters import split_instance

    value = {"f_hz": feature.f_hz, "q": feature.q}.get(places.get(split_instance(name)[0]))
    return float(value) if value is not None and np.isfinite(value) else None


@dataclass(frozen=True)
class MaterialCandidate:
    """The isotropic material replaced by the orthotropic one, started from the isotropic
    fit (its null: D11 = D22 = D, D12 = ν D, D66 = (1 − ν) D / 2)."""

    name: str = "anisotropy"
    policy: Policy = DEFAULT
    at = None
    label = "anisotropy"
    moves_basin = True
    explains = ("mode_shift",)
    #: the anisotropic material moves every resonance its own way, and the isotropic fit
    #: lies far from the orthotropic basin, where chi2's minima are needles
    peaks_first = True
    phase_only = False

    def applies(self, model: PlateModel) -> bool:
        return model.material.model == "isotropic"

    def placements(self, diagnosis, peaks: tuple = ()) -> tuple:
        return (self,)

    def modes_needed(self, model: PlateModel) -> int:
        """The plate's modes the band must hold for the modes' pattern to ask for a new
        material: one more than the current material's stiffnesses (an isotropic plate's
        D and nu can place any two; the first two bending modes of a strip cannot tell an
        orthotropic plate from an isotropic one, and a shifted one is no anisotropy)."""
        return len(model.material.stiffness_names) + 1

    def extend(self, model: PlateModel) -> PlateModel:
        return model.with_material(Material("orthotropic", model.material.per_modulus_loss))

    def bounds(self, box: dict, values: dict, diagnosis=None) -> dict:
        """The orthotropic stiffnesses' physical box from the declared D's: D11 within it,
        D22 and D66 from the isotropic fit's D (its stiffness along the plate, ``values``;
        else the box's low end) over :attr:`Policy.orthotropy_divisor` (a plate declared
        isotropic may be a unidirectional laminate across its fibres, E2 / E1 about 1/15,
        no softer), D12 signed."""
        lo, hi = box["D"]
        weak = values.get("D", lo) / self.policy.orthotropy_divisor
        return {
            "D11": (lo, hi),
            "D22": (weak, hi),
            "D66": (weak, hi / 2),
            "D12": (-hi / 2, hi / 2),
        } | {k: v for k, v in box.items() if k not in ("D", "nu")}

    def prior_bounds(self, box: dict, values: dict) -> dict:
        return self.bounds(box, values)

    def at_null(self, values: dict, box: dict, thickness_m: float, diagnosis) -> dict:
        D, nu = values["D"], values["nu"]
        out = {k: v for k, v in values.items() if k not in ("D", "nu")}
        # an isotropic plate's transverse shear has G = E / 2(1 + nu) = 6 (1 - nu) D / h³
        return out | {
            "D11": D,
            "D12": nu * D,
            "D22": D,
            "D66": 0.5 * (1 - nu) * D,
            "G13_Pa": 6 * (1 - nu) * D / thickness_m**3,
        }

    def placed(self, values: dict) -> set[str]:
        return set()

    def held(self, values: dict, diagnosis) -> dict:
        return {}

    def resonances_hz(self, fitted: dict, values: dict) -> tuple[float, ...]:
        return ()

    def directions(self, J, names, values: dict, current_names):
        """d(D11, D12, D22, D66)/d(D, ν) at the null span the isotropic directions; D22
        and D66 are the new ones."""
        i = {n: k for k, n in enumerate(names)}
        D, nu = values["D"], values["nu"]
        jD = J[:, i["D11"]] + nu * J[:, i["D12"]] + J[:, i["D22"]] + 0.5 * (1 - nu) * J[:, i["D66"]]
        jnu = D * J[:, i["D12"]] - 0.5 * D * J[:, i["D66"]]
        shared = [i[n] for n in current_names if n in i]
        return np.column_stack([jD, jnu] + [J[:, k] for k in shared]), [i["D22"], i["D66"]]

    def distance_from_null(self, result) -> float:
        """Wald z of the anisotropy's two contrasts, D22 − D11 and 2 D66 − D11 + D12 (the
        larger)."""
        names = list(result.parameter_names)
        C = np.asarray(result.covariance)
        theta = np.asarray(result.values)
        z = []
        for combo in ({"D22": 1.0, "D11": -1.0}, {"D66": 2.0, "D11": -1.0, "D12": 1.0}):
            g = np.zeros(len(names))
            for n, c in combo.items():
                g[names.index(n)] = c
            var = float(g @ C @ g)
            z.append(abs(float(g @ theta)) / math.sqrt(var) if var > 0 else math.inf)
        return max(z)


def all_candidates(policy: Policy = DEFAULT) -> tuple:
    """Every candidate the loop knows, and tries unless told which."""
    from vibid.identify.effects import EFFECTS

    return tuple(EffectCandidate(n, policy=policy) for n in EFFECTS) + (
        MaterialCandidate(policy=policy),
    )
