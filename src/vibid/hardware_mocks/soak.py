"""A soak test of a campaign on the simulated stand: faults at random steps, each survived.

:func:`soak` plays a whole campaign on the virtual stand while faults strike at chosen steps
(:func:`fault_plan` draws them from a seed), and checks what a lab needs from a campaign
that must stay up for hours:

* ``no_reply`` (the generator stops answering), ``error`` (it reports a fault), ``drop``
  (its serial link is unplugged) and ``overload`` (a knock on the table clips the response
  channel) are injected through the stand configuration (``simulated.faults``, fired at the
  step's index: :mod:`vibid.hardware_mocks.virtual_stand`). A fault that ends the campaign
  (``aborted``, ``stand fault: ...``) is retried as a resume on a reopened stand, as the
  campaign flow does;
* ``kill``: the run that reaches it is a separate process (``python -m vibid campaign ...
  --record-only``, given the overloads on its way), sent SIGKILL at a random instant within
  a step's time after it reported the step; the next run resumes the file, as ``--resume``.

Checked on the way and at the end (a failed check raises :class:`SoakError`):

* every step reported done is in the file, no step is in it twice, and the file's steps are
  the setup's frequencies in acquisition order (``complete`` at the end);
* the generator output is off after every fault that ends a run: at the run's end where
  the link still works, and by the first command of the next run where it does not (a
  dropped link, a killed process), before any frequency is played;
* the identification of the soaked session is then compared with the truth (each declared
  parameter's error in its std) and, with ``reference=True``, with an uninterrupted run of
  the same stand (chi2/dof, ``unexplained_residual``).

The campaign is a parameter: the setup's stepped sine by default (in-process runs of
:func:`vibid.acquisition.campaign.run_campaign`, process runs of ``vibid campaign
--record-only``), or with ``adaptive`` an adaptive campaign (:mod:`vibid.planner.adaptive`:
in process with its chooser, as a process ``vibid campaign --adaptive`` with the same
options, which runs the Prefect flow). An adaptive campaign's steps are not known in
advance: the file must then hold every step reported, once, in the order acquired, and end
``complete`` when the campaign decided to stop. What a SIGKILLed process leaves running
after a grace of a few seconds (Prefect's temporary server would be, were it not tied to
its parent: :mod:`vibid.flows.server`) is removed with the process group and counted
(``orphans``).
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vibid.errors import VibidError

__all__ = [
    "Fault",
    "FaultOutcome",
    "SoakError",
    "SoakResult",
    "Identification",
    "fault_plan",
    "identify_session",
    "soak",
]

#: faults the soak knows: the virtual stand's (generator, DAQ) and SIGKILL of the process
KINDS = ("no_reply", "error", "drop", "overload", "kill")
#: a generator that stops answering loses this many replies (its shutdown's too)
NO_REPLY_COUNT = 5
#: after a SIGKILL, how long what the process started may take to end by itself, s
ORPHAN_GRACE_S = 5.0
#: a step reported done, on the console line of ``--record-only`` or in the flow's log
_PROGRESS = re.compile(r"\bstep (\d+)/(\d+)\b")


class SoakError(VibidError):
    """A soak check failed (one line: which, at which step)."""


@dataclass(frozen=True, order=True)
class Fault:
    """A fault of ``kind`` (:data:`KINDS`) at the campaign's step ``index`` (0-based)."""

    index: int
    kind: str


@dataclass
class FaultOutcome:
    """What became of one fault: ``fired`` (it struck), ``ended_run`` (it stopped the
    campaign run it struck), ``output_off`` (the output was off after it: True/False, None
    where the fault does not stop the drive, an overload), ``survived`` (it fired and the
    campaign went on to complete with every check passed)."""

    fault: Fault
    fired: bool = False
    ended_run: bool = False
    output_off: bool | None = None
    survived: bool = False
    note: str = ""


