"""One campaign run of a soak: in process on a (re)opened simulated stand, or as a
``vibid campaign`` process sent SIGKILL after a chosen step (what it leaves running in its
process group removed after it); and the adaptive campaign's runner and options."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from vibid.soak.checks import SoakError

#: after a SIGKILL, how long what the process started may take to end by itself, s
ORPHAN_GRACE_S = 5.0
#: a step reported done, on the console line of ``--record-only`` or in the flow's log
_PROGRESS = re.compile(r"\bstep (\d+)/(\d+)\b")


# -- the adaptive campaign ------------------------------------------------------------------------
def adaptive_runner(setup, config, options, say):
    """In-process runs of one adaptive campaign (one chooser: its fit carries over)."""
    from functools import partial

    from vibid.acquisition.campaign import run_campaign
    from vibid.planner.adaptive import AdaptiveCampaign

    chooser = AdaptiveCampaign(
        setup, config, options, seed=options.seed, say=lambda line: say(f"  adaptive: {line}")
    )
    return partial(run_campaign, chooser=chooser)


def adaptive_args(options) -> list[str]:
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


# -- in process ------------------------------------------------------------------------------------
def in_process_run(runner, setup, config, out, name, reported):
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


# -- a process, killed -----------------------------------------------------------------------------
def killed_run(out, setup_path, stand_path, cli, kill_index, rng):
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
