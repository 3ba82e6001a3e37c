"""`vibid campaign SETUP.json --stand simulated|ni [--stand-config STAND.json] [--out S.h5]
[--report DIR] [--no-loop] [--candidates A,B] [--restarts N] [--seed N] [--resume]
[--realtime] [--operator NAME] [--notes TEXT] [--temperature-c T] [--dry-run]
[--record-only] [--adaptive --target D=0.1% [--band 5:2000] [--max-stand-time 600]
[--batch 4]]`: the live stepped-sine campaign, then its identification report.

Plays the setup's frequencies on the stand and records the session step by step (each
step is in the file by the time the next one has settled; a crash or Ctrl-C leaves a valid
file that --resume continues), then fits the AFC, identifies the declared model, closes the
loop and writes the report (report.md, report.json and PNG figures) into --report DIR
(default: S-report beside the session file). It runs as the Prefect flow campaign_flow:
on Prefect's embedded temporary server, or on the server of PREFECT_API_URL. --stand
simulated puts the simulated instruments and the virtual specimen of the stand
configuration's "simulated" section behind the real drivers and runs as fast as it can,
unless --realtime paces it like the real stand. A transient stand fault is retried as a
resume (no step is recorded twice). --record-only records the session without Prefect and
without the report (one progress line per step on stderr). Exit 0 when the campaign
completes (and the identification converges), 1 when it is interrupted or aborted (the
reason is printed) or the input is bad.

--adaptive chooses the steps as the test goes (vibid.planner.adaptive): a coarse sweep over
the band, a fit after each batch, the next batch where the current fit learns most per
second of stand time, until every --target is reached by the report's own standard
uncertainty or the stand time reaches --max-stand-time. The file keeps the steps in the
order acquired and carries the options as its `adaptive` attribute, so --resume continues
it (with the options it was started with).
"""

from __future__ import annotations

import json
import math
import os
import sys

from vibid.cli.options import add_identification_options, profiled
from vibid.errors import VibidError


def add_parser(sub):
    """``vibid campaign``'s parser, its options in groups: the setup and the stand, the
    files, the identification, how the run goes, the session's attributes, what is done,
    and the adaptive campaign."""
    p = sub.add_parser(
        "campaign",
        help="run the stepped-sine campaign on the stand",
        description=__doc__.split("\n\n")[1],
    )
    _add_setup_and_stand(p)
    _add_files(p)
    add_identification_options(p, methods=False)
    _add_run_options(p)
    _add_session_attributes(p)
    _add_what_is_done(p)
    _add_adaptive_options(p)
    p.set_defaults(run=run)


def _add_setup_and_stand(p) -> None:
    """The declared setup, the stand and its configuration."""
    p.add_argument("setup", metavar="SETUP.json", help="the declared setup (with excitation)")
    p.add_argument(
        "--stand",
        required=True,
        choices=("simulated", "ni"),
        help="the real NI stand, or the simulated one behind the same drivers",
    )
    p.add_argument(
        "--stand-config",
        metavar="STAND.json",
        help="the stand configuration (default: every setting at its default)",
    )


def _add_files(p) -> None:
    """The session file and the report folder."""
    p.add_argument(
        "--out",
        metavar="S.h5",
        help="the session file to write (default: runs/<setup name>-<UTC time>.h5)",
    )
    p.add_argument(
        "--report",
        metavar="DIR",
        help="the report folder: report.md, report.json, PNG figures "
        "(default: <session name>-report beside the session file)",
    )


def _add_run_options(p) -> None:
    """How the run goes: a resume, wall-clock time on the simulated stand."""
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted session --out from its first missing step",
    )
    p.add_argument(
        "--realtime",
        action="store_true",
        help="simulated stand: settle and record in wall-clock time",
    )


def _add_session_attributes(p) -> None:
    """What the session file says of the test: who, notes, temperature."""
    p.add_argument("--operator", metavar="NAME", help="who runs the test (session attribute)")
    p.add_argument("--notes", metavar="TEXT", help="free-text notes (session attribute)")
    p.add_argument(
        "--temperature-c",
        type=float,
        metavar="T",
        help="specimen or room temperature, °C, written on every step",
    )