@dataclass(frozen=True)
class Identification:
    """The identification of a session: chi2/dof (the final model's, as reported), whether
    a residual above the noise remains, and per declared parameter (value, std, truth)."""

    chi2_dof: float
    unexplained: bool
    parameters: dict[str, tuple[float, float, float]]
    effects: tuple[str, ...] = ()
    seconds: float = math.nan

    def error_std(self) -> dict[str, float]:
        """|value − truth| / std per parameter."""
        return {n: abs(v - t) / s for n, (v, s, t) in self.parameters.items()}


@dataclass
class SoakResult:
    """The soak's record: each fault's outcome, the steps, the runs, the identification."""

    path: str
    outcomes: list[FaultOutcome]
    n_steps: int
    duplicates: int
    runs: int
    seconds: float
    stand_time_s: float | None = None
    orphans: int = 0  #: server processes a killed campaign process left behind (removed)
    identification: Identification | None = None
    reference: Identification | None = None
    reference_stand_time_s: float | None = None
    log: list[str] = field(default_factory=list)

    @property
    def survived(self) -> int:
        return sum(o.survived for o in self.outcomes)

    def summary(self) -> str:
        """The soak in a few lines: faults survived by kind, steps, chi2/dof, errors."""
        kinds = {}
        for o in self.outcomes:
            got, total = kinds.get(o.fault.kind, (0, 0))
            kinds[o.fault.kind] = (got + o.survived, total + 1)
        by_kind = ", ".join(f"{k} {a}/{b}" for k, (a, b) in kinds.items())
        lines = [
            f"faults survived: {self.survived} of {len(self.outcomes)} ({by_kind})",
            f"steps: {self.n_steps} in the file, duplicates {self.duplicates}, "
            f"campaign runs {self.runs}, orphaned processes removed {self.orphans}, stand time "
            + (f"{self.stand_time_s:.1f} s" if self.stand_time_s is not None else "?")
            + (
                f" (without faults {self.reference_stand_time_s:.1f} s)"
                if self.reference_stand_time_s is not None
                else ""
            ),
        ]
        for label, ident in (("soaked", self.identification), ("without faults", self.reference)):
            if ident is None:
                continue
            errors = ", ".join(f"{n} {e:.2f}" for n, e in ident.error_std().items())
            lines.append(
                f"{label}: chi2/dof {ident.chi2_dof:.3f}, unexplained_residual "
                f"{str(ident.unexplained).lower()}, effects "
                f"{', '.join(ident.effects) or 'none'}; |error|/std {errors}"
            )
        ident_s = sum(i.seconds for i in (self.identification, self.reference) if i is not None)
        lines.append(f"run time {self.seconds:.1f} s (identification {ident_s:.1f} s of it)")
        return "\n".join(lines)


def fault_plan(
    n_steps: int, counts: dict[str, int], seed: int, *, gap: int = 4, first: int = 1
) -> tuple[Fault, ...]:
    """``counts`` faults by kind at distinct random steps (from ``seed``), sorted, at least
    ``gap`` steps apart, from step ``first`` on and at least ``gap`` steps before the end
    (a killed process may have written a step or two beyond its kill step)."""
    kinds = [k for k, c in counts.items() for _ in range(int(c))]
    for k in kinds:
        if k not in KINDS:
            raise ValueError(f"unknown fault kind {k!r}, expected one of {', '.join(KINDS)}")
    if not kinds:
        return ()
    rng = np.random.default_rng(seed)
    t = len(kinds)
    room = (n_steps - gap - first) - (t - 1) * (gap - 1)  # steps first .. n_steps-gap-1
    if room < t:
        raise ValueError(f"{t} faults at least {gap} steps apart do not fit in {n_steps} steps")
    picks = np.sort(rng.choice(room, size=t, replace=False))
    kinds = [str(k) for k in rng.permutation(kinds)]
    return tuple(
        Fault(int(first + y + i * (gap - 1)), k) for i, (y, k) in enumerate(zip(picks, kinds))
    )


