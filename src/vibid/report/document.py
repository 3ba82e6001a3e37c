"""The identification report (shared/spec/report-format.md, version 1), as a JSON document.

:func:`build_report` turns an :class:`~vibid.identify.fit.result.IdentificationResult` (one
loop stage: the declared model alone) and what the assess stage judged of it (an
:class:`~vibid.identify.assess.Assessment`) into the report's dict; it computes nothing of
its own. :func:`write_report` writes it. Extra keys the format allows: ``plausibility``
(constants no material allows, and the comparison with the specimen's material class),
``linearity`` (whether each resolved measured resonance is a linear one),
``identification`` (status sentence, warnings, covariance, correlation, timings,
``data``: ``"complex"`` or ``"magnitude"`` and, for a magnitude-only fit,
``magnitude_only_std_ratio``; ``discretisation``: the model's meshes, measured order and
bias, :func:`discretisation_block`), the signal stage's ``afc.diagnostics`` when given,
and ``not_done``: the stages after the fit that could not be done, each
``{"stage": .., "reason": ..}`` in one line, the rest of the report written
(:mod:`vibid.not_done`; empty when every stage was done).
Non-finite numbers are written as null (JSON has no NaN).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from vibid.not_done import NOT_DONE
from vibid.report.wording import (
    NOISE_UNKNOWN,
    free_length_sentence,
    loop_tried,
    verdict_sentence,
)

FORMAT = "vibid.report"
FORMAT_VERSION = 1


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _nums(a) -> list:
    return [_num(v) for v in np.asarray(a, dtype=float).ravel()]


def afc_block(result) -> dict[str, Any]:
    """The ``afc`` block from the points the fit used."""
    u = np.asarray(result.used, bool)
    H = np.asarray(result.H)[u]
    std = None if result.H_std is None else np.asarray(result.H_std, float)[u]
    return {
        "frequency_hz": _nums(np.asarray(result.frequency_hz)[u]),
        "re": _nums(H.real),
        "im": _nums(H.imag),
        "std": [None] * int(u.sum()) if std is None else _nums(std),
    }


def plausibility_block(found, loop) -> dict:
    """The report's ``plausibility`` block of a
    :class:`~vibid.identify.assess.plausibility.Plausibility`: constants no material
    allows, with what the loop tried, and the comparison with the handbook range of the
    specimen's material class."""
    tried = loop_tried(loop)
    return {
        "material_class": found.material_class,
        "violations": [v + tried for v in found.violations],
        "outside_handbook": list(found.outside_handbook),
        "inside_handbook": list(found.inside_handbook),
    }


def engineering_block(constants: dict, budget: dict | None) -> dict:
    """The report's ``engineering`` block: each constant's value and std, and its
    uncertainty budget by part where one was made."""
    block = {
        k: {"value": _num(v["value"]), "std": None if v["std"] is None else _num(v["std"])}
        for k, v in constants.items()
    }
    if budget is not None:
        block["budget"] = {
            k: {part: _num(u) for part, u in parts.items()} for k, parts in budget.items()
        }
    return block


def assessed_blocks(assessment, loop) -> tuple[dict, list]:
    """(the report's blocks of the assess stage, in the report's order, with its
    ``not_done``; the warnings they add)."""
    extra, warnings = {}, []
    if tested := [t.as_report() for t in assessment.linearity]:
        extra["linearity"] = tested
        warnings.extend(t["note"] for t in tested if not t["linear"])
        warnings.extend(t.left_out_note for t in assessment.linearity if t.left_out_hz is not None)
    if assessment.constants is not None:
        extra["engineering"] = engineering_block(assessment.constants, assessment.budget)
    if assessment.plausibility is not None:
        extra["plausibility"] = plausibility_block(assessment.plausibility, loop)
        warnings.extend(extra["plausibility"]["violations"])
        warnings.extend(extra["plausibility"]["outside_handbook"])
    if assessment.reference is not None:
        extra["reference"] = assessment.reference
    extra[NOT_DONE] = list(assessment.not_done)
    return extra, warnings


def _stage_block(added, result) -> dict[str, Any]:
    return {
        "added": added,
        "chi2_reduced": _num(result.chi2_reduced_reported),
        # the fit's own weights add the model's estimated discretisation error
        "chi2_reduced_with_model_error": _num(result.chi2_reduced),
        "rel_rms_residual": _num(result.rel_rms_residual),
        "parameters": {n: _num(v) for n, v in zip(result.parameter_names, result.values)},
    }


