"""Batch replay: many sessions, one replay task each, then one summary table.

:data:`batch_replay` is the Prefect flow (threads by default, the one to serve);
:func:`batch_replay_flow` runs it with the task runner of a setting
(:func:`vibid.flows.runners.make_task_runner`): threads, a temporary local Dask cluster,
or a lab's Dask cluster by its scheduler address.

The summary (``summary.csv``, ``summary.md`` in ``report_dir``, and a Prefect markdown and
table artifact) has one row per session: the parameters with std, the effects found, χ²/dof
before and after the loop. Every session's own report folder is ``report_dir/<file stem>``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from prefect import flow
from prefect.task_runners import ThreadPoolTaskRunner

from vibid.flows.replay import replay_task
from vibid.flows.tasks import run_logger
from vibid.pipeline import RESTARTS, SEED

SUMMARY_CSV = "summary.csv"
SUMMARY_MD = "summary.md"


@dataclass(frozen=True)
class BatchResult:
    """What a batch produced: per session (in the order given) its report or None, and the
    one-line error of a failed one (empty when it ran); the summary rows and files."""

    session_paths: tuple[str, ...]
    reports: tuple[dict | None, ...]
    errors: tuple[str, ...]
    rows: tuple[dict, ...]
    csv_path: str
    markdown_path: str


def report_names(session_paths) -> list[str]:
    """One folder name per session: its file stem, numbered where two stems are equal."""
    stems = [Path(p).stem for p in session_paths]
    out = []
    for i, s in enumerate(stems):
        out.append(s if stems.count(s) == 1 else f"{s}-{stems[: i + 1].count(s)}")
    return out


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@flow(name="batch-replay", task_runner=ThreadPoolTaskRunner())
def batch_replay(
    session_paths: list[Path],
    report_dir: Path,
    loop: bool = True,
    candidates: list[str] | str | None = None,
    restarts: int = RESTARTS,
    seed: int = SEED,
    magnitude_only: bool = False,
) -> BatchResult:
    """Replay every session (one task each, on the flow's task runner), then write the
    summary table. A session that fails is a row saying why; the others go on."""
    from prefect.artifacts import create_markdown_artifact, create_table_artifact

    from vibid.report import summary_csv, summary_row, summary_table_markdown

    logger = run_logger()
    paths = [os.fspath(p) for p in session_paths]
    names = report_names(paths)
    os.makedirs(report_dir, exist_ok=True)
    futures = [
        replay_task.with_options(task_run_name=f"replay-{name}").submit(
            path,
            report_dir=os.path.join(report_dir, name),
            loop=loop,
            candidates=candidates,
            restarts=restarts,
            seed=seed,
            magnitude_only=magnitude_only,
        )
        for path, name in zip(paths, names)
    ]
    reports, errors = [], []
    for name, fut in zip(names, futures):
        try:
            reports.append(fut.result())
            errors.append("")
        except Exception as exc:  # noqa: BLE001 - one failed session is one row, not the batch
            logger.error("%s: %s", name, _one_line(exc))
            reports.append(None)
            errors.append(_one_line(exc))
    rows = [summary_row(n, r, error=e) for n, r, e in zip(names, reports, errors)]
    csv_path = os.path.join(report_dir, SUMMARY_CSV)
    md_path = os.path.join(report_dir, SUMMARY_MD)
    table = summary_table_markdown(rows)
    with open(csv_path, "w", encoding="utf-8", newline="") as fh:
        fh.write(summary_csv(rows))
    with open(md_path, "w", encoding="utf-8") as fh:
        fh.write(f"# Batch replay: {len(rows)} sessions\n\n{table}")
    create_markdown_artifact(
        key="batch-replay-summary",
        markdown=table,
        description=f"summary of {len(rows)} replayed sessions",
    )
    create_table_artifact(
        key="batch-replay-table",
        table=rows,
        description="one row per session: parameters, std, effects, chi2",
    )
    logger.info("summary: %s, %s\n%s", csv_path, md_path, table)
    return BatchResult(tuple(paths), tuple(reports), tuple(errors), tuple(rows), csv_path, md_path)


def batch_replay_flow(
    session_paths,
    *,
    report_dir,
    task_runner=None,
    loop: bool = True,
    candidates=None,
    restarts: int = RESTARTS,
    seed: int = SEED,
    magnitude_only: bool = False,
) -> BatchResult:
    """Run :data:`batch_replay` on the task runner ``task_runner``: None or ``"threads"``
    (this machine's threads), ``"dask"`` (a temporary local Dask cluster), a Dask scheduler
    address (``"tcp://host:8786"``), or a ready Prefect task runner (e.g.
    ``prefect_dask.DaskTaskRunner(cluster=...)``)."""
    from vibid.flows.runners import make_task_runner

    runner = make_task_runner(task_runner)
    return batch_replay.with_options(task_runner=runner)(
        [Path(p) for p in session_paths],
        Path(report_dir),
        loop=loop,
        candidates=candidates,
        restarts=restarts,
        seed=seed,
        magnitude_only=magnitude_only,
    )
