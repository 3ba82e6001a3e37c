"""The closed loop: residual → the effect the model lacks → add it → refit → error before
and after.

1. Fit the declared model (:func:`vibid.identify.fit.identify`) and test its residual
   against the noise (:mod:`vibid.identify.fit.noise`): chi2 below its 0.999 quantile, and
   where chi2 is borderline (above its 0.95 quantile) a white normalised residual along
   frequency (Ljung-Box). A fit to the noise ends the loop: no effect is ever added to data
   the model already explains.
2. Otherwise score every candidate at the current fit with a score (Lagrange-multiplier)
   test: with ``r`` the weighted residual and ``J`` the Jacobian of the model extended by the
   candidate, at the current estimate and the candidate's null value,
   ``LM = rᵀ (P_ext − P) r``, ``P`` the projector onto the current parameters' sensitivities
   (χ² with as many degrees of freedom as the candidate adds, under the null). Its
   collinearity is how much of its sensitivity the current parameters already explain.
3. Refit the best few candidates from the current fit (several starts along the new
   parameter; in order of score, stopping at one that fits the residual to the noise
   level), keep the one whose likelihood-ratio ``Δχ²`` (same weights) passes the 99 %
   quantile and is largest, provided its refit converged, lowers chi2 under its own
   weights too, lies 3 std from its null value and removes at least a tenth of the chi2
   above the noise. When no refit fits the noise nor explains half of the chi2 above it,
   the top candidate's extended model is also searched globally over its box (the
   current estimate may lie in a wrong basin of it: an orthotropic plate fitted as
   isotropic; anisotropy's search matches the resonance peaks first, with the current
   loss factor, and searches chi2 too only if that fit does not reach the noise). Repeat
   until the residual fits the noise or nothing helps (``unexplained_residual``). Where
   the current estimate has left its prior box (the declared model bending a parameter to
   mimic what it lacks), the refit also starts with those parameters just inside the box,
   and its minimum inside the box is kept unless one outside fits significantly better
   (chi2 differences in units of the reduced chi2, as the misfit, not the noise, then sets
   their scale). While the estimate is outside its box, every candidate that passes the
   score test is refitted (the effect behind the excursion may score low: the bent
   parameter already mimics it; the top candidate's global search then comes first, so
   that the others are refitted only when it does not explain the data), and a kept
   effect that brings the estimate back inside the box goes before one that gains more
   chi2 but leaves it outside (which stays a candidate for the next round). Such an effect
   is kept even when it gains nothing, provided its chi2 is one the data cannot tell from
   the current one (:func:`~vibid.identify.fit.minima.indistinct_chi2`, in units of the
   reduced chi2): the excursion was that effect, and the prior box prefers it. Those
   refits also start with the bent parameters at their box's centre, a physical value far
   from the bent one.

A candidate without parameters of its own (``transverse_shear`` on an isotropic plate) is
scored along the secant from the current model to the extended one (one dof) and kept on
its likelihood ratio.

A candidate is an effect of :mod:`vibid.identify.effects`, or ``anisotropy`` (the isotropic
material replaced by the orthotropic one, started from the isotropic fit).

When the loop ends with a residual no candidate explains, the final model's covariance is
scaled by its reduced chi2 (the Birge ratio squared): the misfit is then the measure of
how far the model is from the data, and the Fisher covariance alone, which assumes the
model right, would be a confident answer the fit has not earned.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from vibid.errors import VibidError
from vibid.identify.fit.data import fit_data
from vibid.identify.fit.local import LOCAL_METHODS
from vibid.identify.fit.minima import best_inside_prior, indistinct_chi2
from vibid.identify.fit.noise import QUANTILE, fits_noise, ljung_box_p
from vibid.identify.fit.problem import LeastSquaresProblem
from vibid.identify.fit.result import IdentificationResult
from vibid.identify.fit.space import ParameterSpace
from vibid.identify.fit.strategy import gives_modes, identify
from vibid.identify.model.materials import Material
from vibid.identify.model.terms import PlateModel
from vibid.identify.profile import timed

log = logging.getLogger(__name__)

#: A residual whose Ljung-Box p-value is below this is structured (not white).
WHITENESS_P = 1e-3
#: chi2 below this quantile fits the noise whatever the residual's shape; between it and
#: the noise test's quantile (0.999) chi2 is borderline, and a structured residual (not
#: white) sends the loop on. The model's own discretisation error is structured along
#: frequency too: on low-noise sessions it alone made Ljung-Box fail on clean data.
BORDERLINE_QUANTILE = 0.95
#: Whiteness is judged where the data's standard uncertainty is at least this share of the
#: weight (the model's estimated error below a quarter of the noise), on at least this many
#: points.
DATA_SHARE = 0.97
WHITENESS_MIN_POINTS = 20
#: Candidates refitted per round (the highest scores that pass the score test).
REFITS_PER_ROUND = 3
#: A candidate's score must pass this quantile of chi-square to be refitted, and its
#: refit's likelihood ratio the same to be kept.
KEEP_QUANTILE = 0.99
#: A kept effect must explain at least this share of the chi2 above the noise (chi2 - dof):
#: where a residual no candidate explains remains, every extra parameter lowers chi2 a
#: little and passes the likelihood-ratio test, which assumes the extended model is right;
#: an effect that removes a few per cent of a misfit is no explanation of it.
KEEP_SHARE = 0.10
#: A kept effect must lie this many standard deviations from its null value (Wald): a
#: refit that lowers chi2 while its effect stays at the null (a different reduced basis
#: fitting the mesh error a little better) adds nothing physical.
KEEP_Z = 3.0
#: The top candidate is searched globally (its extended model over the whole box) only
#: when no local refit explains this share of the chi2 above the noise.
SEARCH_SHARE = 0.5
#: Starts of a refit along the new parameter, in the coordinates u of its prior box.
REFIT_STARTS_U = (-0.75, -0.25, 0.25, 0.75)
#: Where a refit restarts a current parameter found outside its prior box (u = ±1 are
#: the box's faces).
INSIDE_U = 0.9
#: How many instances of an effect that may occur more than once the loop adds.
MAX_INSTANCES = 2


# -- candidates ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Candidate:
    """One way to extend a model: an effect term, or the anisotropic material."""

    name: str

    def applies(self, model: PlateModel) -> bool:
        if self.name == "anisotropy":
            return model.material.model == "isotropic"
        from vibid.identify.effects import EFFECTS

        term = EFFECTS[self.name]
        needs = getattr(term, "requires", None)
        if needs and needs not in model.effect_names:
            return False  # a clamp's own loss needs the clamp's spring first
        if term.instance is not None:
            return model.effect_names.count(self.name) < MAX_INSTANCES
        return self.name not in model.effect_names

    def extend(self, model: PlateModel) -> PlateModel:
        if self.name == "anisotropy":
            return model.with_material(Material("orthotropic", model.material.per_modulus_loss))
        return model.with_effect(self.term_after(model.names))

    @property
    def peaks_first(self) -> bool:
        """Whether its global search should match the resonance peaks first: the
        anisotropic material moves every resonance its own way, and the isotropic fit lies
        far from the orthotropic basin, where chi2's minima are needles."""
        return self.name == "anisotropy"

    def at_null(self, values: dict, box: dict, thickness_m: float) -> dict:
        """The extended model's parameters where it equals the current model: the null
        value (a stand-in far beyond the prior box for a null at infinity)."""
        if self.name == "anisotropy":
            D, nu = values["D"], values["nu"]
            out = {k: v for k, v in values.items() if k not in ("D", "nu")}
            # an isotropic plate's transverse shear has G = E / 2(1 + nu) = 6 (1 - nu) D / h³
            return out | {"D11": D, "D12": nu * D, "D22": D, "D66": 0.5 * (1 - nu) * D,
                          "G13_Pa": 6 * (1 - nu) * D / thickness_m**3}
        out = dict(values)
        term = self.term_after(values)
        own = self.bounds(box, values)
        nulls = term.null_values(values)
        for q in term.parameters:
            if q.name not in nulls:  # no null of its own (a resonance's f, q): the box's
                lo, hi = own[q.name]  # middle, until the score's scan places it
                out[q.name] = math.sqrt(lo * hi) if lo > 0 else 0.5 * (lo + hi)
            else:
                null = nulls[q.name]
                out[q.name] = 100.0 * own[q.name][1] if math.isinf(null) else null
        return out

    def term_after(self, names):
        """The effect term it adds to a model of parameters ``names`` (the next instance
        of one that may occur more than once: a model with ``f_hz_1`` gets
        ``stand_resonance`` instance 2)."""
        from vibid.identify.effects import EFFECTS

        term = EFFECTS[self.name]
        if term.instance is None:
            return term
        k = 1
        while any(n in names for n in replace(term, instance=k).names):
            k += 1
        return replace(term, instance=k)

    def distance_from_null(self, result) -> float:
        """How many standard deviations the fitted extension lies from its null (Wald z;
        for a null at infinity, in the compliance 1/k: z = k / std k)."""
        p, sd = result.parameters, result.parameter_std
        if self.name == "anisotropy":
            names = list(result.parameter_names)
            C = np.asarray(result.covariance)
            z = []
            for combo in ({"D22": 1.0, "D11": -1.0}, {"D66": 2.0, "D11": -1.0, "D12": 1.0}):
                g = np.zeros(len(names))
                for n, c in combo.items():
                    g[names.index(n)] = c
                theta = np.asarray(result.values)
                var = float(g @ C @ g)
                z.append(abs(float(g @ theta)) / math.sqrt(var) if var > 0 else math.inf)
            return max(z)
        term = next(t for t in reversed(result.plate_model.effects) if t.name == self.name)
        z = []
        for name, null in term.null_values(p).items():
            v, s = p[name], sd[name]
            if not (np.isfinite(s) and s > 0):
                z.append(math.inf)
            elif math.isinf(null):
                z.append(abs(v) / s)
            else:
                z.append(abs(v - null) / s)
        return max(z) if z else math.inf  # no parameter: the likelihood ratio alone decides

    def bounds(self, box: dict, values: dict | None = None) -> dict:
        """The prior box of the new parameters (the setup's if it names them), for the
        model of parameters ``values`` (which instance it adds)."""
        if self.name == "anisotropy":
            lo, hi = box["D"]
            return {"D11": (lo, hi), "D22": (lo, hi), "D66": (lo / 10, hi / 2),
                    "D12": (-hi / 2, hi / 2)} | {k: v for k, v in box.items() if k not in ("D", "nu")}
        term = self.term_after(values or {})
        return {q.name: tuple(box.get(q.name, q.bounds)) for q in term.parameters}


