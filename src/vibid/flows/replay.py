"""Replay: a recorded session (or an AFC measured elsewhere) → AFC → identification with
the closed loop → report.

:func:`replay_flow` is ``vibid identify`` run as a Prefect flow (the same JSON report), plus
the readable report folder and the Prefect artifacts. :func:`replay_session` is the same
stages as one plain function: the body of the batch's replay task.
"""

from __future__ import annotations

import os
from pathlib import Path

from prefect import flow, task
from prefect.cache_policies import NO_CACHE

from vibid.errors import VibidError
from vibid.flows.tasks import (
    afc_file_task,
    afc_task,
    identify_task,
    publish_artifacts,
    report_task,
    run_logger,
    uff_task,
)
from vibid.pipeline import (
    RESTARTS,
    SEED,
    require_converged,
    session_afc,
    write_outputs,
)


@flow(name="replay")
def replay_flow(
    session_path: Path | None = None,
    *,
    afc_path: Path | None = None,
    setup_path: Path | None = None,
    uff_path: Path | None = None,
    json_path: Path | None = None,
    report_dir: Path | None = None,
    loop: bool = True,
    candidates: list[str] | str | None = None,
    method: str = "global",
    local: str = "newton",
    restarts: int = RESTARTS,
    seed: int = SEED,
    magnitude_only: bool = False,
    reference_E_pa: float | None = None,
    reference_E_std_pa: float = 0.0,
) -> dict:
    """Replay one session: the report of ``vibid identify SESSION`` with the same options.

    Parameters
    ----------
    session_path: the session file (HDF5, shared/spec/session-format.md); or
    afc_path, setup_path: an AFC measured elsewhere (CSV or UFF58, by content) and its
        declared setup, as ``vibid identify --afc AFC --setup SETUP``.
    uff_path: also write the AFC the identification uses here, as UFF58 (``vibid afc
        --uff``).
    json_path: write the JSON report (shared/spec/report-format.md) here.
    report_dir: write ``report.md``, ``report.json`` and the PNG figures into this folder.
    loop: close the loop (search for the effects the declared model lacks).
    candidates: the loop's candidate effects (names, or ``"A,B"``); default all.
    method, local, restarts, seed: the identification's options (as ``vibid identify``).
    magnitude_only: identify from |H| alone (``vibid identify --magnitude-only``).
    reference_E_pa, reference_E_std_pa: the specimen is a reference of known modulus (Pa)
        and its std: the report gives the clamp's effective free length (``vibid identify
        --reference-E``, :mod:`vibid.identify.assess.reference`).

    Returns the report (a dict). A run that did not converge writes its report, then fails.
    """
    if (session_path is None) == (afc_path is None) or (afc_path is None) != (setup_path is None):
        raise VibidError("replay: give a session file, or an AFC file with its setup")
    from vibid.identify.assess.reference import reference_from

    # checked before the identification's minutes
    reference = reference_from(reference_E_pa, reference_E_std_pa)
    if session_path is not None:
        data = afc_task(os.fspath(session_path))
    else:
        data = afc_file_task(os.fspath(afc_path), os.fspath(setup_path))
    if uff_path is not None:
        uff_task(data, os.fspath(uff_path))
    identified = identify_task(
        data,
        loop=loop,
        candidates=candidates,
        method=method,
        local=local,
        restarts=restarts,
        seed=seed,
        magnitude_only=magnitude_only,
    )
    report, _ = report_task(
        data,
        identified,
        json_path=json_path,
        report_dir=report_dir,
        session_path=session_path,
        reference=reference,
    )
    publish_artifacts(report, specimen=data.setup.specimen.name, report_dir=report_dir)
    require_converged(identified)
    return report


def replay_session(session_path, *, json_path=None, report_dir=None, **options) -> dict:
    """The replay's stages as one plain function (no Prefect run needed): returns the
    report; a run that did not converge says so in it (``identification.converged``).
    ``options``: the identification's, as :func:`~vibid.flows.tasks.identify_task` takes
    them (``loop``, ``candidates``, ``method``, ``local``, ``restarts``, ``seed``,
    ``magnitude_only``)."""
    run_logger().info("replaying %s", session_path)
    data = session_afc(session_path)
    identified = identify_task.fn(data, **options)  # the identify task's own stage, here
    report, _ = write_outputs(
        data, identified, json_path=json_path, report_dir=report_dir, session_path=session_path
    )
    return report


#: The batch's task: one whole replay (its stages run inside the task, on the task runner).
replay_task = task(name="replay", cache_policy=NO_CACHE)(replay_session)