def _effect_terms(loop) -> tuple:
    """The final model's effect terms (in their form for its material), in the order
    the loop added them."""
    model = getattr(loop.final, "plate_model", None)
    return tuple(model.effects) if model is not None else ()


def effects_block(loop) -> list[dict]:
    """The report's ``effects`` of a :class:`vibid.identify.loop.LoopResult`. An effect
    that occurs more than once has one entry per instance, ``"instance": k``, its
    parameters unsuffixed (report format, "Effect names")."""
    from vibid.parameters import split_instance

    final = loop.final
    std = dict(zip(final.parameter_names, final.std))
    effects = []
    for t in _effect_terms(loop):
        if t.name not in loop.effects:
            continue
        entry = {"name": t.name}
        if t.instance is not None:
            entry["instance"] = t.instance
        entry["parameters"] = {
            (split_instance(q.name)[0] if t.instance is not None else q.name): {
                "value": _num(final.parameters[q.name]),
                "std": _num(std[q.name]),
            }
            for q in t.parameters
        }
        effects.append(entry)
    return effects


def _score_entry(sc) -> dict[str, Any]:
    """One candidate of a round of the loop, in the report's ``loop.rounds``."""
    return {
        "candidate": sc.name,
        "score": _num(sc.score),
        "dof": sc.dof,
        "p_value": _num(sc.p_value),
        "collinearity": _num(sc.collinearity),
        "delta_chi2": _num(sc.delta_chi2),
        "kept": sc.kept,
        "log_evidence": _num(sc.log_evidence),
        "probability": _num(sc.probability),
        "estimated": sc.estimated,
        "verdict": sc.verdict.value,
        "note": verdict_sentence(sc.verdict, sc.detail),
    }


def _loop_block(loop) -> dict[str, Any]:
    """The report's ``loop`` block of a :class:`vibid.identify.loop.LoopResult`."""
    stages = []
    for st in loop.stages:
        block = _stage_block(st.added, st.result)
        block["ljung_box_p"] = _num(st.ljung_box_p)
        if st.alternatives:
            block["alternatives"] = [
                {k: (_num(v) if isinstance(v, float) else v) for k, v in a.items()}
                for a in st.alternatives
            ]
        stages.append(block)
    block = {
        "stages": stages,
        "unexplained_residual": bool(loop.unexplained_residual),
        "criterion": loop.criterion,
        "rounds": [[_score_entry(sc) for sc in rnd] for rnd in loop.rounds],
        "seconds": _num(loop.seconds),
    }
    if any(st.diagnosis is not None for st in loop.stages):
        block["diagnosis"] = [
            [] if st.diagnosis is None else st.diagnosis.as_report() for st in loop.stages
        ]
    return block


def discretisation_block(result) -> dict[str, Any] | None:
    """The report's ``identification.discretisation``: how the forward model estimated its
    discretisation error (Richardson's extrapolation over three meshes,
    :mod:`vibid.identify.model.model_error`) and the signed shift of the estimate it causes,
    per parameter (``model_error_bias``, whose b bᵀ the covariance holds); None where the
    fit estimated none."""
    info, bias = getattr(result, "discretisation", None), result.model_error_bias
    if info is None or bias is None:
        return None
    return {
        "meshes": list(info.meshes),
        "order": _num(info.order),
        "factor": _num(info.factor),
        "limited": bool(info.limited),
        "bias": {n: _num(b) for n, b in zip(result.parameter_names, bias)},
    }


def _fit_warnings(result, loop, assessment) -> list[str]:
    """The fit's and the loop's warnings, then what the assessment says of the fit."""
    warnings = list(result.warnings) + (list(loop.warnings) if loop is not None else [])
    if assessment.free_length is not None:
        warnings.append(free_length_sentence(assessment.free_length))
    if not result.noise_known:
        warnings.append(NOISE_UNKNOWN)
    return warnings


def _search_blocks(result) -> dict[str, Any]:
    """The report's ``identification.global_search`` and ``local_runs``."""
    g = result.global_result
    return {
        "global_search": None
        if g is None
        else {
            "restart_best": [dict(zip(result.parameter_names, _nums(t))) for t in g.theta],
            "restart_loss": _nums(g.loss),
            "evaluations": int(g.n_evaluations),
        },
        "local_runs": [
            {
                "method": r.method,
                "status": r.status.value,
                "message": r.message,
                "chi2": _num(r.loss),
                "iterations": r.n_iterations,
            }
            for r in result.local_results[:10]
        ],
    }