#: Effects the loop considers only when asked (``candidates=``, ``--candidates``): the four
#: of a real stand (issue #24). Among the default candidates this loop's rules chose them
#: wrongly on data they did not cause (an orthotropic plate got a stand resonance before
#: its anisotropy; a thick strip the sensor's inertia and position instead of the
#: transverse shear), and scoring them doubled the loop tests' time: choosing between
#: them needs the residual's diagnosis of issue #25.
ON_REQUEST = ("stand_resonance", "clamp_loss", "free_length", "sensor_inertia")


def all_candidates() -> tuple[Candidate, ...]:
    """Every candidate the loop knows (by default it tries :func:`default_candidates`)."""
    from vibid.identify.effects import EFFECTS

    return tuple(Candidate(n) for n in EFFECTS) + (Candidate("anisotropy"),)


def default_candidates() -> tuple[Candidate, ...]:
    """The candidates the loop tries unless told which: all but :data:`ON_REQUEST`."""
    return tuple(c for c in all_candidates() if c.name not in ON_REQUEST)


# -- what the loop reports ----------------------------------------------------------------
@dataclass(frozen=True)
class Score:
    """A candidate scored at the current fit (and refitted if it scored high enough)."""

    name: str
    score: float  # LM statistic
    dof: int
    p_value: float
    collinearity: float  # 0: orthogonal to the current parameters, 1: indistinguishable
    delta_chi2: float = math.nan  # the refit's likelihood ratio (same weights), if refitted
    kept: bool = False
    note: str = ""


