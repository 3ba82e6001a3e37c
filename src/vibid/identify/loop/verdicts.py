"""What the loop reports: each candidate's verdict, each stage, the whole loop.

Every outcome of a candidate is a :class:`Verdict` that maps to the sentence the report
prints (the shape of :class:`vibid.identify.fit.result.Status`).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from vibid.identify.fit.noise import explains, whiteness_p
from vibid.identify.fit.result import IdentificationResult


class Verdict(enum.Enum):
    """What became of a candidate in a round."""

    CHOSEN = "chosen"
    EXPLAINS_EXCURSION = "explains_excursion"
    KEPT_BACK = "kept_back"
    OUTRANKED = "outranked"
    NOT_SCORED = "not_scored"
    BELOW_SCORE = "below_score"
    TOO_FEW_POINTS = "too_few_points"
    NO_MODE_PATTERN = "no_mode_pattern"
    NOT_REFITTED = "not_refitted"
    REFIT_FAILED = "refit_failed"
    NOT_CONVERGED = "not_converged"
    AT_NULL = "at_null"
    LEFT_ITS_FEATURE = "left_its_feature"
    OUTSIDE_PRIOR = "outside_prior"
    WITHIN_MISFIT = "within_misfit"
    NO_STRUCTURE = "no_structure"
    NOT_SIGNIFICANT = "not_significant"
    WITHDRAWN = "withdrawn"

    @property
    def passes(self) -> bool:
        """Whether the refit passed the judge (chosen or not)."""
        return self in (Verdict.CHOSEN, Verdict.EXPLAINS_EXCURSION, Verdict.KEPT_BACK,
                        Verdict.OUTRANKED)

    @property
    def compared(self) -> bool:
        """Whether the refit is a model the data support (converged, away from its null,
        significant), kept or not: the budget's spread is over these
        (:func:`vibid.identify.budget.model_spread`)."""
        return self.passes or self in (Verdict.WITHIN_MISFIT, Verdict.NO_STRUCTURE)

    def sentence(self, **d) -> str:
        """The report's note; ``d`` holds the numbers it quotes."""
        return {
            Verdict.CHOSEN: (f"added: it explains what the residual showed ({d['feature']})"
                             if d.get("feature") else "added: it explains the residual best"),
            Verdict.EXPLAINS_EXCURSION: (
                f"added: it brings {d.get('outside', 'the estimate')} back inside the prior "
                "box at a chi2 the data cannot tell from the current one (the excursion was "
                "this effect)"),
            Verdict.KEPT_BACK: (
                f"kept back: it leaves {d.get('left', 'a parameter')} outside the prior box, "
                "and an effect that brings the estimate back inside it goes first"),
            Verdict.OUTRANKED: f"it passes, but {d.get('by', 'another')} explains the "
                               "residual better or more plainly (a candidate next round)",
            Verdict.NOT_SCORED: f"could not be scored: {d.get('error', '')}",
            Verdict.BELOW_SCORE: "its score test does not ask for it (p "
                                 f"{d.get('p', math.nan):.2g})",
            Verdict.TOO_FEW_POINTS: (
                f"not refitted: too few points for its {d.get('n', '?')} parameters "
                f"({d.get('residuals', '?')} real residuals)"),
            Verdict.NO_MODE_PATTERN: (
                f"not refitted: the band holds {d.get('modes', '?')} of the plate's modes, "
                f"which the current material places; a new material needs "
                f"{d.get('needed', '?')} for their pattern to ask for it"),
            Verdict.NOT_REFITTED: (
                f"not refitted: {d.get('by', 'another candidate')} already fits the residual "
                "to the noise level" if d.get("by") else
                "not refitted: lower scores than the ones refitted"),
            Verdict.REFIT_FAILED: f"refit failed: {d.get('error', '')}",
            Verdict.NOT_CONVERGED: f"the refit did not converge ({d.get('message', '')})",
            Verdict.AT_NULL: (
                f"the refit takes it to its null value, beyond its box: {d['beyond']}"
                if d.get("beyond") else
                f"the refit leaves it at its null value ({d.get('z', math.nan):.2g} std "
                "from it)"),
            Verdict.LEFT_ITS_FEATURE: (
                f"{d.get('moved', 'it left the feature it was added for')}: it explains "
                "another structure than the one the diagnosis found"),
            Verdict.OUTSIDE_PRIOR: (
                f"its refit explains the residual only with {d.get('left', 'a parameter')} "
                "outside the prior box, which the current fit kept inside: no physical "
                "explanation"),
            Verdict.WITHIN_MISFIT: (
                f"it lowers chi2 by {d.get('gain', math.nan):.3g}, no more than a parameter "
                "that explains nothing removes from a misfit this large and this smooth (needs "
                f"{d.get('need', math.nan):.3g}: chi-square's 0.99 quantile times the reduced "
                f"chi2 {d.get('birge', math.nan):.3g} times {d.get('tau', math.nan):.3g} "
                "neighbouring points per independent one along the change it makes)"),
            Verdict.NO_STRUCTURE: (
                f"it lowers chi2 significantly but removes no structure the diagnosis found "
                f"and leaves {d.get('left_share', math.nan):.2g} % of the misfit: a share of "
                "a misfit that remains is no explanation of it"),
            Verdict.NOT_SIGNIFICANT: "the refit does not improve chi2 significantly",
            Verdict.WITHDRAWN: (
                f"withdrawn: added in an earlier round, it lies at its null value once "
                f"{d.get('by', 'the new effect')} is in the model ({d.get('z', math.nan):.2g} "
                "std from it), and the data cannot tell the model without it from the one "
                "with it"),
        }[self] + (" (global search)" if d.get("searched") else "") + (
            f"; {d['held']}" if d.get("held") else "")


