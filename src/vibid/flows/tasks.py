"""The stages as Prefect tasks: thin wrappers over :mod:`vibid.pipeline`.

Each task calls one plain function and logs what it found; the functions are where the work
and its tests are (``task.fn(...)`` runs a task's body without Prefect). No task caches its
result: a replay always recomputes, so a changed session or library is never masked.
Outside a flow run the tasks log to ``logging.getLogger("vibid.flows")``.
"""

from __future__ import annotations

import logging
import os
import threading
from contextlib import contextmanager

from prefect import task
from prefect.cache_policies import NO_CACHE

from vibid.pipeline import (
    RESTARTS,
    SEED,
    Identified,
    SessionAfc,
    afc_file,
    identify_afc,
    session_afc,
    write_afc_uff,
    write_outputs,
)


def run_logger():
    """Prefect's run logger inside a flow or task run, else the module's logger."""
    from prefect import get_run_logger
    from prefect.exceptions import MissingContextError

    try:
        return get_run_logger()
    except MissingContextError:
        return logging.getLogger("vibid.flows")


def progress_logger(logger, *, every: float = 0.25):
    """A search ``progress(label, done, total, best)`` callback that logs one line per
    search at every ``every`` of its generations (no carriage-return bars in a log)."""
    reached: dict[str, int] = {}

    def progress(label: str, done: int, total: int, best: float) -> None:
        mark = int(done / total / every) if total else 0
        if mark > reached.get(label, -1):
            reached[label] = mark
            logger.info("%s: generation %d of %d, best chi2 %.4g", label, done, total, best)

    return progress


class _Forward(logging.Handler):
    """Passes one thread's records on to a (Prefect run) logger: the stages' INFO lines,
    the model's own (``vibid.identify.model``: assembly, bases) only from WARNING up.
    Other threads' records from WARNING up go to the root logger's handlers, as before."""

    def __init__(self, target, thread_id: int):
        super().__init__(logging.INFO)
        self.target, self.thread_id = target, thread_id

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread != self.thread_id:
            if record.levelno >= logging.WARNING:
                logging.getLogger().handle(record)
            return
        if record.levelno >= logging.WARNING or not record.name.startswith("vibid.identify.model"):
            self.target.log(record.levelno, "%s", record.getMessage())


@contextmanager
def forwarded_logs(logger, name: str = "vibid.identify"):
    """While the block runs in this thread, the INFO records of the ``name`` loggers (the
    identification's stages: peak matching, valley walk, each loop candidate) go to
    ``logger`` instead of the root logger, so the console and Prefect show, once, what a
    long search is doing."""
    source = logging.getLogger(name)
    handler = _Forward(logger, threading.get_ident())
    level, propagate = source.level, source.propagate
    source.addHandler(handler)
    source.propagate = False
    if source.getEffectiveLevel() > logging.INFO:
        source.setLevel(logging.INFO)
    try:
        yield
    finally:
        source.removeHandler(handler)
        source.setLevel(level)
        source.propagate = propagate


@task(name="afc", cache_policy=NO_CACHE)
def afc_task(session_path: str) -> SessionAfc:
    """Signal stage: read the session and fit every step's AFC."""
    data = session_afc(session_path)
    used = int(data.afc.used.sum())
    run_logger().info("%s: %d of %d steps used", session_path, used, len(data.afc.used))
    return data


@task(name="afc-file", cache_policy=NO_CACHE)
def afc_file_task(afc_path: str, setup_path: str) -> SessionAfc:
    """An AFC measured elsewhere (CSV or UFF58, by content) with its declared setup."""
    data = afc_file(afc_path, setup_path)
    run_logger().info("%s: %d points", afc_path, len(data.afc.frequency_hz))
    return data


@task(name="afc-uff", cache_policy=NO_CACHE)
def uff_task(data: SessionAfc, uff_path: str) -> str:
    """Write the AFC the identification uses as UFF58 (its std as a second record)."""
    n = write_afc_uff(data, uff_path)
    run_logger().info("wrote %s (%d points, UFF58)", uff_path, n)
    return uff_path