@dataclass(frozen=True)
class Stage:
    """The model after one step of the loop: ``added`` is None for the declared model."""

    added: str | None
    result: IdentificationResult
    ljung_box_p: float

    @property
    def fits_noise(self) -> bool:
        r = self.result
        if not fits_noise(r.chi2, r.dof, r.noise_known):
            return False
        if fits_noise(r.chi2, r.dof, r.noise_known, quantile=BORDERLINE_QUANTILE):
            return True
        return not self.ljung_box_p < WHITENESS_P


@dataclass(frozen=True)
class LoopResult:
    stages: tuple[Stage, ...]
    rounds: tuple[tuple[Score, ...], ...]
    unexplained_residual: bool
    warnings: tuple[str, ...] = field(default=())
    seconds: float = math.nan

    @property
    def final(self) -> IdentificationResult:
        return self.stages[-1].result

    @property
    def effects(self) -> tuple[str, ...]:
        return tuple(s.added for s in self.stages[1:])

    def summary(self) -> str:
        """The error before and after, stage by stage, then the final model's summary."""
        lines = ["closed loop:"]
        for st in self.stages:
            r = st.result
            what = "declared model" if st.added is None else f"+ {st.added}"
            lines.append(f"  {what:<28} chi2_reduced {r.chi2_reduced:10.4g}  rel_rms_residual "
                         f"{r.rel_rms_residual:.3g}  whiteness p {st.ljung_box_p:.2g}")
        lines.append("  the residual " + ("still holds an effect no candidate explains "
                                          "(unexplained_residual)" if self.unexplained_residual
                                          else "is at the noise level"))
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines) + "\n" + self.final.summary()


