"""Campaign: acquire a session on a stand, then AFC → identification with the loop → report.

Acquisition runs in the flow's own (main) thread, never on the task runner: the hardware
stays on the stand's machine, and Ctrl-C or a cancelled flow's SIGTERM reaches the campaign,
which switches the generator's output off and closes the session ``interrupted``
(:func:`vibid.acquisition.campaign.run_campaign`). A transient stand fault (the campaign
ends ``aborted`` with a ``stand fault: ...`` reason, e.g. an instrument that did not answer)
is retried by reopening the stand and *resuming* the session: a written step is never
recorded again. The abort limit (a response above ``drive.abort_response_m_s2``) is a safety
stop and never retried. The stages after acquisition are those of a replay, so a campaign's
report equals a replay of its session (same ``restarts`` and ``seed``).

Progress: one log line per written step (frequency, |H|, phase, time left) and the
identification's search progress, through Prefect's run logger: on the console, one line
each (no carriage returns), and in the Prefect UI; and the artifact ``<specimen>-live``
(:class:`vibid.flows.live.LiveAfc`): the AFC measured so far, updated at most every few
seconds and on the last step, with the identified model over it once the flow has it.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

from prefect import flow

from vibid.flows.tasks import afc_task, identify_task, publish_artifacts, report_task, run_logger
from vibid.pipeline import RESTARTS, SEED, read_setup, require_converged

#: The reason prefix of a campaign ended by a driver's fault (retried as a resume).
TRANSIENT_REASON = "stand fault:"


def is_transient(result) -> bool:
    """Whether a :class:`~vibid.acquisition.campaign.CampaignResult` ended on a stand fault
    that a resume may get past (not the abort limit, not an operator's stop)."""
    return result.run_status == "aborted" and result.reason.startswith(TRANSIENT_REASON)


def default_report_dir(out) -> str:
    """The report folder beside a session file: ``<session stem>-report``."""
    out = Path(out)
    return os.fspath(out.with_name(f"{out.stem}-report"))


def acquire(
    setup,
    *,
    stand: str,
    config,
    out,
    resume: bool = False,
    realtime: bool = False,
    retries: int = 2,
    retry_delay_s: float = 1.0,
    logger=None,
    live=None,
    chooser=None,
    **campaign_options,
):
    """Run the campaign, retrying a transient stand fault up to ``retries`` times as a
    resume (the stand reopened, the session continued from its first missing step).
    ``live``: a :class:`~vibid.flows.live.LiveAfc` each written step goes to (the
    ``<specimen>-live`` artifact), or None; ``chooser``: an adaptive campaign's
    :class:`~vibid.planner.adaptive.AdaptiveCampaign` (it reads the steps from the file on
    a resume). Returns the last :class:`~vibid.acquisition.campaign.CampaignResult`."""
    from vibid.acquisition.campaign import run_campaign
    from vibid.acquisition.stand import open_stand

    logger = logger or run_logger()

    def step_logged(p) -> None:
        logger.info("%s", step_line(p))
        if live is not None:
            live.update(p)  # throttled; never raises

    for attempt in range(retries + 1):
        logger.info(
            "opening the %s stand%s",
            stand,
            " (solving the virtual specimen)" if stand == "simulated" else "",
        )
        with open_stand(stand, setup, config, realtime=realtime) as st:
            result = run_campaign(
                setup,
                st,
                out,
                config,
                resume=resume,
                progress=step_logged,
                chooser=chooser,
                **campaign_options,
            )
        logger.info(
            "campaign %s: %s %s (%d steps, stand time %s s)%s",
            result.path,
            result.run_status,
            result.reason,
            result.n_steps,
            "?" if result.stand_time_s is None else f"{result.stand_time_s:.1f}",
            f"; {result.stopped_because}" if result.stopped_because else "",
        )
        if not is_transient(result) or attempt == retries:
            return result
        logger.warning("%s; resuming (retry %d of %d)", result.reason, attempt + 1, retries)
        # a retry never repeats a written step (an adaptive campaign that stopped before
        # its first step left no file: it starts again)
        resume = os.path.exists(out)
        # operator/notes are attributes of a new session only
        campaign_options = {k: v for k, v in campaign_options.items() if k == "temperature_c"}
        time.sleep(retry_delay_s)
    return result


def step_line(p) -> str:
    """The log line of a written step (a :class:`~vibid.acquisition.campaign.StepProgress`):
    ``step 12/80: 225.00 Hz, |H| 3.412, phase -12.3 deg, ok (about 95 s left)``; nothing
    about the time left while it cannot be estimated (an adaptive campaign's steps to come
    are not known: ``eta_s`` nan)."""
    line = (
        f"step {p.index + 1}/{p.n_steps}: {p.frequency_hz:.2f} Hz, |H| {p.h_abs:.4g}, "
        f"phase {p.phase_deg:.1f} deg, {p.status}"
    )
    if math.isfinite(p.eta_s):
        line += f" (about {p.eta_s:.0f} s left)"
    return line


def show_recorded(live, out) -> None:
    """Give a resumed campaign's live AFC the steps its file holds already, and their stand
    time (a damaged file is the campaign's to report, not the live view's)."""
    from vibid.errors import VibidError
    from vibid.pipeline import session_afc
    from vibid.session import read_session

    try:
        with read_session(out) as s:
            driven = s.driven_s()
        live.add_recorded(session_afc(out).afc, driven)
    except VibidError as exc:
        live.logger.warning("live AFC: the steps recorded before could not be read: %s", exc)


def adaptive_campaign(
    setup,
    config,
    adaptive: dict,
    *,
    loop: bool,
    candidates,
    logger,
    restarts: int = RESTARTS,
    seed: int = SEED,
):
    """The live AFC and the :class:`~vibid.planner.adaptive.AdaptiveCampaign` of an adaptive
    campaign: each batch's fit is drawn over the points and its decision logged."""
    from vibid.flows.live import LiveAfc
    from vibid.identify.model.plate import plate_model
    from vibid.pipeline import parse_candidates
    from vibid.planner.adaptive import AdaptiveCampaign, AdaptiveOptions

    options = AdaptiveOptions.from_attribute(
        adaptive, plate_model(setup.identification.model).names
    )
    live = LiveAfc(
        setup.specimen.name,
        0,
        logger=logger,
        plan=(
            f"adaptive: until {', '.join(map(str, options.targets))} or "
            f"{options.max_stand_time_s:g} s of stand time, batches of {options.batch_size}"
        ),
    )

    def on_fit(fit, n_steps, stand_time_s) -> None:
        from vibid.planner.adaptive import reached

        live.set_identified(fit.result, setup, label=f"fit of {n_steps} steps")
        live.show(note=f"after {n_steps} steps: {reached(fit, options.targets)[1]}")

    names = parse_candidates(candidates)
    chooser = AdaptiveCampaign(
        setup,
        config,
        options,
        loop=loop,
        candidates=names,
        restarts=restarts,
        seed=seed,
        on_fit=on_fit,
        say=lambda line: logger.info("adaptive: %s", line),
    )
    return live, chooser


@flow(name="campaign")
def campaign_flow(
    setup_path: Path,
    *,
    stand: str = "simulated",
    stand_config: Path | None = None,
    out: Path,
    report_dir: Path | None = None,
    resume: bool = False,
    realtime: bool = False,
    loop: bool = True,
    candidates: list[str] | str | None = None,
    retries: int = 2,
    operator: str | None = None,
    notes: str | None = None,
    temperature_c: float | None = None,
    restarts: int = RESTARTS,
    seed: int = SEED,
    magnitude_only: bool = False,
    adaptive: dict | None = None,
):
    """Record a session of the setup at ``setup_path`` on ``stand`` (``"simulated"`` or
    ``"ni"``, configured by the STAND.json ``stand_config``) into ``out``, then identify it
    and write the report into ``report_dir`` (default: ``<out stem>-report`` beside ``out``).

    ``restarts`` and ``seed`` are the identification's (as ``vibid replay``), so a replay
    of the session with the same values gives the same report; ``magnitude_only`` fits
    |H| alone (``vibid campaign --magnitude-only``). ``adaptive``: the options of an
    adaptive campaign (:meth:`~vibid.planner.adaptive.AdaptiveOptions.attribute`: target,
    band, cap, batch size, seed), which chooses its steps as it goes, fitting between
    batches with the closed loop as ``loop`` and ``candidates`` say; the live AFC then
    shows each batch's fit.

    Returns the report (a dict). A campaign that did not complete (interrupted, aborted)
    ends the flow run ``Failed`` with its reason (a returned state: no traceback in the
    log; calling the flow raises, and ``return_state=True`` gives the state); the session
    keeps every step recorded (``resume=True`` continues it). Bad input or a refused resume
    (a :class:`~vibid.errors.VibidError`, e.g. a complete session, another setup's) ends it
    ``Failed`` the same way, its one line logged, the error the state's result.
    """
    from prefect.states import Failed

    from vibid.errors import VibidError

    logger = run_logger()
    try:
        return _campaign(
            setup_path,
            stand=stand,
            stand_config=stand_config,
            out=out,
            report_dir=report_dir,
            resume=resume,
            realtime=realtime,
            loop=loop,
            candidates=candidates,
            retries=retries,
            operator=operator,
            notes=notes,
            temperature_c=temperature_c,
            restarts=restarts,
            seed=seed,
            magnitude_only=magnitude_only,
            adaptive=adaptive,
            logger=logger,
        )
    except VibidError as exc:
        logger.error("%s", exc)
        return Failed(message=str(exc), data=exc)


def _campaign(
    setup_path,
    *,
    stand,
    stand_config,
    out,
    report_dir,
    resume,
    realtime,
    loop,
    candidates,
    retries,
    operator,
    notes,
    temperature_c,
    restarts,
    seed,
    magnitude_only,
    adaptive,
    logger,
):
    """The body of :func:`campaign_flow` (its docstring), in the flow run: the live view,
    the acquisition, then the identification and the report of a complete session."""
    from vibid.acquisition.stand_config import load_stand_config

    setup = read_setup(setup_path)
    config = load_stand_config(stand_config)
    live, chooser = _live_view(
        setup,
        config,
        adaptive,
        loop=loop,
        candidates=candidates,
        logger=logger,
        restarts=restarts,
        seed=seed,
    )
    if resume and os.path.exists(out):
        show_recorded(live, out)
    result = acquire(
        setup,
        stand=stand,
        config=config,
        out=out,
        resume=resume,
        realtime=realtime,
        retries=retries,
        logger=logger,
        live=live,
        chooser=chooser,
        operator=operator,
        notes=notes,
        temperature_c=temperature_c,
    )
    if result.run_status != "complete":
        return _not_complete(result, live, logger)
    return _identify_and_report(
        out,
        default_report_dir(out) if report_dir is None else report_dir,
        result,
        live,
        loop=loop,
        candidates=candidates,
        restarts=restarts,
        seed=seed,
        magnitude_only=magnitude_only,
    )


def _live_view(setup, config, adaptive, *, loop, candidates, logger, restarts, seed):
    """The live AFC of the campaign, and an adaptive campaign's chooser (None for the
    setup's own steps)."""
    from vibid.flows.live import LiveAfc

    if adaptive is None:
        live = LiveAfc(setup.specimen.name, len(setup.excitation.frequencies_hz), logger=logger)
        return live, None
    return adaptive_campaign(
        setup,
        config,
        adaptive,
        loop=loop,
        candidates=candidates,
        logger=logger,
        restarts=restarts,
        seed=seed,
    )


def _not_complete(result, live, logger):
    """A campaign that did not complete: its reason logged and on the live AFC's last
    version, and the flow run's ``Failed`` state (the file keeps its steps)."""
    from prefect.states import Failed

    message = (
        f"campaign {result.run_status}: {result.reason}; {result.path} keeps its "
        f"{result.n_steps} steps (resume to continue)"
    )
    logger.error("%s", message)
    live.close(note=f"campaign {result.run_status}: {result.reason}")
    return Failed(message=message)


def _identify_and_report(
    out, report_dir, result, live, *, loop, candidates, restarts, seed, magnitude_only
):
    """The stages of a replay on the complete session ``out``: AFC, identification (drawn
    over the live AFC's last version), report into ``report_dir``, artifacts; the report,
    once the identification is known to have converged."""
    data = afc_task(os.fspath(out))
    identified = identify_task(
        data,
        loop=loop,
        candidates=candidates,
        restarts=restarts,
        seed=seed,
        magnitude_only=magnitude_only,
    )
    # the live AFC's last version shows the report's fit (on the report's fine grid,
    # computed once here)
    live.set_identified(identified.result, data.setup)
    live.close(
        note="campaign complete; the identified model over the points"
        + (f" ({result.stopped_because})" if result.stopped_because else "")
    )
    # the folder gets report.json beside report.md
    report, _ = report_task(data, identified, report_dir=report_dir, session_path=out)
    publish_artifacts(report, specimen=data.setup.specimen.name, report_dir=report_dir)
    require_converged(identified)
    return report
