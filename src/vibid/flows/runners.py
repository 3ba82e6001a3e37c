"""The task runner of a batch, as a setting.

``None`` or ``"threads"``: a :class:`prefect.task_runners.ThreadPoolTaskRunner` on this
machine (the default). ``"dask"``: a :class:`prefect_dask.DaskTaskRunner` that starts a
temporary local Dask cluster. ``"tcp://host:8786"`` (any scheduler address): a
``DaskTaskRunner`` connected to that running Dask cluster, so a lab's cluster runs the
replays. A running ``distributed`` cluster object (``distributed.LocalCluster(...)``):
a ``DaskTaskRunner`` connected to its scheduler address. A ready
:class:`prefect.task_runners.TaskRunner` is used as it is, except that a ``DaskTaskRunner``
built on a cluster object is reconnected by that cluster's address: Prefect copies a flow's
task runner with its settings (``duplicate``), and prefect-dask's copy forgets the cluster
object (it would start a new local cluster instead).
"""

from __future__ import annotations

from vibid.errors import VibidError


def make_task_runner(setting=None):
    """The task runner for ``setting`` (see the module docstring)."""
    from prefect.task_runners import TaskRunner, ThreadPoolTaskRunner

    cluster = getattr(setting, "_cluster", None) if isinstance(setting, TaskRunner) else setting
    if hasattr(cluster, "scheduler_address"):
        from prefect_dask import DaskTaskRunner

        return DaskTaskRunner(address=cluster.scheduler_address)
    if isinstance(setting, TaskRunner):
        return setting
    if setting is None or setting == "threads":
        return ThreadPoolTaskRunner()
    if not isinstance(setting, str):
        raise VibidError(
            f"task runner: expected 'threads', 'dask' or a Dask scheduler address, got {setting!r}"
        )
    from prefect_dask import DaskTaskRunner

    if setting == "dask":
        return DaskTaskRunner()
    if "://" in setting:
        return DaskTaskRunner(address=setting)
    raise VibidError(
        f"task runner: expected 'threads', 'dask' or a Dask scheduler address "
        f"such as tcp://host:8786, got {setting!r}"
    )