# -- the loop -------------------------------------------------------------------------------
def close_loop(setup, frequency_hz, H, std, *, used=None, candidates=None, max_rounds: int = 4,
               restarts: int = 5, seed=0, progress=None, local: str = "newton",
               declared: IdentificationResult | None = None) -> LoopResult:
    """Fit the declared model, then add the effects the residual asks for (module doc).

    ``candidates``: names to consider (default: every effect and ``anisotropy`` but
    :data:`ON_REQUEST`);
    ``declared``: the declared model's result when already computed.
    """
    t0 = time.perf_counter()
    pool = default_candidates()
    if candidates is not None:
        pool = all_candidates()
        names = {c.name for c in pool}
        unknown = sorted(set(candidates) - names)
        if unknown:
            raise VibidError(f"unknown candidate {', '.join(unknown)}: expected some of "
                             f"{', '.join(sorted(names))}")
        pool = tuple(c for c in pool if c.name in set(candidates))
    if declared is None:
        declared = identify(setup, frequency_hz, H, std, used=used, restarts=restarts,
                            seed=seed, progress=progress, local=local)
    stages = [_stage(None, declared)]
    warnings = []
    if not declared.noise_known:
        warnings.append("the AFC's uncertainty is unknown: the loop cannot test the residual "
                        "against the noise, so no effect was looked for")
        return LoopResult(tuple(stages), (), False, tuple(warnings), time.perf_counter() - t0)
    data = fit_data(frequency_hz, H, std, used)
    box = dict(setup.identification.bounds)
    rounds = []
    for _ in range(max_rounds):
        current = stages[-1]
        if current.fits_noise:
            break
        model = current.result.plate_model
        todo = [c for c in pool if c.applies(model)]
        if not todo:
            break
        scores, best = _round(setup, data, current, todo, box, local)
        rounds.append(tuple(scores))
        if best is None:
            break
        stages.append(best)
        box = box | next(c for c in todo if c.name == best.added).bounds(
            box, stages[-2].result.parameters)
    final = stages[-1]
    unexplained = not final.fits_noise
    if unexplained:
        stages[-1] = replace(final, result=scaled_by_misfit(final.result))
    for s in rounds[-1] if rounds else ():
        if s.kept and s.collinearity > 0.9:
            warnings.append(
                f"{s.name} is nearly collinear with the declared parameters (cosine "
                f"{s.collinearity:.5f}): the data separate them only through the "
                f"{100 * math.sqrt(max(1 - s.collinearity**2, 0)):.2g} % of its sensitivity "
                "the others cannot mimic; its std and theirs include that")
    return LoopResult(tuple(stages), tuple(rounds), unexplained, tuple(warnings),
                      time.perf_counter() - t0)


def scaled_by_misfit(result: IdentificationResult) -> IdentificationResult:
    """``result`` with its covariance scaled by its reduced chi2 when that exceeds 1 (the
    standard deviations by the Birge ratio ``√chi2_red``), the warning saying so in place of
    the one that they understate the error."""
    k = float(result.chi2_reduced)
    if not (result.noise_known and np.isfinite(k) and k > 1.0):
        return result
    note = (f"the standard deviations are scaled by sqrt(reduced chi2) = {math.sqrt(k):.3g}: "
            "the residual holds more than the noise, and the misfit measures the error")
    kept = tuple(w for w in result.warnings if "understate the error" not in w)
    std = result.std * math.sqrt(k)
    poor = tuple(
        f"{n} is poorly determined by these data (scaled std {sd:.2g} = "
        f"{100 * sd / abs(v):.0f} % of its value)"
        for n, v, sd, s0 in zip(result.parameter_names, result.values, std, result.std)
        if abs(v) > 0 and np.isfinite(sd) and sd > 0.3 * abs(v) and not s0 > 0.3 * abs(v))
    return replace(result, std=std, covariance=result.covariance * k,
                   warnings=kept + (note,) + poor)


