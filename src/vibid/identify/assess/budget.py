"""The uncertainty budget of the engineering constants, as metrology writes one (the GUM).

The combined standard uncertainty of each constant c (E, ν, G or E1, E2, G12, ν12) is the
root sum of squares of independent parts:

* ``fit``: the data's noise and misfit: the estimate's covariance C (Fisher information,
  widened by rival minima and the model's discretisation error, scaled by the misfit and
  by its correlation along frequency where a residual remains) less the discretisation's
  own term b bᵀ, through the conversion: u² = gᵀ (C − b bᵀ) g, g = ∂c/∂θ. Where the misfit
  scales C, the scaling's share of b bᵀ stays here (it is the misfit's);
* ``discretisation``, where the fit estimated the model's discretisation error (the
  result's ``model_error_bias`` b, the shift of the estimate that the mesh's error causes
  against Richardson's extrapolation over three meshes,
  :mod:`vibid.identify.model.model_error`): u = |gᵀ b|. C holds b bᵀ, so ``fit`` and this
  part add in quadrature to gᵀ C g, the constant's std from C alone, as before the split;
* one part per declared quantity with a standard uncertainty in the setup (the optional
  ``*_std`` fields: thickness, length, width, density, the sensor's position and mass):
  a declared value off by one standard uncertainty s moves the estimate too, since the
  model then predicts another AFC for the same parameters. To first order the minimum of
  χ² moves by ``Δθ = −H⁻¹ Δg`` (the implicit function theorem), g the gradient of χ² at
  the estimate, Δg its change when the quantity moves by s (central differences on a
  small step, each a model built for that setup, scaled to s: :data:`STEP`) and H its
  exact Hessian (JAX's, as the trust region's). Where a misfit remains, the Jacobian's
  own change times the residual is part of Δg and H: the Gauss–Newton shift ``−J⁺ Δr``,
  which drops it, put a real strip's length part of E at 9.4 GPa for 0.5 mm where the
  refit at the longer length moves E by 2.0 GPa (``tests/test_budget.py``);
  a parameter the loop's last refit held (:mod:`~vibid.identify.loop.held`: the estimate
  is no minimum along it) is held in the shift too: freed, it would carry the shift off
  along the direction the data leave open (a real strip's refit at the length 0.62 mm
  longer with nu free runs nu to 0.50 and moves E by −4.5 GPa, with nu held by +1.7 GPa,
  and −2.0 GPa 0.62 mm shorter: BENCHMARKS.md);
  the part is ``|gᵀ Δθ + ∂c/∂q s|``, the last term for the thickness alone (the
  conversion's h⁻³). A thicker plate is heavier: D grows with h and E goes as h⁻², which
  the conversion alone (h⁻³) would overstate;
* ``model``, where a residual remains (the loop's ``unexplained_residual``): the spread of
  the constant across the models the loop compared (its stages and the refits the data
  support, :attr:`~vibid.identify.loop.verdicts.Verdict.compared`) whose parameters lie
  inside their prior box (the boxes the loop used, :func:`loop_box`: a material it switched
  to has none in the setup; a model that bends a parameter
  out of it is no defensible one; where the final model bends one too, all of them),
  weighted as Burnham & Anderson average models, by
  exp(−ΔQAIC/2), QAIC = χ²/ĉ + 2p with ĉ the final model's reduced χ² (the data's
  weights) times its residual's autocorrelation time along frequency (a smooth misfit
  spans many points, which then count as one: :func:`vibid.identify.fit.noise.
  residual_correlation`).

* ``clamp_line``, where a residual remains, the final model places the clamp's line at the
  declared edge (no ``free_length`` or ``clamp_compliance`` of its own) and the setup
  declares no ``length_std_m``: the free length that bending resonances see starts where
  the strip stops turning, often inside the jaws, and one AFC barely tells a longer span
  from a softer plate (:mod:`vibid.identify.assess.reference`: ``E ∝ L⁴``). The part is
  ``|∂c/∂dL| u(dL)``: ∂c/∂dL the estimate's shift when the free end and the sensor both
  lie further from the line (as a declared quantity's, above), u(dL) the standard
  uncertainty of a rectangular distribution over the free length's box (``dL_m``: the
  setup's bounds, else ±5 mm, so 2.9 mm; the GUM's type B). The loop's ``free_length``
  candidate has asked the data already and not found the line; the data's own first-order
  information on it is not counted, since beside an unexplained residual it is not to be
  trusted: on an exact beam 3 mm longer than declared, with a 2 % crosstalk no candidate
  explains, it put the line at the declared edge within 0.60 mm (one Gauss–Newton step
  towards the line the data prefer, within 0.95 mm), where the box's 2.9 mm covers the truth
  (``tests/test_budget.py``). It can outweigh the fit's own part severalfold (a real strip
  under its declared setup: 11.1 GPa of E against 2.4 GPa, BENCHMARKS.md). A reference
  strip in the same clamp measures the line, and the setup's ``length_std_m`` then
  declares it (the example in ``examples/real-steel/``).

The parts are independent by construction (different sources), so they add in quadrature.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from vibid.identify.assess.engineering import constants, sensitivities
from vibid.identify.fit.noise import residual_correlation
from vibid.parameters import DL
from vibid.setup_model import RESPONSE_STD, SPECIMEN_STD

#: The declared quantities a setup may give a standard uncertainty (the setup's own list of
#: ``*_std`` fields, each beside the value it qualifies): budget name -> (setup block, value
#: field, std field); the sensor's are named ``sensor_…``.
DECLARED = {
    ("sensor_" if block == "response" else "") + std.replace("_std", ""): (
        block,
        std.replace("_std", ""),
        std,
    )
    for block, fields in (("specimen", SPECIMEN_STD), ("response", RESPONSE_STD))
    for std in fields
}


#: How the report's sentences name the declared quantities.
WORDS = {
    "thickness_m": "thickness",
    "length_m": "length",
    "width_m": "width",
    "density_kg_m3": "density",
    "sensor_x_m": "sensor position (x)",
    "sensor_y_m": "sensor position (y)",
    "sensor_mass_kg": "sensor mass",
}


#: How the report's sentences name the clamp's line's part.
CLAMP_LINE_WORDS = (
    "the clamp's effective line, which these data cannot tell from the "
    "stiffness (a longer free span is a softer plate)"
)


#: How the report's sentences name the parts that are no declared quantity.
PART_WORDS = {
    "fit": "the fit (the data's noise and the model's misfit)",
    "discretisation": "the discretisation (the mesh's error, Richardson-extrapolated "
    "over three meshes)",
    "model": "the choice of model (the loop's competitive models disagree)",
    "clamp_line": CLAMP_LINE_WORDS,
}


#: The relative step of the central differences in a declared quantity: a step of a whole
#: standard uncertainty (1 % of the thickness) moves a resonance by more than its
#: half-power width, where the residual is far from linear in it; the derivative is taken
#: on a small step and scaled to the standard uncertainty (the GUM's first order).
STEP = 1e-4


def _block(setup, where: str):
    return setup.specimen if where == "specimen" else setup.sensors.response


def declared_uncertainties(setup) -> dict[str, float]:
    """The setup's declared quantities with a positive standard uncertainty: name -> std."""
    out = {}
    for name, (where, _, std_field) in DECLARED.items():
        s = getattr(_block(setup, where), std_field, None)
        if s is not None and math.isfinite(s) and s > 0:
            out[name] = float(s)
    return out