def identify_session(
    path, truth: dict[str, float], *, restarts: int = 2, seed: int = 0
) -> Identification:
    """The identification the report would give (the closed loop included), against ``truth``."""
    from vibid.pipeline import identify_afc, session_afc

    t = time.perf_counter()
    found = identify_afc(session_afc(path), loop=True, restarts=restarts, seed=seed)
    r = found.result
    if found.loop is not None:
        unexplained = bool(found.loop.unexplained_residual)
        effects = tuple(found.loop.effects)
    else:
        from vibid.identify.fit.noise import explains

        unexplained, effects = explains(r) is False, ()
    params = {
        n: (float(v), float(s), float(truth[n]))
        for n, v, s in zip(r.parameter_names, r.values, r.std)
        if n in truth
    }
    return Identification(
        float(r.chi2_reduced_reported), unexplained, params, effects, time.perf_counter() - t
    )


def soak(
    setup,
    config,
    out,
    faults: Sequence[Fault],
    *,
    runner: Callable | None = None,
    cli: Sequence[str] | None = None,
    seed: int = 0,
    identify: bool = True,
    reference: bool = False,
    restarts: int = 2,
    expected_hz: Sequence[float] | None = None,
    max_runs: int | None = None,
    log: Callable[[str], Any] | None = None,
    adaptive=None,
) -> SoakResult:
    """Run ``setup``'s campaign on the simulated stand of ``config`` into ``out`` (a new
    file) through ``faults`` (:func:`fault_plan`), then check and identify it.

    Parameters
    ----------
    setup, config : the declared setup (with its excitation) and the stand configuration;
        its ``simulated`` section is the truth, its ``faults`` are replaced by ``faults``
        and its generator URL by a stand name of this soak's own.
    runner : the in-process campaign (default :func:`~vibid.acquisition.campaign.run_campaign`,
        with an adaptive campaign's chooser when ``adaptive``).
    cli : the process campaign's command and options (``kill`` faults run it; default
        ``campaign --record-only``, or ``campaign --adaptive`` with ``adaptive``'s options).
    adaptive : an :class:`~vibid.planner.adaptive.AdaptiveOptions`: soak an adaptive campaign.
    seed : the random kill instants.
    identify, reference, restarts : identify the soaked session (and an uninterrupted run's,
        ``reference``) with the closed loop and ``restarts`` global restarts.
    expected_hz : the steps the file must hold, in order (default: the setup's frequencies).
    max_runs : campaign runs at most (default: one per fault, and four more).
    log : called with one line per event (default: nothing).
    """
    from vibid.acquisition.campaign import run_campaign
    from vibid.acquisition.stand_config import StandConfig
    from vibid.identify import configure
    from vibid.session import read_session

    configure()
    say = log or (lambda line: None)
    if adaptive is not None:
        runner = runner or _adaptive_runner(setup, config, adaptive, say)
        cli = cli or ("campaign", "--adaptive", *_adaptive_args(adaptive))
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
    doc = _config_doc(config, name, injected)
    live = StandConfig.from_dict(doc)  # with the faults, for in-process runs
    child_path = out + ".soak-stand.json"  # a killed process's: the faults on its way
    setup_path = out + ".soak-setup.json"
    Path(setup_path).write_text(setup.to_json())
    want = (
        None
        if adaptive is not None
        else np.asarray(
            setup.excitation.frequencies_hz if expected_hz is None else expected_hz, float
        )
    )
    outcomes = {f: FaultOutcome(f) for f in faults}
    by_key = dict(enumerate(injected))  # simulated.faults place -> fault
    rng = np.random.default_rng(seed)
    reported: list[int] = []  # every step reported done, all runs
    awaiting: list[Fault] = []  # faults whose output the next in-process run must switch off first
    runs = orphans = 0
    max_runs = max_runs or len(faults) + 4
    t0 = time.perf_counter()
    lines: list[str] = []

    def note(line: str) -> None:
        lines.append(line)
        say(line)

    try:
        while True:
            done = _steps_in(out, want, reported)
            if (
                os.path.exists(out)
                and (want is None or done == want.size)
                and _status(out) == "complete"
            ):
                break
            runs += 1
            if runs > max_runs:
                raise SoakError(f"{runs - 1} campaign runs and still not complete")
            pending = [f for f in faults if not outcomes[f].fired and f.index >= done]
            t_run = time.perf_counter()
            ending = next((f for f in pending if f.kind != "overload"), None)
            if ending is not None and ending.kind == "kill":
                # this run ends by SIGKILL: it is a process, given the overloads before it
                kill = ending
                on_the_way = [f for f in pending if f.index < kill.index]
                Path(child_path).write_text(json.dumps(_config_doc(config, name, on_the_way)))
                killed, seen, left = _killed_run(out, setup_path, child_path, cli, kill.index, rng)
                reported += seen
                orphans += left
                now = _steps_in(out, want, reported)
                for f in on_the_way:  # it struck the step's first record, and the step is in
                    outcomes[f].fired = now > f.index
                o = outcomes[kill]
                o.fired = o.ended_run = killed
                o.note = (
                    f"SIGKILL after step {kill.index} was reported"
                    if killed
                    else "the process ended before the signal"
                )
                struck = ", ".join(f"{f.kind}@{f.index}" for f in on_the_way if outcomes[f].fired)
                note(
                    f"run {runs}: process from step {done}: {o.note}; {now} steps in the file"
                    f"{'; fired ' + struck if struck else ''}"
                    f"{f'; {left} orphaned process(es) removed' if left else ''} "
                    f"({time.perf_counter() - t_run:.1f} s)"
                )
                if killed:
                    awaiting.append(kill)  # a killed process leaves the output as it was
                continue
            result, fired, first_off, end_off, linked = _in_process_run(
                runner, setup, live, out, name, reported
            )
            for f in awaiting:
                # the run before could not switch the output off (link down, process killed):
                # this run's first command must, before any frequency is played
                outcomes[f].output_off = first_off
                if not first_off:
                    raise SoakError(
                        f"the run after {f.kind} at step {f.index} did not switch "
                        "the output off first"
                    )
            awaiting.clear()
            struck = [by_key[k] for k in fired]
            for f in struck:
                outcomes[f].fired = True
            fired_text = ", ".join(f"{f.kind}@{f.index}" for f in struck)
            note(
                f"run {runs}: in process from step {done}: {result.run_status} {result.reason} "
                f"({result.n_steps} steps{'; fired ' + fired_text if struck else ''}; "
                f"{time.perf_counter() - t_run:.1f} s)"
            )
            if result.run_status == "complete":
                continue
            if result.run_status != "aborted" or not result.reason.startswith("stand fault:"):
                raise SoakError(f"run {runs} ended {result.run_status}: {result.reason}")
            enders = [f for f in struck if f.kind != "overload"]
            if len(enders) != 1:
                raise SoakError(
                    f"run {runs}: a stand fault with {len(enders)} injected faults "
                    f"firing: {result.reason}"
                )
            o = outcomes[enders[0]]
            o.ended_run = True
            if linked:
                o.output_off = end_off
                if not end_off:
                    raise SoakError(f"output left on after {o.fault.kind} at step {o.fault.index}")
            else:
                awaiting.append(o.fault)  # unplugged: the next run must switch it off first
        stand_time = _final_checks(out, want, reported)
    finally:
        for p in (child_path, setup_path):
            if os.path.exists(p):
                os.unlink(p)
    for o in outcomes.values():
        if o.fault.kind == "overload":
            o.output_off = (
                None  # the drive goes on: the clipped record is the step's or recorded again
            )
        o.survived = o.fired and (o.output_off is not False)
    with read_session(out) as s:
        n_file = len(s)
    duplicates = len(reported) - len(set(reported))
    result = SoakResult(
        out,
        [outcomes[f] for f in faults],
        n_file,
        duplicates,
        runs,
        time.perf_counter() - t0,
        stand_time,
        orphans,
        log=lines,
    )
    if duplicates:
        raise SoakError(f"{duplicates} steps reported done twice")
    truth = _truth(live)
    if identify:
        result.identification = identify_session(out, truth, restarts=restarts)
    if reference:
        ref_out = out + ".reference.h5"
        if os.path.exists(ref_out):
            os.unlink(ref_out)
        ref_config = StandConfig.from_dict(_config_doc(config, name + "-ref", []))
        ref_runner = (
            runner
            if adaptive is None
            else _adaptive_runner(setup, ref_config, adaptive, lambda line: None)
        )
        ref, _, _, _, _ = _in_process_run(ref_runner, setup, ref_config, ref_out, name + "-ref", [])
        if ref.run_status != "complete":
            raise SoakError(f"the run without faults ended {ref.run_status}: {ref.reason}")
        result.reference_stand_time_s = ref.stand_time_s
        if identify:
            result.reference = identify_session(ref_out, truth, restarts=restarts)
    result.seconds = time.perf_counter() - t0
    return result