def _stage(added, result: IdentificationResult) -> Stage:
    return Stage(added, result, ljung_box_p(_whiteness_residual(result)))


def _whiteness_residual(result: IdentificationResult) -> np.ndarray:
    """The normalised residual (real parts, then imaginary, each along frequency) on the
    points where the data's noise dominates the weight: the model's own discretisation
    error is smooth along frequency, so where it is a sizeable part of the weight it makes
    the residual look structured on data the model explains (low-noise sessions). Where
    fewer than :data:`WHITENESS_MIN_POINTS` such points remain, every point."""
    u = result.used
    r = (result.model_afc[u] - result.H[u]) / result.weights
    if result.H_std is not None:
        quiet = np.asarray(result.H_std)[u] >= DATA_SHARE * np.asarray(result.weights)
        if np.count_nonzero(quiet) >= WHITENESS_MIN_POINTS:
            r = r[quiet]
    return np.concatenate([r.real, r.imag])


def _round(setup, data, current: Stage, todo, box, local):
    """Score every candidate, refit the best few, and return (scores, the new stage or
    None)."""
    res = current.result
    values = res.parameters
    scores = []
    for cand in todo:
        try:
            scores.append(_score(setup, data, res, cand, values, box))
        except Exception as exc:  # noqa: BLE001 - a candidate that fails is reported, not fatal
            scores.append(Score(cand.name, math.nan, 0, math.nan, math.nan,
                                note=f"could not be scored: {exc}"))
    from scipy.stats import chi2 as chi2_dist

    done = {}  # name -> (delta chi2, note)
    n_residuals = 2 * int(np.count_nonzero(data.used))
    for s in scores:
        n = len(next(c for c in todo if c.name == s.name).extend(res.plate_model).names)
        if n >= n_residuals:
            done[s.name] = (math.nan, f"not refitted: too few points for its {n} parameters "
                                      f"({n_residuals} real residuals)")
    # while the estimate lies outside its prior box, every candidate that passes is
    # refitted: the one that explains the excursion may score low (the parameter bent out
    # of its box already mimics it)
    outside = _outside_prior(res, box)
    ranked = sorted((s for s in scores if np.isfinite(s.score) and s.name not in done
                     and s.score > chi2_dist.ppf(KEEP_QUANTILE, s.dof)),
                    key=lambda s: -s.score)[:None if outside else REFITS_PER_ROUND]

    excess = max(res.chi2 - res.dof, 0.0)  # the chi2 above the noise

    def attempt(s: Score, search: bool):
        """Refit one candidate: (its stage if it is kept, else None, delta chi2, the
        refitted estimate's parameters outside their prior box)."""
        cand = next(c for c in todo if c.name == s.name)
        try:
            stage, gain = _refit(setup, data, res, cand, values, box, local, search=search)
        except Exception as exc:  # noqa: BLE001
            done.setdefault(s.name, (math.nan, f"refit failed: {exc}"))
            return None, math.nan, []
        # significant under the current weights, and lower under the stage's own (the
        # extended model's error re-estimated): an effect must explain data, not mesh error
        z = cand.distance_from_null(stage.result)
        passes = (gain > chi2_dist.ppf(KEEP_QUANTILE, s.dof) and stage.result.converged
                  and stage.result.chi2 < res.chi2 and z > KEEP_Z
                  and gain >= KEEP_SHARE * excess)
        # while the estimate is outside its prior box: an effect that brings it back inside
        # at a chi2 the data cannot tell from the current one explains the excursion (the
        # declared model bent a parameter to mimic it), though it gains nothing in chi2
        left = _outside_prior(stage.result, box | cand.bounds(box, values)) if outside else []
        back_inside = (bool(outside) and not passes and stage.result.converged and z > KEEP_Z
                       and not left
                       and gain >= -indistinct_chi2(len(stage.result.values),
                                                    max(1.0, float(res.chi2_reduced))))
        passes = passes or back_inside
        if back_inside:
            note = (f"it brings {', '.join(outside)} back inside the prior box at a chi2 the "
                    "data cannot tell from the current one: the excursion was this effect")
        elif passes:
            note = ""
        elif not stage.result.converged:
            note = f"the refit did not converge ({stage.result.message})"
        elif z <= KEEP_Z:
            note = f"the refit leaves it at its null value ({z:.2g} std from it)"
        elif gain > chi2_dist.ppf(KEEP_QUANTILE, s.dof) and stage.result.chi2 < res.chi2:
            note = (f"it explains only {100 * gain / excess:.2g} % of the chi2 above the noise "
                    f"(an effect must explain {100 * KEEP_SHARE:.0f} %)")
        else:
            note = "the refit does not improve chi2 significantly"
        if not search or passes or s.name not in done:
            done[s.name] = (gain, note + (" (global search)" if search else ""))
        return (stage if passes else None), gain, left

    # local refits of the best few; a global search of the top candidate only when none of
    # them explains the data, nor most of its misfit (an orthotropic plate fitted as
    # isotropic; a kept refit that explains most of it is in its basin, and what it leaves
    # is the next round's: a second effect). While the estimate is outside its box (every
    # passing candidate is refitted) that search comes first, right after the top
    # candidate's local refit: the others need not be refitted when it explains the data
    kept = []
    for k, s in enumerate(ranked):
        kept.append(attempt(s, bool(outside) and k == 0))
        if kept[-1][0] is not None and kept[-1][0].fits_noise:
            # the residual is explained to the noise level: another candidate could at
            # best tie with it, for the price of its refit
            for rest in ranked[k + 1:]:
                done[rest.name] = (math.nan, f"not refitted: {s.name} already fits the "
                                             "residual to the noise level")
            break
    explained = max((g for st, g, _ in kept if st is not None), default=0.0)
    if (ranked and not outside and explained < SEARCH_SHARE * excess
            and not any(st is not None and st.fits_noise for st, _, _ in kept)):
        kept.append(attempt(ranked[0], True))
    kept = [k for k in kept if k[0] is not None]
    if outside and any(not left for _, _, left in kept):
        # an effect that brings the estimate back inside its prior box explains the
        # excursion; it goes first, whatever the others gain (they stay candidates)
        for st, _, left in kept:
            if left:
                done[st.added] = (done[st.added][0], (
                    f"kept back: it leaves {', '.join(left)} outside the prior box, and an "
                    "effect that brings the estimate back inside it goes first"))
        kept = [k for k in kept if not k[2]]
    best = max(kept, key=lambda k: k[1])[0] if kept else None
    out = []
    for s in scores:
        if s.name in done:
            gain, note = done[s.name]
            s = Score(s.name, s.score, s.dof, s.p_value, s.collinearity, gain,
                      best is not None and best.added == s.name, note)
        out.append(s)
    return out, best


