"""A reference specimen calibrates the clamp: its known modulus gives the free length.

From bending resonances the modulus along the length goes as ``E ∝ ρ L⁴ / h²``
(:mod:`vibid.identify.assess.plausibility`): the data fix ``E L⁻⁴`` and no fit of one AFC can tell
a stiffer strip from a longer one. A clamp's effective line lies where the strip stops
turning, often inside its jaws (a soft or worn clamp, a clamping force too low for the
strip's thickness), so the free length that the resonances see is longer than the one
measured from the jaws' edge, and every modulus identified in that clamp comes out low by
the same length factor. A real stand shows it: an independent beam puts
its strips ~10 % below their handbooks under their declared setups, each needing its free
length +3–4 mm for the nominal modulus (``benchmarks/real_strips_beam.py``).

A lab calibrates this as it calibrates a sensor: it measures a reference strip of known
modulus in the same clamp. The identified model is refitted with the free length free
(:mod:`~vibid.identify.effects.free_length`: the plate stretched, the sensor moving out
with the free end) and its stiffnesses held at the identified ones scaled to the known
modulus (their ratios and Poisson's ratio held as identified); the loss factors and the
effects the loop added move with it. Not a closed form: the fit weighs every resonance's
frequency and height, and the sensor's reading moves with the stretch.

Its standard uncertainty has two parts. The data's: the free length's variance with the
modulus held and the other material parameters free (Poisson's ratio, the stiffnesses'
ratios; the first stiffness follows them so that the modulus stays), from the refit's
Fisher information scaled as the identification's own covariance is (by the misfit and its
correlation along frequency where a residual remains). A strip's two bending modes barely
determine ν, and ν sets which D the known E means: on a real strip (ν 0.41 ± 0.19) this
part was 1.24 mm, where with ν held it would be 0.11 mm (commit 1248a66). And the reference's:
its modulus's
relative uncertainty times how far the best free length moves per relative change of it.
Declared (``length_m`` and ``length_std_m``, the sensor's ``x_m`` moved alike) for the
specimens measured in that clamp, it enters their fits and their uncertainty budgets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibid.errors import VibidError

#: The modulus along the length (x) by material model: what the resonances of a strip
#: clamped on its short edge measure.
MODULUS_ALONG_LENGTH = {"isotropic": "E_Pa", "orthotropic": "E1_Pa", "monoclinic": "E1_Pa"}


@dataclass(frozen=True)
class Reference:
    """The known modulus along the length of a reference specimen (Pa) and its standard
    uncertainty (Pa, 0 where it is taken as exact)."""

    modulus_pa: float
    std_pa: float = 0.0

    def __post_init__(self):
        if not (math.isfinite(self.modulus_pa) and self.modulus_pa > 0):
            raise VibidError(
                f"the reference modulus must be a positive number of Pa, not {self.modulus_pa:g}"
            )
        if not (math.isfinite(self.std_pa) and self.std_pa >= 0):
            raise VibidError(
                f"the reference modulus's std must be 0 Pa or more, not {self.std_pa:g}"
            )


def reference_from(
    modulus_pa: float | None,
    std_pa: float = 0.0,
    *,
    names: tuple[str, str] = ("reference_E_pa", "reference_E_std_pa"),
) -> Reference | None:
    """The :class:`Reference` of a known modulus and its std (Pa), None without a modulus;
    a std given without one is an error that names the two options (``names``: as the
    caller spells them, the CLI's ``--reference-E`` or the flow's keyword)."""
    if modulus_pa is None:
        if std_pa:
            raise VibidError(f"{names[1]} goes with {names[0]}")
        return None
    return Reference(modulus_pa, std_pa)


@dataclass(frozen=True)
class ClampCalibration:
    """The free length a reference specimen's known modulus gives (module doc): the
    declared and the effective free length (m), the latter's standard uncertainty (m), the
    identified and the known modulus (Pa) with their standard uncertainties, and the
    constant's name (``E_Pa`` or ``E1_Pa``)."""

    constant: str
    declared_length_m: float
    free_length_m: float
    free_length_std_m: float
    identified_pa: float
    identified_std_pa: float
    reference: Reference
    #: chi2 of the refit at the reference modulus less the identification's (under its
    #: weights), the free length's box (m) and whether the refit converged
    chi2_change: float = 0.0
    box_m: tuple[float, float] = (-math.inf, math.inf)
    converged: bool = True

    @property
    def offset_m(self) -> float:
        return self.free_length_m - self.declared_length_m

    def sentence(self) -> str:
        """The calibration in a lab's words, with what to declare."""
        symbol = "E" if self.constant == "E_Pa" else "E1"
        known = f"{self.reference.modulus_pa / 1e9:g}"
        if self.reference.std_pa > 0:
            known += f" ± {self.reference.std_pa / 1e9:.2g}"
        where = (
            "its line lies inside the jaws"
            if self.offset_m > 0
            else "its line lies out on the strip"
        )
        text = (
            f"reference specimen: with {symbol} known to be {known} GPa (identified "
            f"{self.identified_pa / 1e9:.1f} ± {self.identified_std_pa / 1e9:.2g} GPa), "
            f"the clamp's effective free length is {1e3 * self.free_length_m:.2f} ± "
            f"{1e3 * self.free_length_std_m:.2f} mm (declared "
            f"{1e3 * self.declared_length_m:.2f} mm: {1e3 * self.offset_m:+.2f} mm, "
            f"{where}); for specimens in this clamp add {1e3 * self.offset_m:+.2f} mm to "
            f"the declared length_m and the sensor's x_m (both measured from the jaws' "
            f"edge) and declare length_std_m {self.free_length_std_m:.2g}"
        )
        lo, hi = self.box_m
        edge = 1e-3 * (hi - lo)
        if not self.converged:
            text += " (the refit did not converge: the free length is where it stopped)"
        elif not lo + edge < self.offset_m < hi - edge:
            text += (
                f" (at the face of the free length's reach, {1e3 * lo:+.0f} to "
                f"{1e3 * hi:+.0f} mm: the clamp lies further off, or the reference "
                "modulus is not this specimen's)"
            )
        return text

    def as_report(self) -> dict:
        return {
            "constant": self.constant,
            "modulus_Pa": self.reference.modulus_pa,
            "modulus_std_Pa": self.reference.std_pa,
            "identified_Pa": self.identified_pa,
            "identified_std_Pa": self.identified_std_pa,
            "declared_length_m": self.declared_length_m,
            "free_length_m": self.free_length_m,
            "free_length_std_m": self.free_length_std_m,
            "chi2_change": self.chi2_change,
            "converged": self.converged,
            "note": self.sentence(),
        }