# -- the adaptive campaign ------------------------------------------------------------------------
def _adaptive_runner(setup, config, options, say):
    """In-process runs of one adaptive campaign (one chooser: its fit carries over)."""
    from functools import partial

    from vibid.acquisition.campaign import run_campaign
    from vibid.planner.adaptive import AdaptiveCampaign

    chooser = AdaptiveCampaign(
        setup, config, options, seed=options.seed, say=lambda line: say(f"  adaptive: {line}")
    )
    return partial(run_campaign, chooser=chooser)


def _adaptive_args(options) -> list[str]:
    """``vibid campaign --adaptive``'s options for ``options``."""
    lo, hi = options.band_hz
    return [
        "--target",
        *map(str, options.targets),
        "--band",
        f"{lo!r}:{hi!r}",
        "--max-stand-time",
        repr(options.max_stand_time_s),
        "--batch",
        str(options.batch_size),
        "--seed",
        str(options.seed),
    ]


# -- one campaign run ----------------------------------------------------------------------------
def _in_process_run(runner, setup, config, out, name, reported):
    """One run on a (re)opened stand: ``(result, fault keys fired in it, output off after its
    first command, output off at its end, link up at its end)``."""
    from vibid.acquisition.stand import open_stand
    from vibid.hardware_mocks.virtual_stand import lookup_stand

    resume = os.path.exists(out)
    with open_stand("simulated", setup, config) as stand:
        virtual = lookup_stand(name)
        fired_before = set(virtual.instrument.sim_fired)
        result = runner(
            setup,
            stand,
            out,
            config,
            resume=resume,
            progress=lambda p: reported.append(int(p.index)),
        )
        inst = virtual.instrument
        end_off, linked = not inst.output_on, inst.connected
        fired = sorted(set(inst.sim_fired) - fired_before)
    log = inst.sim_log
    first_off = bool(log) and log[0][0] == "OUTP OFF" and not _played_before_off(log)
    return result, fired, first_off, end_off, linked