def _outside_prior(result: IdentificationResult, box: dict) -> list[str]:
    """Names of ``result``'s parameters outside (or on a face of) their prior box."""
    bounds = result.plate_model.default_bounds(box)
    space = ParameterSpace.from_bounds(result.parameter_names, bounds,
                                       {q.name: q.kind for q in result.plate_model.parameters})
    return space.out_of_bounds(result.values)


def _extended_problem(setup, data, res, cand, values, box, weights):
    from vibid.identify.model.forward import build_forward_model

    model = cand.extend(res.plate_model)
    start = cand.at_null(values, box, setup.specimen.thickness_m)
    ext_box = model.default_bounds(box | cand.bounds(box, values))
    fm = build_forward_model(setup, data.frequency_hz[data.used], model=model, theta0=start,
                             bounds=ext_box)
    space = ParameterSpace.from_bounds(fm.parameter_names, ext_box,
                                       {q.name: q.kind for q in model.parameters})
    problem = LeastSquaresProblem(fm, data, space, weights)
    added = None if cand.name == "anisotropy" else cand.term_after(values)
    if added is not None and added.rotates_base:  # (not a model that rocks already)
        start = start | _resonance_start(problem, start, added, res.parameter_names, ext_box)
    return problem, start, ext_box


def _resonance_start(problem, start: dict, term, current_names, box: dict) -> dict:
    """A stand resonance's ``f_hz`` and ``q`` where its score at the null is largest.

    At ``θ₀ = 0`` the AFC's derivative along ``θ₀`` is ``H_rotation g(f; f₀, q)`` with
    ``g = 1 / (1 − (f/f₀)² + i f/(f₀ q))``: one Jacobian gives ``H_rotation``, and the
    score of every (f₀, q) of a grid (each measured frequency and the midpoints, a few
    quality factors inside the box) follows from it."""
    names = problem.space.names
    theta = np.array([start[n] for n in names])
    J = problem.jacobian_theta(theta)
    r = problem.residuals_theta(theta)
    f = np.asarray(problem.model.frequencies_hz, float)
    if r.size != 2 * f.size:
        return {}
    n_f, n_q, n_t = term.names
    omega = 2 * np.pi * f

    def shape(f0, q):
        return np.asarray(term.base_rotation({n_f: f0, n_q: q, n_t: 1.0}, omega, np))

    col = J[:f.size, names.index(n_t)] + 1j * J[f.size:, names.index(n_t)]
    h_rot = col / shape(start[n_f], start[n_q])
    small = J[:, [names.index(n) for n in current_names if n in names]]
    base = _projected(small, r)
    fs = np.unique(f[f > 0])
    grid_f = np.concatenate([fs, 0.5 * (fs[1:] + fs[:-1])])
    lo_f, hi_f = box[n_f]
    grid_f = grid_f[(grid_f >= lo_f) & (grid_f <= hi_f)]
    lo_q, hi_q = box[n_q]
    grid_q = np.geomspace(lo_q, hi_q, 7)[1:-1]
    best, where = -np.inf, {}
    for f0 in grid_f:
        for q in grid_q:
            c = h_rot * shape(f0, q)
            lm = _projected(np.column_stack([small, np.concatenate([c.real, c.imag])]), r) - base
            if lm > best:
                best, where = lm, {n_f: float(f0), n_q: float(q)}
    return where


