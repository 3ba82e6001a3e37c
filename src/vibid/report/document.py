"""The identification report (shared/spec/report-format.md, version 1), as a JSON document.

:func:`build_report` turns an :class:`~vibid.identify.fit.result.IdentificationResult` (one
loop stage: the declared model alone) into the report's dict; :func:`write_report` writes
it. Extra keys the format allows: ``plausibility`` (constants no material allows, and the
comparison with the specimen's material class), ``linearity`` (whether each resolved
measured resonance is a linear one), ``identification`` (status sentence, warnings,
covariance, correlation, timings, ``data``: ``"complex"`` or ``"magnitude"`` and, for a
magnitude-only fit, ``magnitude_only_std_ratio``; ``discretisation``: the model's meshes,
measured order and bias, :func:`discretisation_block`), the signal stage's
``afc.diagnostics`` when given,
and ``not_done``: the stages after the fit that could not be done, each
``{"stage": .., "reason": ..}`` in one line, the rest of the report written
(:mod:`vibid.report.not_done`; empty when every stage was done).
Non-finite numbers are written as null (JSON has no NaN).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from typing import Any

import numpy as np

from vibid.report.not_done import NOT_DONE, attempt

FORMAT = "vibid.report"
FORMAT_VERSION = 1


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _nums(a) -> list:
    return [_num(v) for v in np.asarray(a, dtype=float).ravel()]


def unexplained(result) -> bool:
    """Whether the fit leaves a residual above the noise (the one judge,
    :func:`vibid.identify.fit.noise.explains`, as the loop's). Without a known noise level
    nothing can be said, and the answer is False (with a warning in the result)."""
    from vibid.identify.fit.noise import explains

    return explains(result) is False


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


def free_length_share(result) -> str | None:
    """How much of the bending stiffness's (and so E's) uncertainty a fitted free length
    carries: a longer span is a softer plate, and the two are nearly collinear. None when
    the model has no ``dL_m``."""
    names = list(result.parameter_names)
    stiff = "D" if "D" in names else "D11" if "D11" in names else None
    if "dL_m" not in names or stiff is None:
        return None
    C = np.asarray(result.covariance, float)
    i, j = names.index(stiff), names.index("dL_m")
    if not (np.isfinite(C[i, i]) and np.isfinite(C[j, j]) and C[i, i] > 0 and C[j, j] > 0):
        return None
    share = C[i, j] ** 2 / (C[i, i] * C[j, j])
    known = math.sqrt(max(C[i, i] * (1.0 - share), 0.0))
    return (
        f"free_length: dL carries {100 * share:.0f} % of the variance of {stiff} (and so "
        f"of E): with dL known, {stiff}'s std would be {known:.3g} instead of "
        f"{math.sqrt(C[i, i]):.3g} N m"
    )


def plausibility_block(model: str, result, constants: dict, setup, loop) -> tuple[dict, list]:
    """(the report's ``plausibility`` block, its warnings): constants no material allows,
    with what the loop tried, and the comparison with the handbook range of the specimen's
    material class (:mod:`vibid.identify.assess.plausibility`)."""
    from vibid.identify.assess.plausibility import plausibility

    sp = setup.specimen
    found = plausibility(
        model,
        result.parameters,
        result.parameter_std,
        constants,
        specimen_name=sp.name,
        material=sp.material,
        specimen=sp,
        sensor=setup.sensors.response,
    )
    if loop is None:
        tried = " (the closed loop did not run)"
    else:
        names = sorted({s.name for rnd in loop.rounds for s in rnd})
        tried = (
            f" (the closed loop tried {', '.join(names) or 'no candidate'}"
            f" and added {', '.join(loop.effects) or 'none'})"
        )
    block = {
        "material_class": found.material_class,
        "violations": [v + tried for v in found.violations],
        "outside_handbook": list(found.outside_handbook),
        "inside_handbook": list(found.inside_handbook),
    }
    return block, block["violations"] + block["outside_handbook"]


def linearity_block(result, tests=None) -> list[dict]:
    """The ``linearity`` block: whether each measured resonance the grid resolves is the
    response of a linear structure, and which tops were left out of the fit
    (:mod:`vibid.identify.assess.linearity`; the measured AFC alone, complex data only); empty
    where no resonance is resolved. ``tests``: the tests made before the fit
    (:func:`vibid.pipeline.identify_afc`), whose points the fit's own no longer hold."""
    from vibid.identify.assess.linearity import linear_part

    if tests is None:  # tested here, after a fit that left nothing out
        if result.magnitude:
            return []
        std = None if result.H_std is None else np.asarray(result.H_std)
        tests = [
            replace(t, left_out_hz=None)
            for t in linear_part(result.frequency_hz, result.H, std, result.used)[1]
        ]
    return [t.as_report() for t in tests]


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


def _loop_block(loop) -> tuple[list, dict]:
    """(effects, loop block) of a :class:`vibid.identify.loop.LoopResult`. An effect that
    occurs more than once has one entry per instance, ``"instance": k``, its parameters
    unsuffixed (report format, "Effect names")."""
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
    rounds = [
        [
            {
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
                "note": sc.note,
            }
            for sc in rnd
        ]
        for rnd in loop.rounds
    ]
    block = {
        "stages": stages,
        "unexplained_residual": bool(loop.unexplained_residual),
        "criterion": loop.criterion,
        "rounds": rounds,
        "seconds": _num(loop.seconds),
    }
    if any(st.diagnosis is not None for st in loop.stages):
        block["diagnosis"] = [
            [] if st.diagnosis is None else st.diagnosis.as_report() for st in loop.stages
        ]
    return effects, block


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


def fit_constants(setup, result) -> dict:
    """The engineering constants with the fit's covariance and the declared thickness's
    uncertainty through the conversion alone (:func:`vibid.identify.assess.engineering.
    engineering_constants`): the report's block where the budget could not be made."""
    from vibid.identify.assess.engineering import engineering_constants

    model = getattr(result.plate_model, "model", None) or result.model
    sp = setup.specimen
    return engineering_constants(
        model,
        result.parameter_names,
        result.values,
        result.covariance,
        sp.thickness_m,
        getattr(sp, "thickness_std_m", None) or 0.0,
    )


def build_report(
    result,
    *,
    session_id: str = "",
    declared_model: str | None = None,
    afc: dict | None = None,
    loop=None,
    setup=None,
    linearity=None,
    reference=None,
    not_done=(),
) -> dict[str, Any]:
    """The report of one identification: with ``loop`` (a
    :class:`~vibid.identify.loop.LoopResult`) every stage of the closed loop and the
    effects it added, ``result`` then being its final stage; without, the declared model
    alone (a loop of one stage).

    Parameters
    ----------
    result: the IdentificationResult of the declared model.
    session_id: the session's id.
    declared_model: ``setup.identification.model`` (default ``result.model``).
    afc: the signal stage's report block (``AfcTable.to_report_block()``); default built
        from the points in ``result``.
    setup: the declared setup; with it the report gains the ``engineering`` block (E, nu,
        G from the stiffnesses and the declared thickness) with its uncertainty budget
        (:mod:`vibid.identify.assess.budget`).
    linearity: the linearity tests made before the fit (:func:`linearity_block`).
    reference: with ``setup``, the ``reference`` block: what the specimen's known modulus
        says of the clamp's free length (:func:`vibid.pipeline.reference_block`).
    not_done: the stages an earlier step could not do (:mod:`vibid.report.not_done`); the
        report's ``not_done`` adds those of its own that fail (the linearity tests, the
        budget, the constants, the plausibility), each leaving the rest of the report.
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
    warnings = list(result.warnings) + (list(loop.warnings) if loop is not None else [])
    shared = free_length_share(result)
    if shared:
        warnings.append(shared)
    if not result.noise_known:
        warnings.append(
            "the AFC's uncertainty is unknown: the fit cannot be tested against "
            "the noise (unexplained_residual is false by default)"
        )
    if loop is None:
        effects = []
        loop_block = {
            "stages": [_stage_block(None, result)],
            "unexplained_residual": unexplained(result),
        }
    else:
        effects, loop_block = _loop_block(loop)
    model = getattr(getattr(result, "plate_model", None), "model", None) or result.model
    g = result.global_result
    extra, notes, not_done = {}, [], list(not_done)
    if tested := attempt("linearity", not_done, linearity_block, result, linearity, default=[]):
        extra["linearity"] = tested
        warnings.extend(t["note"] for t in tested if not t["linear"])
        warnings.extend(t.left_out_note for t in linearity or () if t.left_out_hz is not None)
    if setup is not None:
        from vibid.identify.assess.budget import engineering_budget

        block = attempt("uncertainty budget", not_done, engineering_budget, setup, result, loop)
        if block is None:  # the constants with the fit's std alone
            block = attempt(
                "engineering constants", not_done, fit_constants, setup, result, default={}
            )
        if block:
            budget, notes = block.pop("budget", None), block.pop("notes", [])
            extra["engineering"] = {
                k: {"value": _num(v["value"]), "std": None if v["std"] is None else _num(v["std"])}
                for k, v in block.items()
            }
            if budget is not None:
                extra["engineering"]["budget"] = {
                    k: {part: _num(u) for part, u in parts.items()} for k, parts in budget.items()
                }
        found = attempt(
            "plausibility", not_done, plausibility_block, model, result, block, setup, loop
        )
        if found is not None:
            extra["plausibility"], said = found
            warnings.extend(said)
        if reference is not None:
            extra["reference"] = reference
    extra[NOT_DONE] = not_done
    return extra | {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "session_id": session_id,
        "declared_model": declared_model or result.model,
        "model": model,
        "afc": afc if afc is not None else afc_block(result),
        "parameters": params,
        "effects": effects,
        "loop": loop_block,
        "identification": {
            "status": result.status.value,
            "converged": result.converged,
            "message": result.message,
            "warnings": warnings,
            "noise_known": result.noise_known,
            # what the fit saw: the complex AFC, or |H| alone (--magnitude-only)
            "data": "magnitude" if result.magnitude else "complex",
            "chi2": _num(result.chi2),
            "chi2_reduced_data_weights": _num(result.chi2_reduced_data_weights),
            "model_error_std": None
            if result.model_error_bias is None
            else {n: _num(abs(b)) for n, b in zip(result.parameter_names, result.model_error_bias)},
            "discretisation": discretisation_block(result),
            "dof": int(result.dof),
            "parameter_names": list(result.parameter_names),
            "covariance": [_nums(row) for row in result.covariance],
            "correlation": [_nums(row) for row in result.correlation],
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
            "seconds": _num(result.seconds),
            # the engineering constants' budget in words: each one's largest part
            "uncertainty_notes": list(notes),
        }
        | (
            {}
            if result.magnitude_only_std_ratio is None
            else {
                # each std over the complex fit's of the same points (both Fisher informations)
                "magnitude_only_std_ratio": {
                    n: _num(v) for n, v in result.magnitude_only_std_ratio.items()
                }
            }
        ),
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