def identification_block(result, warnings: list, notes) -> dict[str, Any]:
    """The report's ``identification`` block; ``notes``: the engineering constants' budget
    in words (each one's largest part)."""
    names = result.parameter_names
    bias = result.model_error_bias
    block = {
        "status": result.status.value,
        "converged": result.converged,
        "message": result.message,
        "warnings": warnings,
        "noise_known": result.noise_known,
        # what the fit saw: the complex AFC, or |H| alone (--magnitude-only)
        "data": "magnitude" if result.magnitude else "complex",
        "chi2": _num(result.chi2),
        "chi2_reduced_data_weights": _num(result.chi2_reduced_data_weights),
        "model_error_std": None if bias is None else {n: _num(abs(b)) for n, b in zip(names, bias)},
        "discretisation": discretisation_block(result),
        "dof": int(result.dof),
        "parameter_names": list(names),
        "covariance": [_nums(row) for row in result.covariance],
        "correlation": [_nums(row) for row in result.correlation],
        **_search_blocks(result),
        "seconds": _num(result.seconds),
        "uncertainty_notes": list(notes),
    }
    if result.magnitude_only_std_ratio is not None:
        # each std over the complex fit's of the same points (both Fisher informations)
        block["magnitude_only_std_ratio"] = {
            n: _num(v) for n, v in result.magnitude_only_std_ratio.items()
        }
    return block


def build_report(
    result,
    assessment,
    *,
    session_id: str = "",
    declared_model: str | None = None,
    afc: dict | None = None,
    loop=None,
) -> dict[str, Any]:
    """The report of one identification: with ``loop`` (a
    :class:`~vibid.identify.loop.LoopResult`) every stage of the closed loop and the
    effects it added, ``result`` then being its final stage; without, the declared model
    alone (a loop of one stage).

    Parameters
    ----------
    result: the IdentificationResult of the declared model.
    assessment: what the assess stage judged of it (:func:`vibid.identify.assess.assess`):
        the ``linearity``, ``engineering`` (E, nu, G with their uncertainty budget),
        ``plausibility`` and ``reference`` blocks, and the ``not_done`` stages.
    session_id: the session's id.
    declared_model: ``setup.identification.model`` (default ``result.model``).
    afc: the signal stage's report block (``AfcTable.to_report_block()``); default built
        from the points in ``result``.
    """
    if loop is not None:
        result = loop.final
    effect_params = set()
    if loop is not None:
        effect_params = {q.name for t in _effect_terms(loop) for q in t.parameters}
    params = {
        n: {"value": _num(v), "std": _num(s)}
        for n, v, s in zip(result.parameter_names, result.values, result.std)
        if n not in effect_params
    }
    warnings = _fit_warnings(result, loop, assessment)
    if loop is None:
        effects = []
        loop_block = {
            "stages": [_stage_block(None, result)],
            "unexplained_residual": assessment.unexplained_residual,
        }
    else:
        effects, loop_block = effects_block(loop), _loop_block(loop)
    extra, said = assessed_blocks(assessment, loop)
    warnings.extend(said)
    return extra | {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "session_id": session_id,
        "declared_model": declared_model or result.model,
        "model": getattr(getattr(result, "plate_model", None), "model", None) or result.model,
        "afc": afc if afc is not None else afc_block(result),
        "parameters": params,
        "effects": effects,
        "loop": loop_block,
        "identification": identification_block(result, warnings, assessment.notes),
    }


def write_report(report: dict, path) -> None:
    """Write ``report`` as JSON (strict: no NaN). The text is made in full first and then
    replaces ``path`` in one step, so a failure never leaves half a report behind. The file
    gets the permissions of any file the user makes (``0o666`` less the umask), not the
    private ``0o600`` of a temporary file; a failure is a VibidError naming ``path``."""
    import os
    import tempfile

    from vibid.errors import VibidError

    text = json.dumps(report, indent=1, allow_nan=False) + "\n"
    folder = os.path.dirname(os.path.abspath(path))
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=".report-", suffix=".json", dir=folder)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None and os.path.exists(tmp):
            os.remove(tmp)
        if isinstance(exc, OSError):
            raise VibidError(
                f"{os.fspath(path)}: cannot write the report ({exc.strerror or exc})"
            ) from None
        raise


def _umask() -> int:
    """The process's file-creation mask (read by setting it and putting it back)."""
    import os

    mask = os.umask(0o022)
    os.umask(mask)
    return mask