def calibrate_free_length(
    setup, result, reference: Reference, local: str = "newton", box: dict | None = None
) -> ClampCalibration:
    """The clamp's effective free length from a reference specimen (module doc): ``result``
    is the specimen's identification (the loop's final stage), ``setup`` its declared
    setup; ``box``: the prior boxes the loop used (:func:`vibid.identify.assess.budget.loop_box`:
    a material it switched to has none in the setup), default the setup's."""
    from vibid.identify.effects.free_length import EFFECT as FREE_LENGTH
    from vibid.identify.fit.local import LOCAL_METHODS, HeldProblem
    from vibid.parameters import STIFFNESS

    current = result.plate_model
    name = current.model
    key, identified = _identified_modulus(setup, result)
    value = identified["value"]
    model = current if "dL_m" in current.names else current.with_effect(FREE_LENGTH)
    names = list(model.names)
    scaled = [q.name for q in STIFFNESS[name] if q.name != "nu"]  # E is linear in them
    held = {q.name for q in STIFFNESS[name]}  # the scaled ones and Poisson's ratio
    ratio = reference.modulus_pa / value
    start = dict(result.parameters) | {"dL_m": result.parameters.get("dL_m", 0.0)}
    at_reference = start | {n: start[n] * ratio for n in scaled}
    box = model.default_bounds(dict(setup.identification.bounds) if box is None else box)
    for n in scaled:  # the reference's stiffnesses may lie beyond the declared box
        lo, hi = box[n]
        box[n] = (min(lo, at_reference[n] / 2), max(hi, at_reference[n] * 2))
    problem = _refit_problem(setup, result, model, at_reference, box)
    free = np.array([i for i, n in enumerate(names) if n not in held])
    u0 = problem.space.to_u(np.array([at_reference[n] for n in names]))
    fixed = HeldProblem(problem, free, u0)
    run = LOCAL_METHODS[local](fixed, u0[free])
    theta = fixed.space.theta(run.u)
    i = names.index("dL_m")
    std = _free_length_std(problem, result, names, start, theta, free, key, reference, setup)
    L = setup.specimen.length_m
    return ClampCalibration(
        key,
        L,
        L + float(theta[i]),
        std,
        float(value),
        identified["std"] if identified["std"] is not None else math.nan,
        reference,
        float(run.loss - result.chi2),
        box["dL_m"],
        bool(run.converged),
    )