def _played_before_off(log) -> bool:
    """Whether a frequency or amplitude was set before the first ``OUTP OFF``."""
    for command, _ in log:
        if command.startswith("OUTP OFF"):
            return False
        if command.startswith(("FREQ ", "VOLT ", "OUTP ON")):
            return True
    return True


def _killed_run(out, setup_path, stand_path, cli, kill_index, rng):
    """Run the campaign as a process and SIGKILL it at a random instant after it reported
    step ``kill_index``: ``(killed, the steps it reported, orphaned processes removed)``:
    what the killed process left running in its process group (Prefect's temporary server)
    is removed after it."""
    import vibid

    args = [
        sys.executable,
        "-m",
        "vibid",
        cli[0],
        setup_path,
        "--stand",
        "simulated",
        "--stand-config",
        stand_path,
        "--out",
        out,
        *cli[1:],
    ]
    if os.path.exists(out):
        args.append("--resume")
    env = dict(os.environ)
    src = str(Path(vibid.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([src, env.get("PYTHONPATH", "")])
    child = subprocess.Popen(
        args,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
    )
    seen, times, killed = [], [], False
    try:
        for line in child.stderr:
            m = _PROGRESS.search(line)
            if not m:
                continue
            seen.append(int(m.group(1)) - 1)
            times.append(time.perf_counter())
            if seen[-1] >= kill_index:
                step_s = float(np.mean(np.diff(times))) if len(times) > 1 else 0.2
                time.sleep(float(rng.uniform(0.0, step_s)))  # somewhere in the next step
                os.kill(child.pid, signal.SIGKILL)
                killed = True
                break
    finally:
        if killed:
            child.wait()
        # what it left running holds its stderr open: removed before reading to the end
        # (after a grace of ORPHAN_GRACE_S: a child told to end with its parent is ending)
        left = _remove_group(child.pid, grace_s=ORPHAN_GRACE_S) if killed else 0
        try:
            child.communicate(timeout=600)
        except subprocess.TimeoutExpired:
            child.kill()
            _remove_group(child.pid)
            child.communicate()
    if killed and child.returncode != -signal.SIGKILL:
        killed = False  # it ended by itself between the report and the signal
    if not killed and child.returncode not in (0, -signal.SIGKILL):
        raise SoakError(f"the campaign process failed ({child.returncode})")
    return killed, seen, left


def _remove_group(pgid: int, grace_s: float = 0.0) -> int:
    """SIGKILL whatever is left in process group ``pgid`` after ``grace_s``; how many
    processes were left."""
    deadline = time.monotonic() + grace_s
    left = _alive_in_group(pgid)
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = _alive_in_group(pgid)
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    return left


def _alive_in_group(pgid: int) -> int:
    """Processes of group ``pgid`` that are not zombies (Linux /proc)."""
    import glob

    left = 0
    for stat in glob.glob("/proc/[0-9]*/stat"):
        try:
            fields = Path(stat).read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            left += 1
    return left


# -- checks ----------------------------------------------------------------------------------------
def _status(out) -> str | None:
    from vibid.session import read_session

    with read_session(out) as s:
        return s.run_status


def _steps_in(out, want, reported) -> int:
    """The file's step count, after checking that its steps are ``want``'s first ones (None:
    an adaptive campaign's, whatever they are) and that every step reported done is among
    them."""
    if not os.path.exists(out):
        if reported:
            raise SoakError(f"steps {sorted(set(reported))[:5]}... reported, but no session file")
        return 0
    from vibid.session import file_problems, read_session

    problems = file_problems(out)
    if problems:
        raise SoakError(f"{out}: {problems[0]}")
    with read_session(out) as s:
        got = np.asarray(s.frequencies_hz(), float)
    n = got.size
    if want is not None and (n > want.size or not np.array_equal(got, want[:n])):
        bad = next(i for i in range(n) if i >= want.size or got[i] != want[i])
        raise SoakError(
            f"step {bad} of the file is {got[bad]:g} Hz, not the setup's step "
            f"{bad} (each step once, in order)"
        )
    if reported and max(reported) >= n:
        raise SoakError(f"step {max(reported)} was reported done but the file holds {n} steps")
    return n


def _final_checks(out, want, reported) -> float | None:
    from vibid.session import read_session

    n = _steps_in(out, want, reported)
    with read_session(out) as s:
        status, stand_time = s.run_status, s.stand_time_s
    if (want is not None and n != want.size) or status != "complete":
        raise SoakError(f"{out}: {status} with {n} of {'?' if want is None else want.size} steps")
    return stand_time


def _config_doc(config, name: str, faults) -> dict:
    """The stand configuration as a document, with this soak's stand name and faults."""
    doc = json.loads(json.dumps(config.to_dict()))
    doc["generator"]["url"] = f"vibidsim://{name}"
    doc["simulated"]["faults"] = [
        {
            "kind": f.kind,
            "at_index": f.index,
            **({"count": NO_REPLY_COUNT} if f.kind == "no_reply" else {}),
        }
        for f in faults
    ]
    return doc


def _truth(config) -> dict[str, float]:
    from vibid.hardware_mocks.virtual_stand import true_parameters

    return true_parameters(config)
