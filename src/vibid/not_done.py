"""What a report could not do: a stage after the fit that fails leaves the fit's result in
the report and says, in one line, what is missing and why.

The identification's result is the job's work (the loop's minutes, the stand's hours). A
later stage — the engineering constants, their uncertainty budget, the plausibility, the
reference specimen's calibration, the linearity tests, the figures, ``report.md`` — that
fails must not lose it. Each such stage runs through :func:`attempt`: its failure becomes
one entry of the report's list ``not_done`` (an additive field of
shared/spec/report-format.md, present in every report, empty when every stage was done)::

    "not_done": [{"stage": "uncertainty budget",
                  "reason": "no bounds given for D11, D12, D22, D66"}]

``stage`` names what is missing (:data:`STAGES`), ``reason`` is the failure in one line.
The console says each in one line (:func:`not_done_lines`, among
:func:`vibid.report.console.plausibility_lines`), the report is written with the rest,
and the command's exit code is the identification's own (0 when it converged).
"""

from __future__ import annotations

import logging

#: The report's key.
NOT_DONE = "not_done"

#: The stages after the fit that may be missing from a report, by the name an entry gives
#: them, with what their absence leaves out.
STAGES = {
    "engineering constants": "no engineering block",
    "uncertainty budget": "the engineering constants carry the fit's std alone",
    "plausibility": "no plausibility block",
    "reference": "no reference block",
    "linearity": "no linearity block",
    "figures": "report.md goes without it",
    "report.md": "report.json alone",
}

log = logging.getLogger(__name__)


def reason(exc: BaseException) -> str:
    """``exc`` in one line: its message (a :class:`~vibid.errors.VibidError`'s is the
    user's sentence), prefixed by the exception's type for any other."""
    from vibid.errors import VibidError

    text = " ".join(str(exc).split())
    if isinstance(exc, VibidError):
        return text or type(exc).__name__
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def attempt(stage: str, not_done: list, fn, *args, default=None, about: str = "", **kwargs):
    """``fn(*args, **kwargs)``; where it raises (an :class:`Exception`: an interrupt still
    stops the job), ``default``, with ``{"stage": stage, "reason": ...}`` appended to
    ``not_done`` (the reason prefixed by ``about``, the part of the stage that failed; the
    traceback goes to this module's logger at DEBUG)."""
    if stage not in STAGES:
        raise ValueError(f"unknown report stage {stage!r}: expected one of {', '.join(STAGES)}")
    try:
        return fn(*args, **kwargs)
    except Exception as exc:  # the fit's result stays; the report says why
        log.debug("report stage %r could not be done", stage, exc_info=True)
        not_done.append(
            {"stage": stage, "reason": f"{about}: {reason(exc)}" if about else reason(exc)}
        )
        return default


def not_done_lines(report: dict) -> list[str]:
    """One console line per stage the report could not do (its ``not_done``)."""
    return [
        f"not done: {e['stage']} ({STAGES.get(e['stage'], 'left out')}): {e['reason']}"
        for e in report.get(NOT_DONE) or ()
    ]