def _add_what_is_done(p) -> None:
    """Less than the whole job: the plan only, or the recording only."""
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="print the plan (steps, settle and record times, the least duration) "
        "and exit without opening the stand or writing --out",
    )
    p.add_argument(
        "--record-only",
        action="store_true",
        help="record the session only: no Prefect flow, no identification or report",
    )


def _add_adaptive_options(p) -> None:
    """The adaptive campaign's option group."""
    a = p.add_argument_group(
        "adaptive campaign",
        "choose the steps as the test goes: a coarse "
        "sweep, a fit after each batch, the next steps where the fit learns "
        "most per second of stand time, until the targets or the cap",
    )
    a.add_argument(
        "--adaptive",
        action="store_true",
        help="run an adaptive campaign (the setup's excitation gives the band and "
        "the settle floor; its frequencies are not played)",
    )
    a.add_argument(
        "--target",
        nargs="+",
        metavar="NAME=STD[%]",
        help="standard uncertainties to reach, relative with %%, e.g. D=0.1%% nu=0.002",
    )
    a.add_argument(
        "--band",
        metavar="LOW:HIGH",
        help="frequency band, Hz (default: the setup's frequency span)",
    )
    a.add_argument(
        "--max-stand-time", type=float, metavar="S", help="stop at this stand time, s (default 600)"
    )
    a.add_argument("--batch", type=int, metavar="N", help="steps per batch (default 4)")


def adaptive_options(args, setup):
    """The adaptive campaign's options from the command line, or from the session file an
    adaptive campaign is resumed from (None for a campaign of the setup's steps). One-line
    errors for options that do not go together."""
    from vibid.identify.model.plate import plate_model
    from vibid.planner.adaptive import AdaptiveOptions
    from vibid.planner.prior import parse_targets

    given = [
        o
        for o, v in (
            ("--target", args.target),
            ("--band", args.band),
            ("--max-stand-time", args.max_stand_time),
            ("--batch", args.batch),
        )
        if v is not None
    ]
    recorded = None
    if args.resume and args.out and os.path.isfile(args.out):
        from vibid.session import read_session

        with read_session(args.out) as s:
            recorded = s.adaptive
    if not args.adaptive and recorded is None:
        if given:
            raise VibidError(f"{given[0]} goes with --adaptive")
        return None
    if args.record_only:
        raise VibidError(
            "--record-only with --adaptive: an adaptive campaign fits between "
            "batches to choose its steps; run it without --record-only"
        )
    if args.magnitude_only:
        raise VibidError(
            "--magnitude-only with --adaptive: the adaptive campaign plans on the "
            "complex AFC; run it without --magnitude-only"
        )
    names = plate_model(setup.identification.model).names
    if recorded is not None and not given:
        return AdaptiveOptions.from_attribute(recorded, names)  # --resume: the file's own
    if not args.target:
        raise VibidError("--adaptive needs --target, e.g. --target D=0.1%")
    from vibid.cli.plan import parse_band

    freqs = setup.excitation.frequencies_hz
    band = parse_band(args.band) or (float(min(freqs)), float(max(freqs)))
    options = AdaptiveOptions(
        parse_targets(args.target, names),
        band,
        600.0 if args.max_stand_time is None else args.max_stand_time,
        4 if args.batch is None else args.batch,
        seed=args.seed,
    )
    options.check(setup)
    if recorded is not None and options.attribute() != recorded:
        raise VibidError(
            f"--out {args.out}: an adaptive campaign started with other options "
            f"({json.dumps(recorded, sort_keys=True)}); resume it without "
            f"{', '.join(given)}: --resume continues with the options it records"
        )
    return options


def default_out(setup_path: str, now=None) -> str:
    """``runs/<setup file stem>-<UTC time YYYYmmdd-HHMMSS>.h5``: a new file on every run."""
    import datetime

    now = now or datetime.datetime.now(datetime.UTC)
    stem = os.path.splitext(os.path.basename(setup_path))[0] or "session"
    return os.path.join("runs", f"{stem}-{now:%Y%m%d-%H%M%S}.h5")