@timed("loop scoring")
def _score(setup, data, res, cand, values, box) -> Score:
    problem, start, _ = _extended_problem(setup, data, res, cand, values, box, res.weights)
    names = problem.space.names
    theta = np.array([start[n] for n in names])
    J = problem.jacobian_theta(theta)
    r = problem.residuals_theta(theta)
    J_small, new = _current_directions(cand, J, names, values, res.parameter_names)
    from scipy.stats import chi2 as chi2_dist

    if not new:
        # a term without parameters (transverse shear): the extended model at the current
        # values differs from the current one by d; score along that secant, one dof
        u = res.used
        rc = (res.model_afc[u] - res.H[u]) / res.weights
        r0 = np.concatenate([rc.real, rc.imag])
        d = r - r0
        lm = max(_projected(np.column_stack([J, d]), r0) - _projected(J, r0), 0.0)
        return Score(cand.name, float(lm), 1, float(chi2_dist.sf(lm, 1)),
                     _collinearity(J, d[:, None]))
    lm = max(_projected(J, r) - _projected(J_small, r), 0.0)
    dof = len(names) - len(res.parameter_names)
    return Score(cand.name, float(lm), dof, float(chi2_dist.sf(lm, dof)),
                 _collinearity(J_small, J[:, new]))


def _current_directions(cand, J, names, values, current_names):
    """The current model's sensitivities inside the extended model's (its tangent space at
    the null), and the indices of the extension's new directions."""
    i = {n: k for k, n in enumerate(names)}
    shared = [i[n] for n in current_names if n in i]
    if cand.name != "anisotropy":
        return J[:, shared], [k for k in range(len(names)) if k not in shared]
    D, nu = values["D"], values["nu"]  # d(D11, D12, D22, D66) / d(D, nu) at the null
    jD = J[:, i["D11"]] + nu * J[:, i["D12"]] + J[:, i["D22"]] + 0.5 * (1 - nu) * J[:, i["D66"]]
    jnu = D * J[:, i["D12"]] - 0.5 * D * J[:, i["D66"]]
    return np.column_stack([jD, jnu] + [J[:, k] for k in shared]), [i["D22"], i["D66"]]


def _projected(J, r) -> float:
    """``rᵀ P r``, P the projector onto the columns of J (scale-invariant, rank-safe)."""
    scale = np.linalg.norm(J, axis=0)
    Jn = J / np.where(scale > 0, scale, 1.0)
    Q, s, _ = np.linalg.svd(Jn, full_matrices=False)
    Q = Q[:, s > 1e-10 * s.max()]
    return float(np.sum((Q.T @ r) ** 2))


def _collinearity(J_old, J_new) -> float:
    """How much of the extension the current parameters can mimic: the cosine between a
    new direction and the span of the current ones (the smallest over the new directions:
    the data see the extension through its least mimicked direction)."""
    Q, s, _ = np.linalg.svd(J_old / np.linalg.norm(J_old, axis=0), full_matrices=False)
    Q = Q[:, s > 1e-10 * s.max()]
    cos = [np.linalg.norm(Q.T @ v) / np.linalg.norm(v) for v in J_new.T if np.linalg.norm(v) > 0]
    return float(min(cos)) if cos else math.nan


