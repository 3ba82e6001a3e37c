"""The soak itself (:func:`soak`): campaign runs, each from where the file ends and each
through the faults due in it, until the campaign is complete; then the file checked, each
fault's outcome settled, and the session identified (beside an uninterrupted run's)."""

from __future__ import annotations

import json
import os
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vibid.soak.checks import SoakError, final_checks, run_status, steps_in
from vibid.soak.faults import Fault, config_doc, truth
from vibid.soak.record import FaultOutcome, SoakResult, identify_session
from vibid.soak.runs import adaptive_args, adaptive_runner, in_process_run, killed_run


@dataclass(frozen=True)
class SoakOptions:
    """How a soak plays its campaign and judges it (every field has its default).

    The campaign:

    * ``runner`` — the in-process campaign (default
      :func:`~vibid.acquisition.campaign.run_campaign`, with an adaptive campaign's chooser
      when ``adaptive``);
    * ``cli`` — the process campaign's command and options (``kill`` faults run it; default
      ``campaign --record-only``, or ``campaign --adaptive`` with ``adaptive``'s options);
    * ``adaptive`` — an :class:`~vibid.planner.adaptive.AdaptiveOptions`: soak an adaptive
      campaign;
    * ``expected_hz`` — the steps the file must hold, in order (default: the setup's
      frequencies);
    * ``max_runs`` — campaign runs at most (default: one per fault, and four more);
    * ``seed`` — the random kill instants.

    The judging: ``identify``, ``reference``, ``restarts`` — identify the soaked session (and
    an uninterrupted run's, ``reference``) with the closed loop and ``restarts`` global
    restarts. ``log`` is called with one line per event (default: nothing).
    """

    runner: Callable | None = None
    cli: Sequence[str] | None = None
    adaptive: Any = None
    expected_hz: Sequence[float] | None = None
    max_runs: int | None = None
    seed: int = 0
    identify: bool = True
    reference: bool = False
    restarts: int = 2
    log: Callable[[str], Any] | None = None


@dataclass
class _Day:
    """What the soak carries from one campaign run to the next."""

    setup: Any
    config: Any  #: the stand configuration as given (its faults replaced per run)
    live: Any  #: ... with the injected faults and this soak's stand name: in-process runs
    out: str
    name: str  #: this soak's stand name
    faults: list[Fault]  #: sorted
    runner: Callable
    cli: Sequence[str]
    want: np.ndarray | None  #: the steps the file must hold, in order (None: adaptive)
    setup_path: str  #: the setup, for a process run
    child_path: str  #: a killed process's stand configuration: the faults on its way
    max_runs: int
    rng: np.random.Generator
    say: Callable[[str], Any]
    t0: float
    outcomes: dict[Fault, FaultOutcome] = field(default_factory=dict)
    by_key: dict[int, Fault] = field(default_factory=dict)  #: simulated.faults place -> fault
    reported: list[int] = field(default_factory=list)  #: every step reported done, all runs
    #: faults whose output the next in-process run must switch off first
    awaiting: list[Fault] = field(default_factory=list)
    runs: int = 0
    orphans: int = 0
    lines: list[str] = field(default_factory=list)

    def note(self, line: str) -> None:
        self.lines.append(line)
        self.say(line)


def soak(
    setup, config, out, faults: Sequence[Fault], options: SoakOptions = SoakOptions()
) -> SoakResult:
    """Run ``setup``'s campaign on the simulated stand of ``config`` into ``out`` (a new
    file) through ``faults`` (:func:`~vibid.soak.faults.fault_plan`), then check and
    identify it; a :class:`~vibid.soak.record.SoakResult`.

    ``setup`` and ``config`` are the declared setup (with its excitation) and the stand
    configuration; its ``simulated`` section is the truth, its ``faults`` are replaced by
    ``faults`` and its generator URL by a stand name of this soak's own. ``options``
    (:class:`SoakOptions`): which campaign, how it is judged. A failed check raises
    :class:`~vibid.soak.checks.SoakError`.
    """
    from vibid.identify import configure

    configure()
    day = _open_day(setup, config, out, faults, options)
    try:
        _run_until_complete(day)
        stand_time = final_checks(day.out, day.want, day.reported)
    finally:
        for p in (day.child_path, day.setup_path):
            if os.path.exists(p):
                os.unlink(p)
    _settle_outcomes(day)
    result = _record(day, stand_time)
    true = truth(day.live)
    if options.identify:
        result.identification = identify_session(day.out, true, restarts=options.restarts)
    if options.reference:
        _reference_run(day, options, true, result)
    result.seconds = time.perf_counter() - day.t0
    return result