def check_out_path(path: str, resume: bool) -> None:
    """Refuse an output path that cannot be used, before anything slow starts."""
    if resume:
        if not os.path.isfile(path):
            raise VibidError(f"--out {path}: no such session file to resume")
        if not os.access(path, os.W_OK) or not os.access(
            os.path.dirname(os.path.abspath(path)), os.W_OK
        ):
            raise VibidError(f"--out {path}: cannot be written")
        return
    if os.path.exists(path):
        raise VibidError(
            f"--out {path}: already exists; a session file is never overwritten "
            "(--resume continues an interrupted one)"
        )
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise VibidError(f"--out {path}: the directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise VibidError(f"--out {path}: the directory {parent} is not writable")


def run(args) -> int:
    from vibid.acquisition.stand_config import load_stand_config
    from vibid.pipeline import parse_candidates
    from vibid.session import load_setup

    setup = load_setup(args.setup)
    if setup.excitation is None:
        raise VibidError(f"{args.setup}: the setup has no excitation to play")
    config = load_stand_config(args.stand_config)
    if args.realtime and args.stand != "simulated":
        raise VibidError(
            "--realtime paces the simulated stand; the real stand always runs in real time"
        )
    if args.temperature_c is not None and not math.isfinite(args.temperature_c):
        raise VibidError("--temperature-c must be a finite number")
    candidates = parse_candidates(args.candidates)
    if args.restarts < 1:
        raise VibidError("--restarts must be at least 1")
    if args.resume and args.out is None:
        raise VibidError("--resume needs --out: the session file to continue")
    adaptive = adaptive_options(args, setup)
    if args.dry_run:
        if adaptive is not None:
            from vibid.planner.adaptive import AdaptiveCampaign

            print(
                "\n".join(
                    AdaptiveCampaign(setup, config, adaptive, loop=not args.no_loop).describe()
                )
            )
        else:
            print_plan(setup, config)
        return 0
    if args.out is None:
        args.out = default_out(args.setup)
        os.makedirs(os.path.dirname(args.out), exist_ok=True)
    check_out_path(args.out, args.resume)
    if args.resume:  # the file, its setup and options resumable: before the stand opens
        from vibid.acquisition.campaign import resume_point

        resume_point(args.out, setup, None if adaptive is None else adaptive.attribute())
    if args.record_only:
        return record_only(args, setup, config)
    from vibid.cli.paths import check_output_dir
    from vibid.flows.campaign import default_report_dir

    report_dir = args.report or default_report_dir(args.out)
    check_output_dir(report_dir)
    return run_flow(
        args,
        report_dir,
        None if candidates is None else list(candidates),
        None if adaptive is None else adaptive.attribute(),
    )


def run_flow(args, report_dir: str, candidates, adaptive: dict | None = None) -> int:
    """The campaign as the Prefect flow: acquisition (``adaptive``: the adaptive campaign's
    options, as the session's attribute), AFC, identification, report; then the report's
    path and its summary on stdout."""
    from vibid.identify import configure

    configure()
    from vibid.flows import campaign_flow
    from vibid.flows.server import tie_temporary_server
    from vibid.report import console_summary

    tie_temporary_server()  # a campaign killed outright leaves no Prefect server behind

    with profiled(args.profile):
        state = campaign_flow(
            args.setup,
            stand=args.stand,
            stand_config=args.stand_config,
            out=args.out,
            report_dir=report_dir,
            resume=args.resume,
            realtime=args.realtime,
            loop=not args.no_loop,
            candidates=candidates,
            operator=args.operator,
            notes=args.notes,
            temperature_c=args.temperature_c,
            restarts=args.restarts,
            seed=args.seed,
            magnitude_only=args.magnitude_only,
            adaptive=adaptive,
            return_state=True,
        )
    if not state.is_completed():
        error = state.result(raise_on_failure=False)
        report_md = os.path.join(report_dir, "report.md")
        if isinstance(error, VibidError):
            # refused or failed in one line that says what to do (a resume refused is not
            # to be resumed again): the report, if one was written, first
            if os.path.exists(report_md):
                print(f"report: {report_md}")
            raise error
        message = str(error) if isinstance(error, BaseException) else (state.message or state.name)
        print(f"vibid campaign: {' '.join(message.split())}", file=sys.stderr)
        if os.path.exists(report_md):
            print(f"report: {report_md}")
        elif os.path.exists(args.out):  # the campaign did not complete
            print(resume_hint(args, args.out), file=sys.stderr)
        return 1
    report = state.result()
    print(f"session: {args.out}")
    print(f"report: {os.path.join(report_dir, 'report.md')}")
    print(console_summary(report))
    return 0


def record_only(args, setup, config) -> int:
    """The campaign without Prefect and without the report: the session file only."""
    from vibid.acquisition.campaign import run_campaign
    from vibid.acquisition.stand import open_stand

    if args.stand == "simulated":
        from vibid.identify import configure

        configure()  # the virtual specimen is the plate model
    printer = ProgressPrinter(sys.stderr)
    with open_stand(args.stand, setup, config, realtime=args.realtime) as stand:
        result = run_campaign(
            setup,
            stand,
            args.out,
            config,
            resume=args.resume,
            progress=printer,
            operator=args.operator,
            notes=args.notes,
            temperature_c=args.temperature_c,
        )
    printer.close()
    n = len(setup.excitation.frequencies_hz)
    line = f"{result.path}: {result.run_status}, {result.n_steps} of {n} steps"
    if result.reason:
        line += f" ({result.reason})"
    if result.stand_time_s is not None:
        line += f"; stand time {result.stand_time_s:.1f} s (the specimen driven: settle and record)"
    print(line)
    if result.run_status == "interrupted":
        print(resume_hint(args, result.path), file=sys.stderr)
    return 0 if result.run_status == "complete" else 1


def resume_hint(args, path) -> str:
    """The command that continues the session at ``path``."""
    return (
        f"continue with: vibid campaign {args.setup} --stand {args.stand}"
        f"{' --stand-config ' + args.stand_config if args.stand_config else ''} "
        f"--out {path} --resume{' --record-only' if args.record_only else ''}"
    )


def print_plan(setup, config) -> None:
    """The dry run: one line per step, then the totals (every record assumed settled)."""
    from vibid.acquisition.plan import plan_summary

    summary = plan_summary(setup, config)
    for c in summary.commands:
        print(
            f"step {c.index + 1}/{c.n_steps}  {c.frequency_hz:g} Hz  settle {c.settle_s:g} s  "
            f"record {c.n_samples} samples ({c.record_s:.4g} s)"
        )
    print(
        f"{len(summary.commands)} steps: settle {summary.settle_s:.1f} s + record "
        f"{summary.record_s:.1f} s = at least {_duration(summary.duration_s)} (longer where a "
        "record is unsettled or the drive moves)"
    )


class ProgressPrinter:
    """One progress line per step: rewritten in place on a terminal, appended otherwise."""

    def __init__(self, stream):
        self.stream = stream
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self._width = 0

    def __call__(self, p) -> None:
        text = progress_line(p)
        if self.tty:
            pad = max(0, self._width - len(text))
            self.stream.write("\r" + text + " " * pad)
            self._width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty and self._width:
            self.stream.write("\n")
            self.stream.flush()


def progress_line(p) -> str:
    """``step 12/200  97.5 Hz  |H| 3.412  phase -12.3 deg  left 2 min 10 s`` (+ status, note);
    nothing about the time left while it cannot be estimated (``eta_s`` nan)."""
    text = (
        f"step {p.index + 1}/{p.n_steps}  {p.frequency_hz:g} Hz  |H| {p.h_abs:.4g}  "
        f"phase {p.phase_deg:+.1f} deg"
    )
    if math.isfinite(p.eta_s):
        text += f"  left {_duration(p.eta_s)}"
    if p.status != "ok":
        text += f"  [{p.status}]"
    if p.note:
        text += f"  ({p.note})"
    return text


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    minutes, s = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes} min {s:02d} s"
    hours, m = divmod(minutes, 60)
    return f"{hours} h {m:02d} min"
