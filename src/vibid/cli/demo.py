"""`vibid demo`: the end-to-end job on the simulated stand, until the live campaign lands.

Simulate a session of the paper's steel strip (virtual specimen = full FE model), check the
file, fit the AFC, identify the declared isotropic model, and write the report (JSON, text
summary and a PNG of the fit) into ``--out``.
"""

from __future__ import annotations

import os


def add_parser(sub) -> None:
    p = sub.add_parser("demo", help="simulate a session of the paper's strip, then fit and identify it",
                       description=__doc__)
    p.add_argument("--out", default="vibid-demo", help="output folder (default: vibid-demo)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated noise and the search")
    p.add_argument("--restarts", type=int, default=3, help="global-search restarts (default 3)")
    p.set_defaults(run=run)


def run(args) -> int:
    from vibid.cli.paths import check_output_dir, check_output_file
    from vibid.cli.progress import search_progress
    from vibid.hardware_mocks.simulated_session import simulate_session
    from vibid.identify import configure
    from vibid.identify.fit import identify
    from vibid.plots import plot_afc_fit
    from vibid.report import build_report, write_report
    from vibid.session import file_problems, read_session
    from vibid.setup_model import example_setup
    from vibid.signal import afc_from_session

    check_output_dir(args.out)  # before the simulation and the search
    for name in ("report.json", "report.txt", "afc_fit.png"):
        check_output_file(os.path.join(args.out, name), overwrite=True)
    configure()
    truth = {"D": 17.97, "nu": 0.286, "beta": 0.003}
    session_path = os.path.join(args.out, f"session-seed{args.seed}.h5")
    if os.path.exists(session_path):
        os.remove(session_path)  # the demo's own file, made again on every run
    print(f"1/4 simulating the paper's strip (D={truth['D']}, nu={truth['nu']}, beta={truth['beta']}) ...")
    simulate_session(session_path, example_setup(), truth, seed=args.seed)
    problems = file_problems(session_path)
    print(f"2/4 {session_path}: {'valid' if not problems else problems[0]}")
    with read_session(session_path) as s:
        setup, session_id = s.setup, s.session_id
        afc = afc_from_session(s)
    print(f"3/4 AFC: {int(afc.used.sum())} of {len(afc.used)} steps used")
    print("4/4 identifying (global search, then trust-region Newton) ...")
    with search_progress() as progress:
        result = identify(setup, afc.frequency_hz, afc.H, afc.std, used=afc.used,
                          restarts=args.restarts, seed=args.seed, progress=progress)
    report = build_report(result, session_id=session_id, declared_model=setup.identification.model,
                          afc=afc.to_report_block())
    json_path = os.path.join(args.out, "report.json")
    write_report(report, json_path)
    png = plot_afc_fit(os.path.join(args.out, "afc_fit.png"), afc.frequency_hz[afc.used],
                       afc.H[afc.used], afc.std[afc.used], result.model_afc[afc.used],
                       title="paper's strip, simulated stand: measured vs identified model")
    lines = [result.summary(), "", f"{'param':>6} {'true':>10} {'identified':>12} {'std':>9} {'error/std':>9}"]
    for name, value, std in zip(result.parameter_names, result.values, result.std):
        lines.append(f"{name:>6} {truth[name]:>10.6g} {value:>12.7g} {std:>9.2g} "
                     f"{(value - truth[name]) / std:>9.2f}")
    text = "\n".join(lines)
    with open(os.path.join(args.out, "report.txt"), "w") as fh:
        fh.write(text + "\n")
    print(text)
    print(f"report: {json_path}, {os.path.join(args.out, 'report.txt')}, {png}")
    return 0 if result.converged else 1