def _open_day(setup, config, out, faults, options: SoakOptions) -> _Day:
    """The soak's campaign (runner and process command), its checked faults, its stand
    configuration with them, and the setup written for the process runs."""
    from vibid.acquisition.campaign import run_campaign
    from vibid.acquisition.stand_config import StandConfig

    say = options.log or (lambda line: None)
    runner, cli, adaptive = options.runner, options.cli, options.adaptive
    if adaptive is not None:
        runner = runner or adaptive_runner(setup, config, adaptive, say)
        cli = cli or ("campaign", "--adaptive", *adaptive_args(adaptive))
    runner = runner or run_campaign
    cli = cli or ("campaign", "--record-only")
    out = os.fspath(out)
    if os.path.exists(out):
        raise SoakError(f"{out}: already exists")
    faults = sorted(faults)
    if len({f.index for f in faults}) != len(faults):
        raise SoakError("two faults at one step")
    name = f"soak-{uuid.uuid4().hex[:12]}"
    injected = [f for f in faults if f.kind != "kill"]
    live = StandConfig.from_dict(config_doc(config, name, injected))
    setup_path = out + ".soak-setup.json"
    Path(setup_path).write_text(setup.to_json())
    want = None
    if adaptive is None:
        hz = setup.excitation.frequencies_hz if options.expected_hz is None else options.expected_hz
        want = np.asarray(hz, float)
    return _Day(
        setup,
        config,
        live,
        out,
        name,
        faults,
        runner,
        cli,
        want=want,
        setup_path=setup_path,
        child_path=out + ".soak-stand.json",
        max_runs=options.max_runs or len(faults) + 4,
        rng=np.random.default_rng(options.seed),
        say=say,
        t0=time.perf_counter(),
        outcomes={f: FaultOutcome(f) for f in faults},
        by_key=dict(enumerate(injected)),
    )


def _run_until_complete(day: _Day) -> None:
    """Campaign runs, each from the file's first missing step, until the file is complete:
    a process killed at the next ``kill`` if it comes before any other fault that ends a
    run, else a run in process."""
    while True:
        done = steps_in(day.out, day.want, day.reported)
        if (
            os.path.exists(day.out)
            and (day.want is None or done == day.want.size)
            and run_status(day.out) == "complete"
        ):
            return
        day.runs += 1
        if day.runs > day.max_runs:
            raise SoakError(f"{day.runs - 1} campaign runs and still not complete")
        pending = [f for f in day.faults if not day.outcomes[f].fired and f.index >= done]
        t_run = time.perf_counter()
        ending = next((f for f in pending if f.kind != "overload"), None)
        if ending is not None and ending.kind == "kill":
            _killed_process_run(day, ending, pending, done, t_run)
        else:
            _in_process_campaign_run(day, done, t_run)


def _killed_process_run(day: _Day, kill: Fault, pending, done: int, t_run: float) -> None:
    """The run that ends by SIGKILL at ``kill``: a process, given the overloads before it."""
    on_the_way = [f for f in pending if f.index < kill.index]
    Path(day.child_path).write_text(json.dumps(config_doc(day.config, day.name, on_the_way)))
    killed, seen, left = killed_run(
        day.out, day.setup_path, day.child_path, day.cli, kill.index, day.rng
    )
    day.reported += seen
    day.orphans += left
    now = steps_in(day.out, day.want, day.reported)
    for f in on_the_way:  # it struck the step's first record, and the step is in
        day.outcomes[f].fired = now > f.index
    o = day.outcomes[kill]
    o.fired = o.ended_run = killed
    o.note = (
        f"SIGKILL after step {kill.index} was reported"
        if killed
        else "the process ended before the signal"
    )
    struck = ", ".join(f"{f.kind}@{f.index}" for f in on_the_way if day.outcomes[f].fired)
    day.note(
        f"run {day.runs}: process from step {done}: {o.note}; {now} steps in the file"
        f"{'; fired ' + struck if struck else ''}"
        f"{f'; {left} orphaned process(es) removed' if left else ''} "
        f"({time.perf_counter() - t_run:.1f} s)"
    )
    if killed:
        day.awaiting.append(kill)  # a killed process leaves the output as it was


