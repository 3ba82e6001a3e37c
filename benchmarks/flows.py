"""Flows: one replay, and a batch of 8 replays on threads against a 2-worker local Dask cluster.

    python benchmarks/flows.py [--sessions 8] [--out DIR] [--json benchmarks/flows.json]

Simulates ``--sessions`` short sessions of the paper's strip (21 steps to 900 Hz, 0.05 s
records, seeds 1..N), then times, each in this process on Prefect's embedded temporary
server (its start-up is timed apart):

1. ``replay_flow`` of one session (the declared model, no loop, 2 restarts) with its report
   folder (report.md and figures);
2. ``batch_replay_flow`` over all sessions on threads (``ThreadPoolTaskRunner``);
3. the same on a ``distributed.LocalCluster`` of 2 worker processes, 1 thread each (its
   start-up, and each worker's JAX compilation, included).

Every batch writes the report folders; the parameters of the two batches are compared
(they must agree to 1e-12 relative). Prints one JSON line per measurement.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile
import time

OPTIONS = {"loop": False, "restarts": 2}


def make_sessions(folder: str, n: int) -> list[str]:
    from vibid.hardware_mocks.simulated_session import StandConditions, simulate_session
    from vibid.setup_model import example_setup

    s = example_setup()
    freqs = (30.0,) + tuple(45.0 * k for k in range(1, 21))
    s = dataclasses.replace(s, excitation=dataclasses.replace(s.excitation, frequencies_hz=freqs))
    truth = {"D": 17.97, "nu": 0.286, "beta": 0.003}
    return [
        simulate_session(
            os.path.join(folder, f"session-{k}.h5"),
            s,
            truth,
            seed=k,
            conditions=StandConditions(record_s=0.05),
            accuracy="default",
        )
        for k in range(1, n + 1)
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sessions", type=int, default=8)
    ap.add_argument("--out", help="folder for sessions and reports (default: a temporary one)")
    ap.add_argument("--json", help="append the rows to this JSON file")
    args = ap.parse_args()

    from vibid.identify import configure

    configure()
    folder = args.out or tempfile.mkdtemp(prefix="vibid-bench-flows-")
    os.makedirs(folder, exist_ok=True)
    rows = []

    def row(what, seconds, **extra):
        r = {"what": what, "seconds": round(seconds, 1), **extra}
        rows.append(r)
        print(json.dumps(r), flush=True)

    t = time.perf_counter()
    paths = make_sessions(folder, args.sessions)
    row("simulate sessions", time.perf_counter() - t, n=len(paths))

    from prefect.server.api.server import SubprocessASGIServer
    from prefect.settings import PREFECT_API_URL, temporary_settings

    t = time.perf_counter()
    server = SubprocessASGIServer()
    server.start()
    row("Prefect embedded server start-up", time.perf_counter() - t)
    try:
        with temporary_settings({PREFECT_API_URL: server.api_url}):
            from distributed import LocalCluster

            from vibid.flows import batch_replay_flow, replay_flow

            t = time.perf_counter()
            replay_flow(paths[0], report_dir=os.path.join(folder, "replay"), **OPTIONS)
            row("replay_flow, one session", time.perf_counter() - t, **OPTIONS)

            t = time.perf_counter()
            threads = batch_replay_flow(
                paths, report_dir=os.path.join(folder, "threads"), task_runner="threads", **OPTIONS
            )
            row(
                "batch_replay_flow, threads",
                time.perf_counter() - t,
                n=len(paths),
                errors=sum(bool(e) for e in threads.errors),
            )

            t = time.perf_counter()
            with LocalCluster(
                n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
            ) as cluster:
                dask = batch_replay_flow(
                    paths, report_dir=os.path.join(folder, "dask"), task_runner=cluster, **OPTIONS
                )
            row(
                "batch_replay_flow, LocalCluster 2 worker processes",
                time.perf_counter() - t,
                n=len(paths),
                errors=sum(bool(e) for e in dask.errors),
            )
    finally:
        server.stop()

    worst = 0.0
    for a, b in zip(threads.reports, dask.reports):
        for name, p in a["parameters"].items():
            worst = max(worst, abs(p["value"] - b["parameters"][name]["value"]) / abs(p["value"]))
    row("threads vs dask: largest relative parameter difference", 0.0, value=worst)
    if args.json:
        with open(args.json, "a") as fh:
            for r in rows:
                fh.write(json.dumps(r) + "\n")


if __name__ == "__main__":
    main()
