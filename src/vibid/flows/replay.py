"""Replay: a recorded session → AFC → identification with the closed loop → report.

:func:`replay_flow` is ``vibid identify`` run as a Prefect flow (the same JSON report), plus
the readable report folder and the Prefect artifacts. :func:`replay_session` is the same
stages as one plain function: the body of the batch's replay task.
"""

from __future__ import annotations

import os
from pathlib import Path

from prefect import flow, task
from prefect.cache_policies import NO_CACHE

from vibid.flows.tasks import (afc_task, forwarded_logs, identify_task, progress_logger,
                               publish_artifacts, report_task, run_logger)
from vibid.pipeline import (RESTARTS, SEED, identify_afc, require_converged, session_afc,
                            write_outputs)


@flow(name="replay")
def replay_flow(session_path: Path, *, json_path: Path | None = None,
                report_dir: Path | None = None, loop: bool = True,
                candidates: list[str] | str | None = None, method: str = "global",
                local: str = "newton", restarts: int = RESTARTS, seed: int = SEED) -> dict:
    """Replay one session: the report of ``vibid identify SESSION`` with the same options.

    Parameters
    ----------
    session_path: the session file (HDF5, shared/spec/session-format.md).
    json_path: write the JSON report (shared/spec/report-format.md) here.
    report_dir: write ``report.md``, ``report.json`` and the PNG figures into this folder.
    loop: close the loop (search for the effects the declared model lacks).
    candidates: the loop's candidate effects (names, or ``"A,B"``); default all.
    method, local, restarts, seed: the identification's options (as ``vibid identify``).

    Returns the report (a dict). A run that did not converge writes its report, then fails.
    """
    data = afc_task(os.fspath(session_path))
    identified = identify_task(data, loop=loop, candidates=candidates, method=method,
                               local=local, restarts=restarts, seed=seed)
    report, _ = report_task(data, identified, json_path=json_path, report_dir=report_dir,
                            session_path=session_path)
    publish_artifacts(report, specimen=data.setup.specimen.name, report_dir=report_dir)
    require_converged(identified)
    return report


def replay_session(session_path, *, json_path=None, report_dir=None, loop: bool = True,
                   candidates=None, method: str = "global", local: str = "newton",
                   restarts: int = RESTARTS, seed: int = SEED) -> dict:
    """The replay's stages as one plain function (no Prefect run needed): returns the
    report; a run that did not converge says so in it (``identification.converged``)."""
    logger = run_logger()
    data = session_afc(session_path)
    with forwarded_logs(logger):
        identified = identify_afc(data, loop=loop, candidates=candidates, method=method,
                                  local=local, restarts=restarts, seed=seed,
                                  progress=progress_logger(logger))
    logger.info("%s:\n%s", session_path, identified.summary)
    report, _ = write_outputs(data, identified, json_path=json_path, report_dir=report_dir,
                              session_path=session_path)
    return report


#: The batch's task: one whole replay (its stages run inside the task, on the task runner).
replay_task = task(name="replay", cache_policy=NO_CACHE)(replay_session)