def with_declared(setup, name: str, value: float):
    """``setup`` with the declared quantity ``name`` set to ``value``."""
    where, field, _ = DECLARED[name]
    block = dataclasses.replace(_block(setup, where), **{field: value})
    if where == "specimen":
        return dataclasses.replace(setup, specimen=block)
    return dataclasses.replace(setup, sensors=dataclasses.replace(setup.sensors, response=block))


def estimate_shifts(setup, result, names, held=(), linearised=None) -> dict[str, np.ndarray]:
    """name -> (p,) the shift of the estimate when the declared quantity ``name`` is one
    standard uncertainty larger (module doc), for ``names`` among
    :func:`declared_uncertainties`; the parameters ``held`` do not move. ``linearised``:
    ``result``'s :class:`Linearised` where the caller has it already (a function that
    returns it)."""
    if not names or result.plate_model is None:
        return {}
    at = linearised() if linearised else Linearised(setup, result, held)
    std = declared_uncertainties(setup)
    out = {}
    for name in names:
        value = getattr(_block(setup, DECLARED[name][0]), DECLARED[name][1])
        step = min(std[name], STEP * abs(value)) or std[name]
        out[name] = at.moved(lambda s, d: with_declared(s, name, value + d), step) * std[name]
    return out


class Linearised:
    """``result``'s least-squares problem around its estimate, and how the estimate moves
    when the setup does (the declared quantities' parts and the clamp's line, module doc).
    The parameters ``held`` do not move."""

    def __init__(self, setup, result, held=()):
        from vibid.identify.fit.data import fit_data
        from vibid.identify.fit.space import ParameterSpace

        self.setup, self.result = setup, result
        model, self.theta = result.plate_model, np.asarray(result.values, float)
        self.data = fit_data(
            result.frequency_hz, result.H, result.H_std, result.used, magnitude=result.magnitude
        )
        # linear coordinates u = (theta - estimate) / half, whatever the prior box: an
        # estimate outside it (a bent nu) has its derivatives all the same
        sd = np.asarray(result.std, float)
        self.half = np.where(
            np.isfinite(sd) & (sd > 0), sd, 1e-3 * np.maximum(np.abs(self.theta), 1e-12)
        )
        self.space = ParameterSpace.from_bounds(
            model.names,
            {n: (v - h, v + h) for n, v, h in zip(model.names, self.theta, self.half)},
            {n: ("linear",) for n in model.names},
        )
        self.u = self.space.to_u(self.theta)
        self.free = np.array([n not in held for n in model.names])
        self.hessian = self.problem(setup).hessian(self.u)[np.ix_(self.free, self.free)]

    def problem(self, setup):
        from vibid.identify.fit.problem import LeastSquaresProblem
        from vibid.identify.model.plate import build_forward_model

        f_used = self.data.frequency_hz[self.data.used]
        fm = build_forward_model(
            setup, f_used, model=self.result.plate_model, theta0=self.result.parameters
        )
        return LeastSquaresProblem(fm, self.data, self.space, self.result.weights)

    def moved(self, move, step: float) -> np.ndarray:
        """(p,) the estimate's shift per unit of a quantity q, where ``move(setup, dq)`` is
        the setup with q changed by dq: central differences on ``step``, the shift by the
        implicit function theorem (module doc)."""
        up, down = self.problem(move(self.setup, step)), self.problem(move(self.setup, -step))
        dg = (up.value_and_grad(self.u)[1] - down.value_and_grad(self.u)[1]) / (2 * step)
        du = np.zeros(self.theta.size)
        du[self.free] = -np.linalg.lstsq(self.hessian, dg[self.free], rcond=1e-12)[0]
        return du * self.half


