"""The task runner of a batch, as a setting.

``None`` or ``"threads"``: a :class:`prefect.task_runners.ThreadPoolTaskRunner` on this
machine (the default). ``"dask"``: a :class:`prefect_dask.DaskTaskRunner` that starts a
temporary local Dask cluster. ``"tcp://host:8786"`` (any scheduler address): a
``DaskTaskRunner`` connected to that running Dask cluster, so a lab's cluster runs the
replays. A ready :class:`prefect.task_runners.TaskRunner` is used as it is.
"""

from __future__ import annotations

from vibid.errors import VibidError


def make_task_runner(setting=None):
    """The task runner for ``setting`` (see the module docstring)."""
    from prefect.task_runners import TaskRunner, ThreadPoolTaskRunner

    if isinstance(setting, TaskRunner):
        return setting
    if setting is None or setting == "threads":
        return ThreadPoolTaskRunner()
    if not isinstance(setting, str):
        raise VibidError(f"task runner: expected 'threads', 'dask' or a Dask scheduler address, "
                         f"got {setting!r}")
    from prefect_dask import DaskTaskRunner

    if setting == "dask":
        return DaskTaskRunner()
    if "://" in setting:
        return DaskTaskRunner(address=setting)
    raise VibidError(f"task runner: expected 'threads', 'dask' or a Dask scheduler address "
                     f"such as tcp://host:8786, got {setting!r}")