@task(name="identify", cache_policy=NO_CACHE)
def identify_task(
    data: SessionAfc,
    *,
    loop: bool = True,
    candidates=None,
    method: str = "global",
    local: str = "newton",
    restarts: int = RESTARTS,
    seed: int = SEED,
    magnitude_only: bool = False,
) -> Identified:
    """Identification stage: the declared model, then the closed loop (with ``loop``)."""
    logger = run_logger()
    with forwarded_logs(logger):
        identified = identify_afc(
            data,
            loop=loop,
            candidates=candidates,
            method=method,
            local=local,
            restarts=restarts,
            seed=seed,
            progress=progress_logger(logger),
            magnitude_only=magnitude_only,
        )
    logger.info("%s", identified.summary)
    return identified


@task(name="report", cache_policy=NO_CACHE)
def report_task(
    data: SessionAfc,
    identified: Identified,
    *,
    json_path=None,
    report_dir=None,
    session_path=None,
    reference=None,
) -> tuple[dict, dict]:
    """Report stage: the JSON report, and the readable report folder; (report, paths).
    ``reference``: a reference specimen's known modulus, which calibrates the clamp."""
    report, paths = write_outputs(
        data,
        identified,
        json_path=json_path,
        report_dir=report_dir,
        session_path=session_path,
        reference=reference,
    )
    for name, path in paths.items():
        run_logger().info("wrote %s", path)
    return report, paths


#: A figure file larger than this is linked by its path, not embedded: the artifact's
#: markdown is stored in Prefect's database and sent whole to the browser (a PNG grows by a
#: third as base64).
MAX_EMBEDDED_PNG_BYTES = 1_500_000


def figures_markdown(report_dir) -> str:
    """The lab report's figures in ``report_dir`` (those of
    :data:`vibid.report.figures.FIGURES`, in its order, missing ones skipped) as markdown
    images with their PNG embedded as data URIs, so the Prefect UI shows them without
    reaching the folder. A file over :data:`MAX_EMBEDDED_PNG_BYTES` is linked by its path
    instead. Empty if none."""
    from vibid.report import figures
    from vibid.report.plots import png_data_uri

    lines = []
    for fig in figures.FIGURES:
        path, caption = os.path.join(os.fspath(report_dir), fig.file), fig.caption
        if not os.path.isfile(path):
            continue
        if os.path.getsize(path) > MAX_EMBEDDED_PNG_BYTES:
            # too large for the artifact's markdown: name the file instead
            lines += [
                f"**{caption}**: `{path}` (not embedded: {os.path.getsize(path) / 1e6:.1f} MB)",
                "",
            ]
            continue
        with open(path, "rb") as f:
            lines += figures.figure_markdown(caption, png_data_uri(f.read()))
    if not lines:
        return ""
    return "\n".join(["", "## Figures", ""] + lines)


def publish_artifacts(report: dict, *, specimen: str, report_dir=None) -> None:
    """The report's summary as Prefect artifacts: a markdown summary (with the report
    folder's figures embedded, :func:`figures_markdown`) and a parameter table, keyed by
    specimen (``<specimen>-report``, ``<specimen>-parameters``) so one specimen's runs form
    a history in the Prefect UI. Call inside a flow run, once the report is written: artifacts
    that cannot be made are one warning line of the run's log, and the flow goes on (the
    report's files hold everything they would show)."""
    from vibid.not_done import reason

    try:
        _publish(report, specimen, report_dir)
    except Exception as exc:  # noqa: BLE001 - the report is written; the UI's copy is not the job
        run_logger().warning(
            "the report's Prefect artifacts could not be published: %s", reason(exc)
        )


def _publish(report: dict, specimen: str, report_dir) -> None:
    from prefect.artifacts import create_markdown_artifact, create_table_artifact

    from vibid.report import artifact_key, parameter_table, summary_markdown

    text = summary_markdown(report, title=f"{specimen or 'specimen'}: identification report")
    if report_dir is not None:
        text += figures_markdown(report_dir)
        text += f"\nFigures and report.md: `{report_dir}`\n"
    create_markdown_artifact(
        key=artifact_key(specimen, "report"),
        markdown=text,
        description=f"identification report of session {report['session_id']}",
    )
    create_table_artifact(
        key=artifact_key(specimen, "parameters"),
        table=parameter_table(report),
        description=f"identified values (SI units) of session {report['session_id']}",
    )
