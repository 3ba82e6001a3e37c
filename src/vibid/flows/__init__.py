"""Prefect flows: how a lab runs vibid's stages together.

* :func:`replay_flow`: a recorded session → AFC → identification with the closed loop →
  the JSON report (the same as ``vibid identify``) and a readable report folder;
* :func:`batch_replay_flow`: many sessions, one replay task each on a task runner (threads,
  or a Dask cluster), ending in a summary table (CSV and markdown);
* :func:`campaign_flow`: acquisition on a stand (in the flow's main thread), then the same
  stages as a replay.

The stages are Prefect tasks (:mod:`vibid.flows.tasks`) that wrap the plain functions of
:mod:`vibid.pipeline` and :mod:`vibid.lab_report`; the numerical core never imports Prefect.
With no configuration the flows run on Prefect's embedded temporary server; with
``PREFECT_API_URL`` set, against that server. Importing this package loads Prefect only
when one of the names below is first used.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "replay_flow": "vibid.flows.replay",
    "replay_session": "vibid.flows.replay",
    "batch_replay": "vibid.flows.batch",
    "batch_replay_flow": "vibid.flows.batch",
    "BatchResult": "vibid.flows.batch",
    "campaign_flow": "vibid.flows.campaign",
    "make_task_runner": "vibid.flows.runners",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'vibid.flows' has no attribute {name!r}")
