"""Prefect flows: how a lab runs vibid's stages together.

* :func:`replay_flow`: a recorded session → AFC → identification with the closed loop →
  the JSON report (the same as ``vibid identify``) and a readable report folder;
* :func:`batch_replay_flow`: many sessions, one replay task each on a task runner (threads,
  or a Dask cluster), ending in a summary table (CSV and markdown);
* :func:`campaign_flow`: acquisition on a stand (in the flow's main thread), then the same
  stages as a replay.

The stages are Prefect tasks (:mod:`vibid.flows.tasks`) that wrap the plain functions of
:mod:`vibid.pipeline` and :mod:`vibid.report`; the numerical core never imports Prefect.
With no configuration the flows run on Prefect's embedded temporary server; with
``PREFECT_API_URL`` set, against that server. Importing this package loads Prefect only
when one of the names below is first used, and sets the embedded server's defaults
(:func:`embedded_server_defaults`) before then.
"""

from __future__ import annotations

import importlib
import os

#: Seconds Prefect waits for its embedded server (its default, 20 s, is about what a fresh
#: install's first start-up takes on a busy 2-core PC, the modules compiling on import).
EMBEDDED_SERVER_STARTUP_S = 120


def embedded_server_defaults() -> None:
    """Settings for Prefect's embedded server unless the lab set them: no usage telemetry
    (an offline lab PC logs an error for it) and a start-up wait a busy PC meets."""
    os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    os.environ.setdefault(
        "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", str(EMBEDDED_SERVER_STARTUP_S)
    )


# before any flow module imports Prefect, which reads its settings once, on import
embedded_server_defaults()

_EXPORTS = {
    "replay_flow": "vibid.flows.replay",
    "replay_session": "vibid.flows.replay",
    "batch_replay": "vibid.flows.batch",
    "batch_replay_flow": "vibid.flows.batch",
    "BatchResult": "vibid.flows.batch",
    "campaign_flow": "vibid.flows.campaign",
    "make_task_runner": "vibid.flows.runners",
}

__all__ = sorted(_EXPORTS) + ["embedded_server_defaults"]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'vibid.flows' has no attribute {name!r}")