def _in_process_campaign_run(day: _Day, done: int, t_run: float) -> None:
    """A run in process on a reopened stand: its first command switched the output off
    where the run before could not, and a run it did not complete ended by one fault."""
    result, fired, first_off, end_off, linked = in_process_run(
        day.runner, day.setup, day.live, day.out, day.name, day.reported
    )
    for f in day.awaiting:
        # the run before could not switch the output off (link down, process killed):
        # this run's first command must, before any frequency is played
        day.outcomes[f].output_off = first_off
        if not first_off:
            raise SoakError(
                f"the run after {f.kind} at step {f.index} did not switch the output off first"
            )
    day.awaiting.clear()
    struck = [day.by_key[k] for k in fired]
    for f in struck:
        day.outcomes[f].fired = True
    fired_text = ", ".join(f"{f.kind}@{f.index}" for f in struck)
    day.note(
        f"run {day.runs}: in process from step {done}: {result.run_status} {result.reason} "
        f"({result.n_steps} steps{'; fired ' + fired_text if struck else ''}; "
        f"{time.perf_counter() - t_run:.1f} s)"
    )
    if result.run_status != "complete":
        _check_ended_by_one_fault(day, result, struck, end_off, linked)


def _check_ended_by_one_fault(day: _Day, result, struck, end_off: bool, linked: bool) -> None:
    """A run that did not complete: a stand fault, of exactly one injected fault that ends
    a run, after which the output is off (or, its link down, the next run's first job)."""
    if result.run_status != "aborted" or not result.reason.startswith("stand fault:"):
        raise SoakError(f"run {day.runs} ended {result.run_status}: {result.reason}")
    enders = [f for f in struck if f.kind != "overload"]
    if len(enders) != 1:
        raise SoakError(
            f"run {day.runs}: a stand fault with {len(enders)} injected faults "
            f"firing: {result.reason}"
        )
    o = day.outcomes[enders[0]]
    o.ended_run = True
    if linked:
        o.output_off = end_off
        if not end_off:
            raise SoakError(f"output left on after {o.fault.kind} at step {o.fault.index}")
    else:
        day.awaiting.append(o.fault)  # unplugged: the next run must switch it off first


def _settle_outcomes(day: _Day) -> None:
    """Each fault survived where it fired and the output was not left on after it."""
    for o in day.outcomes.values():
        if o.fault.kind == "overload":
            # the drive goes on: the clipped record is the step's or recorded again
            o.output_off = None
        o.survived = o.fired and (o.output_off is not False)


def _record(day: _Day, stand_time: float | None) -> SoakResult:
    """The soak's record of the complete file; no step may have been reported twice."""
    from vibid.session import read_session

    with read_session(day.out) as s:
        n_file = len(s)
    duplicates = len(day.reported) - len(set(day.reported))
    result = SoakResult(
        day.out,
        [day.outcomes[f] for f in day.faults],
        n_file,
        duplicates,
        day.runs,
        time.perf_counter() - day.t0,
        stand_time,
        day.orphans,
        log=day.lines,
    )
    if duplicates:
        raise SoakError(f"{duplicates} steps reported done twice")
    return result


def _reference_run(day: _Day, options: SoakOptions, true, result: SoakResult) -> None:
    """The same campaign on the same stand without faults, into ``<out>.reference.h5``:
    its stand time and (``identify``) its identification go into ``result``."""
    from vibid.acquisition.stand_config import StandConfig

    ref_out = day.out + ".reference.h5"
    if os.path.exists(ref_out):
        os.unlink(ref_out)
    ref_config = StandConfig.from_dict(config_doc(day.config, day.name + "-ref", []))
    ref_runner = (
        day.runner
        if options.adaptive is None
        else adaptive_runner(day.setup, ref_config, options.adaptive, lambda line: None)
    )
    ref, _, _, _, _ = in_process_run(
        ref_runner, day.setup, ref_config, ref_out, day.name + "-ref", []
    )
    if ref.run_status != "complete":
        raise SoakError(f"the run without faults ended {ref.run_status}: {ref.reason}")
    result.reference_stand_time_s = ref.stand_time_s
    if options.identify:
        result.reference = identify_session(ref_out, true, restarts=options.restarts)