def clamp_line(setup, loop, box: dict, linearised=None) -> dict[str, float]:
    """constant -> the clamp's line's part (module doc), where the loop's final model
    leaves a residual unexplained, places the clamp's line at the declared edge (no
    ``free_length`` or ``clamp_compliance`` of its own) and the setup declares no
    uncertainty of the free length; else empty. ``box``: the setup's prior boxes (the free
    length's change ``dL_m``, else the catalogue's); ``linearised``: the final fit's
    :class:`Linearised` where the caller has it already (a function that returns it)."""
    if loop is None or not loop.unexplained_residual or "length_m" in declared_uncertainties(setup):
        return {}
    final = loop.final
    if final.plate_model is None or {"free_length", "clamp_compliance"} & set(
        final.plate_model.effect_names
    ):
        return {}
    lo, hi = box.get(DL.name, DL.bounds)
    prior = (hi - lo) / math.sqrt(12.0)  # a rectangular distribution over the box
    at = linearised() if linearised else Linearised(setup, final, loop.stages[-1].held)
    length, x = setup.specimen.length_m, setup.sensors.response.x_m

    def longer(s, d):  # the free end and the sensor both further from the clamp's line
        return with_declared(with_declared(s, "length_m", length + d), "sensor_x_m", x + d)

    shift = at.moved(longer, STEP * length)
    model = getattr(final.plate_model, "model", None) or final.model
    keys, g, _ = sensitivities(
        model, list(final.parameter_names), at.theta, setup.specimen.thickness_m
    )
    return {k: float(abs(v)) * prior for k, v in zip(keys, g @ shift)}


