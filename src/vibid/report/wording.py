"""The report's words: each status, verdict and judgement turned into the sentence a person
at the stand reads. The results hold the kinds and the numbers (an optimiser's
:class:`~vibid.identify.fit.result.Status`, a loop candidate's
:class:`~vibid.identify.loop.verdicts.Verdict` with its ``detail``, an
:class:`~vibid.identify.assess.Assessment`); this module alone says them.

Every status maps to a sentence that tells what happened and what to do (the shape of
optimistix's ``RESULTS``); nothing is returned without one, and a run that did not
converge says so. Every verdict of a candidate maps to the note the report prints; the
numbers it quotes are the round's (``detail``: the loop's policy numbers among them, as
the round used them).

Importing it loads nothing beyond the standard library.
"""

from __future__ import annotations

import math

#: What each :class:`~vibid.identify.fit.result.Status` (by its value) says.
STATUS_WORDS = {
    "converged": "converged",
    "max_iterations": (
        "did not converge within the iteration limit: the estimate is not a minimum; "
        "allow more iterations or start closer (a global search)"
    ),
    "stalled": (
        "stalled: the trust region shrank to nothing before the gradient vanished; "
        "the loss is not smooth there (check the model's accuracy and the data)"
    ),
    "not_finite": "the loss or the estimate is not finite: check the data and the start values",
    "at_physical_limit": (
        "stopped at the end of a parameter's physical range, where no plate is: "
        "not a converged estimate; check that the data hold the plate's response "
        "and that the setup declares this specimen"
    ),
    "failed": "failed",
}


def status_sentence(status, detail: str = "") -> str:
    """The sentence of ``status`` (a :class:`~vibid.identify.fit.result.Status`), with its
    ``detail`` in parentheses where given."""
    base = STATUS_WORDS[status.value]
    return f"{base} ({detail})" if detail else base


def _not_refitted(d: dict) -> str:
    if d.get("fitted_by"):
        return (
            f"not refitted: {d['fitted_by']}'s refit already fits the residual to the noise level"
        )
    return (
        "not refitted: its evidence estimated from the score test (log evidence "
        f"{d.get('log_evidence', math.nan):.4g}) ranks below the refits the round could afford"
    )


def _withdrawn(d: dict) -> str:
    """A withdrawal's sentence: by a later addition (``by``), or by the loop's test of its
    last addition from the final estimate (``final``)."""
    if d.get("final"):
        how, then = "withdrawn at the end: refitted without it from the loop's final estimate", ","
    else:
        by = d.get("by", "the new effect")
        how, then = f"withdrawn: added in an earlier round, once {by} is in the model", ""
    return (
        f"{how} ({d.get('z', math.nan):.2g} std from its null there){then} the model without "
        f"it is the more probable (log odds {d.get('odds', math.nan):.3g})"
    )


def _verdict_words(kind: str, d: dict) -> str:
    """The sentence of the verdict ``kind`` (its value) quoting the numbers ``d``."""
    p = d.get("probability", math.nan)
    by, p_by = d.get("by", "another"), d.get("by_probability", math.nan)
    if kind == "not_refitted":
        return _not_refitted(d)
    return {
        "chosen": f"added: the most probable explanation (probability {p:.2g})",
        "less_probable": f"compared: probability {p:.2g}, against {p_by:.2g} for {by}",
        "compared": "refitted and weighed",
        "not_scored": f"could not be scored: {d.get('error', '')}",
        "too_few_points": (
            f"not refitted: too few points for its {d.get('n', '?')} parameters "
            f"({d.get('residuals', '?')} real residuals)"
        ),
        "no_mode_pattern": (
            f"not refitted: the band holds {d.get('modes', '?')} of the plate's modes, "
            f"which the current material places; a new material needs "
            f"{d.get('needed', '?')} for their pattern to ask for it"
        ),
        "refit_failed": f"refit failed: {d.get('error', '')}",
        "not_converged": f"the refit did not converge ({d.get('message', '')})",
        "withdrawn": _withdrawn(d),
    }[kind]


def verdict_sentence(verdict, detail=()) -> str:
    """The report's note on a loop candidate: its ``verdict`` (a
    :class:`~vibid.identify.loop.verdicts.Verdict`) quoting ``detail`` (the ``(key,
    value)`` pairs, or a dict, of the round's numbers), how it was refitted and what its
    refit held."""
    d = dict(detail)
    return (
        _verdict_words(verdict.value, d)
        + (" (global search)" if d.get("searched") else "")
        + (f"; {d['held']}" if d.get("held") else "")
    )


def free_length_sentence(found) -> str:
    """The warning of a :class:`~vibid.identify.assess.FreeLengthShare`."""
    stiff = found.stiffness
    return (
        f"free_length: dL carries {100 * found.share:.0f} % of the variance of {stiff} (and so "
        f"of E): with dL known, {stiff}'s std would be {found.known_std:.3g} instead of "
        f"{found.std:.3g} N m"
    )


#: The warning of a fit whose AFC has no uncertainty.
NOISE_UNKNOWN = (
    "the AFC's uncertainty is unknown: the fit cannot be tested against "
    "the noise (unexplained_residual is false by default)"
)


def loop_tried(loop) -> str:
    """What the closed loop tried and added, appended to each physically impossible value
    the plausibility names (``loop`` a :class:`~vibid.identify.loop.LoopResult` or None)."""
    if loop is None:
        return " (the closed loop did not run)"
    names = sorted({s.name for rnd in loop.rounds for s in rnd})
    return (
        f" (the closed loop tried {', '.join(names) or 'no candidate'}"
        f" and added {', '.join(loop.effects) or 'none'})"
    )