def _identified_modulus(setup, result) -> tuple[str, dict]:
    """The constant of the modulus along the length and its identified value and std
    (:func:`~vibid.identify.assess.engineering.engineering_constants`); an error where
    none was identified (a positive, finite number)."""
    from vibid.identify.assess.engineering import engineering_constants

    name = result.plate_model.model
    key = MODULUS_ALONG_LENGTH.get(name)
    h = setup.specimen.thickness_m
    identified = (
        engineering_constants(
            name, result.parameter_names, result.values, result.covariance, h
        ).get(key, {})
        if key
        else {}
    )
    value = identified.get("value")
    if value is None or not math.isfinite(value) or value <= 0:
        raise VibidError(
            f"no modulus along the length was identified ({name} model): a "
            "reference specimen cannot calibrate the clamp"
        )
    return key, identified


def _refit_problem(setup, result, model, at_reference: dict, box: dict):
    """The least-squares problem of ``result``'s data under ``model`` (the free length
    free), linearised about ``at_reference`` within ``box``, weighted as ``result`` was."""
    from vibid.identify.fit.data import fit_data
    from vibid.identify.fit.problem import LeastSquaresProblem
    from vibid.identify.fit.space import ParameterSpace
    from vibid.identify.model.plate import build_forward_model

    names = list(model.names)
    data = fit_data(
        result.frequency_hz, result.H, result.H_std, result.used, magnitude=result.magnitude
    )
    fm = build_forward_model(
        setup, data.frequency_hz[data.used], model=model, theta0=at_reference, bounds=box
    )
    space = ParameterSpace.from_bounds(names, box, {q.name: q.kind for q in model.parameters})
    return LeastSquaresProblem(fm, data, space, result.weights)


def _free_length_std(
    problem, result, names, start, theta, free, key: str, reference: Reference, setup
) -> float:
    """The free length's standard uncertainty at the refit's ``theta`` (module doc): the
    data's part and the reference modulus's, in quadrature. ``free``: the refit's free
    parameters (positions in ``names``); ``key`` the modulus's constant."""
    from vibid.identify.assess.engineering import sensitivities
    from vibid.parameters import STIFFNESS

    name = result.plate_model.model
    h = setup.specimen.thickness_m
    i = names.index("dL_m")
    # the uncertainty in the coordinates where the modulus along the length is one: the
    # other material parameters free, the first stiffness (D, D11) following them so that
    # the modulus stays (their columns by the chain rule), and the modulus itself
    J = problem.jacobian_theta(theta)
    material = [q.name for q in STIFFNESS[name]]
    keys, g, _ = sensitivities(name, material, theta[[names.index(n) for n in material]], h)
    grad = dict(zip(material, g[keys.index(key)]))  # ∂E/∂θ
    lead = names.index(material[0])
    columns = [J[:, k] for k in free]
    columns += [
        J[:, names.index(n)] - J[:, lead] * grad[n] / grad[material[0]] for n in material[1:]
    ]
    A = np.column_stack(columns)
    cov = np.linalg.pinv(A.T @ A)
    # the data's part: dL's variance with the modulus held, scaled as the result's own
    # covariance is (its ratio to the current model's Fisher information at the result)
    k = list(free).index(i)
    data_var = _covariance_scale(problem, result, names, start) * cov[k, k]
    # the reference's part: how far the best dL moves per relative change of the modulus
    along = J[:, lead] * reference.modulus_pa / grad[material[0]]  # the refit's modulus
    slope = -(cov @ (A.T @ along))[k]
    ref_rel = reference.std_pa / reference.modulus_pa
    return math.sqrt(max(data_var, 0.0) + (slope * ref_rel) ** 2)


def _covariance_scale(problem, result, names, start) -> float:
    """The factor by which ``result``'s covariance exceeds its own Fisher information's
    inverse (the misfit's scaling, the model error's widening), read on its first
    parameter: the extended problem at the result (dL = 0) is the result's model."""
    theta = np.array([start[n] for n in names])
    J = problem.jacobian_theta(theta)
    cur = [names.index(n) for n in result.parameter_names]
    inv = np.linalg.pinv(J[:, cur].T @ J[:, cur])
    c = np.asarray(result.covariance, float)
    return float(c[0, 0] / inv[0, 0]) if inv[0, 0] > 0 and np.isfinite(c[0, 0]) else 1.0