def loop_box(setup, loop) -> dict:
    """The prior boxes the loop judged its models by: the setup's
    (``setup.identification.bounds``), and for each parameter that has none there and no
    default box of its own (a material the loop switched to: an isotropic setup's loop that
    added ``anisotropy`` fitted D11, D12, D22, D66 in boxes its candidate made from the box
    of D), the box the loop's candidate gave it, replayed stage by stage from the
    candidates' own rule (:meth:`~vibid.identify.loop.candidates.MaterialCandidate.bounds`).
    Without a loop, the setup's boxes."""
    from vibid.parameters import known_parameter

    declared = dict(setup.identification.bounds)
    if loop is None:
        return declared
    from vibid.identify.loop.candidates import all_candidates

    by_name = {c.name: c for c in all_candidates()}
    used = dict(declared)
    for before, stage in zip(loop.stages, loop.stages[1:]):
        if (cand := by_name.get(stage.added)) is not None:
            used |= cand.bounds(used, before.result.parameters, before.diagnosis)
    return declared | {
        n: tuple(b)
        for n, b in used.items()
        if n not in declared and getattr(known_parameter(n), "bounds", None) is None
    }


def model_spread(
    loop, model: str, thickness_m: float, *, tau: float = 1.0, box: dict | None = None
) -> dict[str, float]:
    """constant -> the between-model standard deviation across the loop's models of the
    final material (module doc); empty without a loop or where the final model explains
    the data. ``tau``: the final residual's autocorrelation time; ``box``: the prior box
    (the setup's bounds) outside which a model is not defensible (None: every model; every
    model too where the final one lies outside it: where every model the loop compared
    keeps a parameter outside the box, as a real strip's nu below it, weighing the final
    alone would make the choice of model cost nothing: commit 8453de7)."""
    if loop is None or not loop.unexplained_residual:
        return {}
    from vibid.identify.loop.evidence import outside_prior

    final = loop.final
    if box is not None and outside_prior(final, box):
        box = None  # the final model is outside it too: the box tells no model from another
    fits = [st.result for st in loop.stages] + list(loop.alternatives)
    fits = [
        r
        for r in fits
        if getattr(r.plate_model, "model", None) == model
        and math.isfinite(r.chi2_reduced_reported)
        and r.dof > 0
        and (r is final or box is None or not outside_prior(r, box))
    ]
    c_hat = max(1.0, float(final.chi2_reduced_reported)) * max(1.0, float(tau))
    qaic = np.array(
        [r.chi2_reduced_reported * r.dof / c_hat + 2 * len(r.parameter_names) for r in fits]
    )
    w = np.exp(-(qaic - qaic.min()) / 2.0)
    w /= w.sum()
    values = [constants(model, r.parameters, thickness_m) for r in fits]
    out = {}
    for k in values[0] if values else ():
        c = np.array([v[k] for v in values])
        mean = float(w @ c)
        out[k] = float(math.sqrt(max(float(w @ (c - mean) ** 2), 0.0)))
    return out


def engineering_budget(setup, result, loop=None) -> dict:
    """The report's ``engineering`` block: ``{constant: {"value", "std"}, ...,
    "budget": {constant: {"fit": u, "discretisation": u, <declared quantity>: u, ...,
    "model": u}},
    "notes": [each constant's largest part in words]}`` (standard uncertainties in the
    constant's unit; ``std`` their root sum of squares); empty for a model without closed
    forms."""
    model = getattr(result.plate_model, "model", None) or result.model
    h = setup.specimen.thickness_m
    names, theta = list(result.parameter_names), np.asarray(result.values, float)
    keys, g, dh = sensitivities(model, names, theta, h)
    if not keys:
        return {}
    base = constants(model, dict(zip(names, theta)), h)
    parts = fit_parts(keys, g, result.covariance, getattr(result, "model_error_bias", None))
    std = declared_uncertainties(setup)
    is_final = loop is not None and loop.final is result
    held = loop.stages[-1].held if is_final else ()
    # built at most once, for the declared quantities and the clamp's line alike (its
    # Hessian is the budget's dearest step)
    linearised = functools.cache(lambda: Linearised(setup, result, held))
    shifts = estimate_shifts(setup, result, list(std), held, linearised)
    for name in std:
        if name in shifts:
            moved = g @ shifts[name] + (dh * std[name] if name == "thickness_m" else 0.0)
        elif name == "thickness_m":  # no plate model to move: the conversion alone
            moved = dh * std[name]
        else:
            continue
        for k, v in zip(keys, moved):
            parts[k][name] = float(abs(v))
    tau = residual_correlation(loop.final) if loop is not None else 1.0
    box = loop_box(setup, loop)
    for k, v in model_spread(loop, model, h, tau=tau, box=box).items():
        parts[k]["model"] = v
    for k, v in (clamp_line(setup, loop, box, linearised) if is_final else {}).items():
        parts[k]["clamp_line"] = v
    block = {}
    for k in keys:
        total = sum(v**2 for v in parts[k].values())
        block[k] = {
            "value": float(base[k]),
            "std": float(math.sqrt(total)) if math.isfinite(total) else None,
        }
    block["budget"] = parts
    block["notes"] = [n for k in keys if (n := largest_part(k, parts[k], std))]
    if unknown := [WORDS.get(n, n) for n in DECLARED if n not in std]:
        block["notes"].append(
            f"the setup declares no uncertainty for the {', '.join(unknown)}: the budget "
            "leaves them out (give the setup's *_std fields to have them counted)"
        )
    return block