def _refit_starts(space, u0, new, current_names) -> list[np.ndarray]:
    """Starts of a refit: the current estimate, and it with the new parameters at
    :data:`REFIT_STARTS_U`. Where current parameters lie outside their prior box (an
    effect the declared model lacked pushed them there), the same again with those moved
    just inside it: the extended model may explain the data inside the box, in a basin the
    current estimate does not reach."""
    out = set(space.out_of_bounds(space.theta(u0))) & set(current_names)
    outside = [i for i, n in enumerate(space.names) if n in out]
    bases = [u0]
    if outside:
        moved = u0.copy()
        moved[outside] = np.clip(moved[outside], -INSIDE_U, INSIDE_U)
        centred = u0.copy()
        centred[outside] = 0.0  # a physical value, far from the bent one
        bases += [moved, centred]
    starts = []
    for base in bases:
        starts.append(base)
        for v in REFIT_STARTS_U if new else ():
            u = base.copy()
            u[new] = v
            starts.append(u)
    return starts


@timed("loop refits")
def _refit(setup, data, res, cand, values, box, local, search: bool = False):
    """Local fits of the extended model from the current estimate (several starts along the
    new parameters), then the full identification from the best; returns (stage, Δχ²).
    With ``search``, when the local refit did not converge or does not fit the noise (the
    current estimate may lie in a wrong basin of the extended model: an orthotropic plate
    fitted as isotropic), also a global search of the extended model over its prior box
    (on the resonance peaks first for a :attr:`Candidate.peaks_first` candidate, then on
    chi2 unless that fits the noise), and the best converged one (chi2 under the current
    weights)."""
    problem, start, ext_box = _extended_problem(setup, data, res, cand, values, box, res.weights)
    space = problem.space
    names = space.names
    with np.errstate(divide="ignore"):  # a null on a log parameter's edge: u = -inf
        u0 = space.to_u(np.array([start[n] for n in names]))
    new = [i for i, n in enumerate(names) if n not in res.parameter_names]
    if cand.name != "anisotropy":  # a resonance's f and q come from the score's scan
        term = cand.term_after(res.parameter_names)
        scanned = set(term.names) - set(term.null_values(values))
        new = [i for i in new if names[i] not in scanned]
    starts = _refit_starts(space, np.clip(u0, -5, 5), new, res.parameter_names)
    run = LOCAL_METHODS[local]
    runs = [run(problem.with_model(problem.model.refresh(space.theta(u))), u) for u in starts]
    runs.sort(key=lambda r: r.loss if np.isfinite(r.loss) else np.inf)
    inside = best_inside_prior(runs, space, max(1.0, float(res.chi2_reduced)))
    best = inside if inside is not None else runs[0]
    fm = problem.model.refresh(best.theta)
    result = identify(setup, data.frequency_hz, data.H, data.std, used=data.used,
                      model=fm.param.model, forward_model=fm, method="local",
                      start=dict(zip(names, best.theta)), bounds=ext_box, local=local)
    loss = best.loss

    def done(r) -> bool:
        # a refit that did not converge fits nothing, whatever its chi2 (a runaway's model
        # error can swamp its own weights)
        return r.converged and bool(fits_noise(r.chi2, r.dof, True))

    if search and not done(result):
        from vibid.identify.model.forward import build_forward_model

        wide = build_forward_model(setup, data.frequency_hz[data.used], model=fm.param,
                                   bounds=ext_box)
        # anisotropy: the resonance peaks first (cheap), chi2's search if that fit does
        # not reach the noise (on a coarse grid the peaks leave neighbouring basins open)
        peaks = cand.peaks_first and gives_modes(wide)
        for peaks_only in ([start] if peaks else []) + [None]:
            found = identify(setup, data.frequency_hz, data.H, data.std, used=data.used,
                             model=fm.param.model, forward_model=wide, bounds=ext_box,
                             restarts=3, seed=0, local=local, peaks_only=peaks_only)
            local_model = problem.model.refresh(found.values)
            found_loss = problem.with_model(local_model).chi2(space.to_u(found.values))
            log.info("loop: %s searched globally%s, chi2 %.6g (local refit %.6g)", cand.name,
                     " on its peaks" if peaks_only else "", found_loss, loss)
            if found.converged and found_loss < loss:
                result, loss = found, found_loss
            if done(result):
                break
    log.info("loop: %s refitted, chi2 %.6g -> %.6g", cand.name, res.chi2, loss)
    return _stage(cand.name, result), float(res.chi2 - loss)
