"""What the loop reports: each candidate's verdict, each stage, the whole loop.

Every outcome of a candidate is a :class:`Verdict` (its kind) with the numbers its sentence
quotes (``detail``); the sentence the report prints is the report's
(:func:`vibid.report.wording.verdict_sentence`, the shape of
:class:`vibid.identify.fit.result.Status`).
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
    LESS_PROBABLE = "less_probable"
    #: refitted and weighed (:func:`~vibid.identify.loop.choose.compare` then decides)
    COMPARED = "compared"
    NOT_SCORED = "not_scored"
    TOO_FEW_POINTS = "too_few_points"
    NO_MODE_PATTERN = "no_mode_pattern"
    NOT_REFITTED = "not_refitted"
    REFIT_FAILED = "refit_failed"
    NOT_CONVERGED = "not_converged"
    WITHDRAWN = "withdrawn"

    @property
    def compared(self) -> bool:
        """Whether the refit is a model the round compared (converged, its evidence
        weighed), chosen or not: the budget's spread is over these
        (:func:`vibid.identify.assess.budget.model_spread`)."""
        return self in (Verdict.CHOSEN, Verdict.LESS_PROBABLE, Verdict.COMPARED)


#: The verdicts of a refit the round compared and did not choose: what may have come
#: close to explaining a residual that remains.
CLOSE_CALLS = frozenset({Verdict.LESS_PROBABLE})


def is_close_call(verdict, delta_chi2) -> bool:
    """Whether a refit (its verdict, a :class:`Verdict` or its report name, and the chi2 it
    removed) may have come close to explaining a residual that remains: one of
    :data:`CLOSE_CALLS` that lowered chi2."""
    try:
        verdict = Verdict(verdict)
    except ValueError:  # a report written by an earlier loop
        return False
    return (
        verdict in CLOSE_CALLS
        and delta_chi2 is not None
        and math.isfinite(delta_chi2)
        and delta_chi2 > 0
    )


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
    verdict: Verdict = Verdict.COMPARED
    detail: tuple = ()  # (key, value) pairs the verdict's sentence quotes
    #: its log evidence (:mod:`~vibid.identify.loop.evidence`): its refit's, or where it
    #: was not refitted (``estimated``) the score test's approximation
    log_evidence: float = math.nan
    probability: float = math.nan  # its posterior share among the round's explanations
    estimated: bool = False
    at_hz: float | None = None  # where a resonance was tried

    @property
    def kept(self) -> bool:
        """Whether the loop added it this round."""
        return self.verdict is Verdict.CHOSEN

    @property
    def note(self) -> str:
        """Its verdict in the report's words (:func:`vibid.report.wording.verdict_sentence`)."""
        from vibid.report.wording import verdict_sentence

        return verdict_sentence(self.verdict, self.detail)


@dataclass(frozen=True)
class Judgement:
    """The round's word on one candidate: its verdict, the numbers the verdict's sentence
    quotes, its refit (None where it was not refitted) and the refit's log evidence."""

    verdict: Verdict
    detail: tuple = ()
    fit: object = None  # :class:`vibid.identify.loop.refit.Refit`
    evidence: float = math.nan  # the refit's log evidence

    @property
    def gain(self) -> float:
        """The refit's likelihood ratio under the current fit's weights (nan unrefitted)."""
        return self.fit.gain if self.fit is not None else math.nan

    def becomes(self, verdict: Verdict, **more) -> Judgement:
        """This judgement with another verdict and more numbers for its sentence."""
        return Judgement(verdict, self.detail + tuple(more.items()), self.fit, self.evidence)


@dataclass(frozen=True)
class Stage:
    """The model after one step of the loop (``added`` None for the declared model), and
    what its residual shows."""

    added: str | None
    result: IdentificationResult
    ljung_box_p: float = math.nan
    diagnosis: object = None
    #: the fitted plate's first modes (:class:`~vibid.identify.model.plate.Modes`, None
    #: where they could not be computed): asked of the plate once per stage
    modes: object = None
    #: parameters its refit held at the previous stage's values (:mod:`~vibid.identify.
    #: loop.held`): its estimate is no minimum of chi2 along them
    held: tuple[str, ...] = ()
    #: the explanations compared at this stage, the chosen first (each ``{"added": name or
    #: None for stopping here, "criterion": log evidence, "probability": ..}``, report
    #: format ``loop.stages[].alternatives``); empty where none was compared
    alternatives: tuple = ()

    @classmethod
    def of(cls, added, result: IdentificationResult) -> Stage:
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
    #: :mod:`vibid.identify.assess.budget`)
    alternatives: tuple = ()

    @property
    def criterion(self) -> dict:
        """The report's ``loop.criterion``: the loop's one criterion and what it means."""
        from vibid.identify.loop.evidence import CRITERION, MEANING

        return {"name": CRITERION, "meaning": MEANING}

    @property
    def final(self) -> IdentificationResult:
        return self.stages[-1].result

    @property
    def effects(self) -> tuple[str, ...]:
        return tuple(s.added for s in self.stages[1:])

    def closest(self) -> Score | None:
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
            lines.append(
                f"  {what:<28} chi2_reduced {r.chi2_reduced_reported:10.4g}  "
                f"rel_rms_residual {r.rel_rms_residual:.3g}  whiteness p "
                f"{st.ljung_box_p:.2g}"
            )
            for f in getattr(st.diagnosis, "features", ()):
                lines.append(f"      residual: {f.note}")
            if st.alternatives:
                lines.append(
                    "      compared: "
                    + "; ".join(
                        ("stop here" if a["added"] is None else a["added"])
                        + (f" at {a['f_hz']:.4g} Hz" if a.get("f_hz") else "")
                        + f" {a['probability']:.2g}"
                        + (" (estimated)" if a.get("estimated") else "")
                        for a in st.alternatives[:4]
                    )
                )
        lines.append(
            "  the residual "
            + (
                "still holds an effect no candidate explains (unexplained_residual)"
                if self.unexplained_residual
                else "is at the noise level"
            )
        )
        closest = self.closest()
        if closest is not None:
            last = self.stages[min(len(self.rounds), len(self.stages)) - 1].result
            share = closest.delta_chi2 / (last.chi2_reduced_reported * last.dof)
            lines.append(
                f"  closest: {closest.name} (chi2 -{closest.delta_chi2:.3g}, "
                f"{100 * share:.0f} % of the misfit): {closest.note}"
            )
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines) + "\n" + self.final.summary()