def fit_parts(keys, g, covariance, bias=None) -> dict[str, dict[str, float]]:
    """constant -> ``{"fit": u}`` and, with the discretisation's bias ``bias`` (p,) (the
    result's ``model_error_bias``, whose b bᵀ ``covariance`` holds), ``"discretisation"``:
    ``|gᵀ b|``, ``fit`` then ``√(gᵀ (C − b bᵀ) g)`` (module doc). ``g``: (k, p) the
    constants' gradients in the parameters."""
    C = np.asarray(covariance, float)
    total = np.einsum("ij,jk,ik->i", g, np.where(np.isfinite(C), C, np.nan), g)
    disc = None if bias is None else np.abs(g @ np.asarray(bias, float))
    parts = {}
    for i, k in enumerate(keys):
        v = total[i]
        if disc is not None and np.isfinite(v):
            # C − b bᵀ is a covariance itself: a negative rest is the subtraction's rounding
            v = max(v - disc[i] ** 2, 0.0) if v >= 0 else v
        parts[k] = {"fit": float(math.sqrt(v)) if np.isfinite(v) and v >= 0 else math.nan}
        if disc is not None:
            parts[k]["discretisation"] = float(disc[i])
    return parts


def largest_part(constant: str, parts: dict, std_of: dict) -> str | None:
    """The budget's largest part in words, and what halving the combined uncertainty would
    take (``std_of``: the declared quantities' standard uncertainties)."""
    finite = {n: v for n, v in parts.items() if v is not None and math.isfinite(v)}
    total = math.sqrt(sum(v**2 for v in finite.values()))
    if not finite or total <= 0:
        return None
    name, u = max(finite.items(), key=lambda kv: kv[1])
    share = (u / total) ** 2
    what = PART_WORDS.get(name, f"the declared {WORDS.get(name, name)}")
    text = f"{constant}'s uncertainty is mostly {what}: {100 * share:.0f} % of its variance"
    if name in std_of:
        # halving the total needs u_new² = u² − ¾ total²: possible when this part is most
        need = u**2 - 0.75 * total**2
        if need > 0:
            unit = _unit(name)
            text += (
                f"; know it to {_fmt(std_of[name] * math.sqrt(need) / u, unit)} "
                f"(now {_fmt(std_of[name], unit)}) to halve it"
            )
        else:
            text += "; even knowing it exactly would not halve the total"
    elif name == "discretisation":
        text += (
            '; a finer mesh (the forward model\'s accuracy "fine") would shrink it, '
            "at the cost of a slower fit"
        )
    elif name == "clamp_line":
        text += (
            "; a reference strip of known modulus in the same clamp measures it "
            "(vibid identify --reference-E), and the setup's specimen.length_std_m "
            "then declares it"
        )
    return text


def _unit(name: str) -> str:
    return "kg/m³" if name.endswith("kg_m3") else "kg" if name.endswith("_kg") else "m"


def _fmt(value: float, unit: str) -> str:
    if unit == "m" and value < 1e-3:
        return f"{value * 1e6:.2g} µm"
    if unit == "kg" and value < 1e-3:
        return f"{value * 1e6:.2g} mg"
    return f"{value:.2g} {unit}"
