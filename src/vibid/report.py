"""The identification report (shared/spec/report-format.md, version 1), as a JSON document.

:func:`build_report` turns an :class:`~vibid.identify.fit.result.IdentificationResult` (one
loop stage: the declared model alone) into the report's dict; :func:`write_report` writes
it. Extra keys the format allows: ``identification`` (status sentence, warnings,
covariance, correlation, timings) and the signal stage's ``afc.diagnostics`` when given.
Non-finite numbers are written as null (JSON has no NaN).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

FORMAT = "vibid.report"
FORMAT_VERSION = 1


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _nums(a) -> list:
    return [_num(v) for v in np.asarray(a, dtype=float).ravel()]


def unexplained(result) -> bool:
    """Whether the fit leaves a residual above the noise
    (:func:`vibid.identify.fit.noise.fits_noise`). Without a known noise level nothing can
    be said, and the answer is False (with a warning in the result)."""
    from vibid.identify.fit.noise import fits_noise

    return fits_noise(result.chi2, result.dof, result.noise_known) is False


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


def build_report(result, *, session_id: str = "", declared_model: str | None = None,
                 afc: dict | None = None) -> dict[str, Any]:
    """The report of one identification (a loop with its first stage only).

    Parameters
    ----------
    result: the IdentificationResult of the declared model.
    session_id: the session's id.
    declared_model: ``setup.identification.model`` (default ``result.model``).
    afc: the signal stage's report block (``AfcTable.to_report_block()``); default built
        from the points in ``result``.
    """
    params = {n: {"value": _num(v), "std": _num(s)}
              for n, v, s in zip(result.parameter_names, result.values, result.std)}
    warnings = list(result.warnings)
    if not result.noise_known:
        warnings.append("the AFC's uncertainty is unknown: the fit cannot be tested against "
                        "the noise (unexplained_residual is false by default)")
    stage = {
        "added": None,
        "chi2_reduced": _num(result.chi2_reduced),
        "rel_rms_residual": _num(result.rel_rms_residual),
        "parameters": {n: _num(v) for n, v in zip(result.parameter_names, result.values)},
    }
    g = result.global_result
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "session_id": session_id,
        "declared_model": declared_model or result.model,
        "model": result.model,
        "afc": afc if afc is not None else afc_block(result),
        "parameters": params,
        "effects": [],
        "loop": {"stages": [stage], "unexplained_residual": unexplained(result)},
        "identification": {
            "status": result.status.value,
            "converged": result.converged,
            "message": result.message,
            "warnings": warnings,
            "noise_known": result.noise_known,
            "chi2": _num(result.chi2),
            "chi2_reduced_data_weights": _num(result.chi2_reduced_data_weights),
            "model_error_std": None if result.model_error_bias is None else {
                n: _num(abs(b)) for n, b in zip(result.parameter_names, result.model_error_bias)},
            "dof": int(result.dof),
            "parameter_names": list(result.parameter_names),
            "covariance": [_nums(row) for row in result.covariance],
            "correlation": [_nums(row) for row in result.correlation],
            "global_search": None if g is None else {
                "restart_best": [dict(zip(result.parameter_names, _nums(t))) for t in g.theta],
                "restart_loss": _nums(g.loss),
                "evaluations": int(g.n_evaluations),
            },
            "local_runs": [{"method": r.method, "status": r.status.value, "message": r.message,
                            "chi2": _num(r.loss), "iterations": r.n_iterations}
                           for r in result.local_results[:10]],
            "seconds": _num(result.seconds),
        },
    }


def write_report(report: dict, path) -> None:
    """Write ``report`` as JSON (strict: no NaN). The text is made in full first and then
    replaces ``path`` in one step, so a failure never leaves half a report behind."""
    import os
    import tempfile

    text = json.dumps(report, indent=1, allow_nan=False) + "\n"
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".report-", suffix=".json", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