#: The verdicts of a refit that moved its effect off its null and was not kept: what may
#: have come close to explaining a residual that remains (not one at its null, whose chi2
#: drop is the other parameters' or round-off's, nor a refit that failed).
CLOSE_CALLS = frozenset({Verdict.WITHIN_MISFIT, Verdict.OUTSIDE_PRIOR, Verdict.NO_STRUCTURE,
                         Verdict.LEFT_ITS_FEATURE, Verdict.KEPT_BACK,
                         Verdict.NOT_SIGNIFICANT})


def is_close_call(verdict, delta_chi2) -> bool:
    """Whether a refit (its verdict, a :class:`Verdict` or its report name, and the chi2 it
    removed) may have come close to explaining a residual that remains: one of
    :data:`CLOSE_CALLS` that lowered chi2."""
    return (Verdict(verdict) in CLOSE_CALLS and delta_chi2 is not None
            and math.isfinite(delta_chi2) and delta_chi2 > 0)


@dataclass(frozen=True)
class Score:
    """A candidate scored at the current fit, refitted if it scored high enough, and its
    verdict."""

    name: str
    score: float  # LM statistic
    dof: int
    p_value: float
    collinearity: float  # 0: orthogonal to the current parameters, 1: indistinguishable
    delta_chi2: float = math.nan  # the refit's likelihood ratio (same weights), if refitted
    verdict: Verdict = Verdict.BELOW_SCORE
    detail: tuple = ()  # (key, value) pairs the verdict's sentence quotes
    asked: bool = False  # whether the diagnosis found a feature it explains

    @property
    def kept(self) -> bool:
        """Whether the loop added it this round."""
        return self.verdict in (Verdict.CHOSEN, Verdict.EXPLAINS_EXCURSION)

    @property
    def note(self) -> str:
        return self.verdict.sentence(**dict(self.detail))


