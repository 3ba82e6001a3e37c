"""A round's last step: every explanation compared by its evidence, the most probable chosen."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from vibid.identify.loop.evidence import probabilities
from vibid.identify.loop.policy import Policy
from vibid.identify.loop.state import STOP
from vibid.identify.loop.verdicts import Verdict


def compare(scores, judged: dict, log_z_now: float, policy: Policy):
    """Every explanation of the round by its evidence: returns the scores with their final
    verdicts and probabilities, the name chosen (:data:`STOP` for the current model), and
    the stage's alternatives (the report's ``loop.stages[].alternatives``, the chosen
    first).

    The model prior: :attr:`Policy.stop_prior` on "the current model is complete", the
    rest spread evenly over the round's candidates. The probabilities are shares among the
    fitted explanations and stopping, and the most probable is chosen: only a fit is a
    model. A candidate that was not refitted keeps its approximate evidence in its score
    (marked estimated), with no share."""
    names = [s.name for s in scores]
    log_z = {STOP: log_z_now}
    estimated = set()
    for s in scores:
        j = judged.get(s.name)
        if j is not None and j.verdict is Verdict.COMPARED:
            log_z[s.name] = j.evidence
        elif j is not None and j.verdict is Verdict.NOT_REFITTED and np.isfinite(s.log_evidence):
            log_z[s.name] = s.log_evidence
            estimated.add(s.name)
        else:
            log_z[s.name] = -math.inf
    share = (1.0 - policy.stop_prior) / max(len(names), 1)
    prior = {STOP: policy.stop_prior} | {n: share for n in names}
    prob = probabilities({k: (-math.inf if k in estimated else z) for k, z in log_z.items()}, prior)
    fitted = [k for k in log_z if k is STOP or (k not in estimated and np.isfinite(log_z[k]))]
    chosen = max(fitted, key=lambda k: (prob[k], log_z[k]))
    for k in estimated:
        prob[k] = math.nan
    by = "stopping here" if chosen is STOP else chosen
    out = []
    for s in scores:
        j = judged.get(s.name)
        verdict, detail = (j.verdict, j.detail) if j is not None else (s.verdict, s.detail)
        if s.name == chosen:
            verdict = Verdict.CHOSEN
        elif verdict is Verdict.COMPARED:
            verdict = Verdict.LESS_PROBABLE
        detail = detail + (
            ("probability", prob[s.name]),
            ("by", by),
            ("by_probability", prob[chosen]),
            ("log_evidence", log_z[s.name]),
        )
        out.append(
            replace(
                s,
                verdict=verdict,
                detail=detail,
                probability=prob[s.name],
                log_evidence=log_z[s.name],
                estimated=s.name in estimated,
                delta_chi2=j.gain if j is not None else math.nan,
            )
        )
    at = {
        s.name: dict(judged[s.name].detail).get("f_hz", s.at_hz) if s.name in judged else s.at_hz
        for s in scores
    }
    order = sorted(fitted, key=lambda k: (k != chosen, -prob[k], -log_z[k]))
    shares = tuple(
        {"added": k, "criterion": log_z[k], "probability": prob[k]}
        | (
            {"f_hz": at[k]}
            if k is not STOP and at.get(k) is not None and np.isfinite(at[k])
            else {}
        )
        for k in order
    )
    return out, chosen, shares
