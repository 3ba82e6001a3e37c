"""`vibid afc SESSION.h5 [--json AFC.json] [--uff AFC.uff]`: the measured AFC of a session,
step by step; ``--uff`` exchanges the AFC the identification uses as UFF58
(:mod:`vibid.signal.uff`)."""

from __future__ import annotations

import math


def add_parser(sub) -> None:
    p = sub.add_parser(
        "afc",
        help="fit every step of a session: complex AFC with uncertainty and quality flags",
        description="Fit both accelerometer records of every step (shared refined frequency, "
        "offset, drift, 2nd and 3rd harmonics) and print the AFC H = response/base: refined "
        "frequency, |H|, phase (deg, positive when the response leads), standard uncertainty "
        "per real and imaginary part, the worse channel's SNR per sample, and quality flags. "
        "Flagged steps are listed but left out of the identification.",
    )
    p.add_argument("session", metavar="SESSION.h5", help="session file")
    p.add_argument(
        "--json",
        metavar="AFC.json",
        help="also write the report's 'afc' block with per-step diagnostics",
    )
    p.add_argument(
        "--uff",
        metavar="AFC.uff",
        help="also write the AFC the identification uses (used steps only, refined "
        "frequencies) as UFF58: the AFC, then its std as a second record",
    )
    p.set_defaults(run=run)


def run(args) -> int:
    import json

    from vibid.cli.paths import check_output_file
    from vibid.errors import VibidError
    from vibid.session import read_session
    from vibid.signal import afc_from_session

    for out in (args.json, args.uff):
        if out:
            check_output_file(out, overwrite=True)  # before every step is fitted
    with read_session(args.session) as session:
        table = afc_from_session(session)
        session_id = session.session_id
    print(format_table(table))
    if args.json:
        doc = {"session_id": session_id, "afc": table.to_report_block()}
        try:
            with open(args.json, "w") as fh:
                json.dump(doc, fh, indent=1, allow_nan=False)
                fh.write("\n")
        except OSError as exc:
            raise VibidError(f"{args.json}: cannot write ({exc.strerror})") from None
    if args.uff:
        _write_uff(args.uff, table, session_id)
    return 0


def _write_uff(path, table, session_id: str) -> None:
    """The used steps, at their refined frequencies (Hz, DAQ clock), with H and the single
    std per point: the arrays the identification fits (:func:`vibid.pipeline.write_afc_uff`)."""
    from vibid.pipeline import SessionAfc, write_afc_uff

    n = write_afc_uff(SessionAfc(None, session_id, table), path)
    print(f"{n} used steps written to {path} (UFF58: the AFC, then its std)")


def format_table(table) -> str:
    """The AFC as a fixed-width text table, one line per step, then a summary line."""
    head = (
        f"{'step':>5} {'f_Hz':>12} {'|H|':>11} {'phase_deg':>10} {'std':>10} {'SNR_dB':>7}  flags"
    )
    lines = [head]
    for p in table.points:
        snr = min(p.snr_db)
        lines.append(
            f"{p.index:>5d} {_num(p.frequency_hz, '12.5f')} {_num(abs(p.h), '11.5g')} "
            f"{_num(math.degrees(math.atan2(p.h.imag, p.h.real)), '10.3f')} {_num(p.std, '10.3g')} "
            f"{_num(snr, '7.1f')}  {','.join(p.flag_names) or '-'}"
        )
    n_used = int(table.used.sum())
    lines.append(
        f"{n_used} of {len(table)} steps used"
        + (
            ""
            if n_used == len(table)
            else "; flagged steps are left out (reasons in the --json diagnostics)"
        )
    )
    return "\n".join(lines)


def _num(value: float, spec: str) -> str:
    width = int(spec.split(".")[0])
    return f"{value:{spec}}" if math.isfinite(value) else f"{'-':>{width}}"