@dataclass(frozen=True)
class Judgement:
    """The judge's word on one candidate in a round: its verdict, the numbers the
    verdict's sentence quotes, its refit (None where it was not refitted), the names of
    the refit's parameters outside their prior box, and the diagnosis of a passing refit's
    residual (read on the refit's own thread)."""

    verdict: Verdict
    detail: tuple = ()
    fit: object = None  # :class:`vibid.identify.loop.refit.Refit`
    left: tuple[str, ...] = ()
    diagnosis: object = None  # :class:`vibid.identify.diagnosis.Diagnosis`

    @property
    def gain(self) -> float:
        """The refit's likelihood ratio under the current fit's weights (nan unrefitted)."""
        return self.fit.gain if self.fit is not None else math.nan

    def becomes(self, verdict: Verdict, **more) -> "Judgement":
        """This judgement with another verdict and more numbers for its sentence."""
        return Judgement(verdict, self.detail + tuple(more.items()), self.fit, self.left,
                         self.diagnosis)


@dataclass(frozen=True)
class Stage:
    """The model after one step of the loop (``added`` None for the declared model), and
    what its residual shows."""

    added: str | None
    result: IdentificationResult
    ljung_box_p: float = math.nan
    diagnosis: object = None
    #: parameters its refit held at the previous stage's values (:mod:`~vibid.identify.
    #: loop.held`): its estimate is no minimum of chi2 along them
    held: tuple[str, ...] = ()

    @classmethod
    def of(cls, added, result: IdentificationResult) -> "Stage":
        return cls(added, result, whiteness_p(result))

    @property
    def fits_noise(self) -> bool:
        return bool(explains(self.result))


@dataclass(frozen=True)
class LoopResult:
    stages: tuple[Stage, ...]
    rounds: tuple[tuple[Score, ...], ...]
    unexplained_residual: bool
    warnings: tuple[str, ...] = field(default=())
    seconds: float = math.nan
    #: the refits the data support (:attr:`Verdict.compared`) that were not chosen: with
    #: the stages, the models the loop compared (the uncertainty budget's model part,
    #: :mod:`vibid.identify.budget`)
    alternatives: tuple = ()

    @property
    def final(self) -> IdentificationResult:
        return self.stages[-1].result

    @property
    def effects(self) -> tuple[str, ...]:
        return tuple(s.added for s in self.stages[1:])

    def closest(self) -> "Score | None":
        """Where a residual remains: the candidate of the last round that lowered chi2 most
        and was not kept, among :data:`CLOSE_CALLS` (what came closest to explaining it), or
        None."""
        if not self.unexplained_residual or not self.rounds:
            return None
        tried = [s for s in self.rounds[-1] if is_close_call(s.verdict, s.delta_chi2)]
        return max(tried, key=lambda s: s.delta_chi2, default=None)

    def summary(self) -> str:
        """The error before and after, stage by stage, then the final model's summary."""
        lines = ["closed loop:"]
        for st in self.stages:
            r = st.result
            what = "declared model" if st.added is None else f"+ {st.added}"
            lines.append(f"  {what:<28} chi2_reduced {r.chi2_reduced_reported:10.4g}  "
                         f"rel_rms_residual {r.rel_rms_residual:.3g}  whiteness p "
                         f"{st.ljung_box_p:.2g}")
            for f in getattr(st.diagnosis, "features", ()):
                lines.append(f"      residual: {f.note}")
        lines.append("  the residual " + ("still holds an effect no candidate explains "
                                          "(unexplained_residual)" if self.unexplained_residual
                                          else "is at the noise level"))
        closest = self.closest()
        if closest is not None:
            last = self.stages[min(len(self.rounds), len(self.stages)) - 1].result
            share = closest.delta_chi2 / (last.chi2_reduced_reported * last.dof)
            lines.append(f"  closest: {closest.name} (chi2 -{closest.delta_chi2:.3g}, "
                         f"{100 * share:.0f} % of the misfit): {closest.note}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines) + "\n" + self.final.summary()
