"""The stand's overhead: how much longer a campaign takes than its settles and records.

    python benchmarks/stand.py [--realtime-steps 40] [--unpaced-steps 200] [--json OUT.json]

1. **Real-time overhead.** A ``--realtime`` campaign on the simulated stand (the real SCPI and
   NI-DAQmx drivers in front of the mocks, paced on the wall clock) of the example steel
   strip, ``--realtime-steps`` frequencies from 200 to 1500 Hz, the stand configuration's
   defaults (0.5 s settle, 0.25 s records of whole cycles). The virtual specimen's H is
   solved at every played frequency before the clock starts (a real stand has no
   finite-element model to solve; unpaced, below, it is part of the time). The wall time of
   ``run_campaign`` is set against the sum of the settle and record times of its steps (from
   the file: each step's time from its frequency change to the start of its last record,
   ``vibid_settle_s``, control moves and re-records after a longer settle included, plus that
   record). Overhead = wall / (settle + record) - 1; the target is at most 5 %.
   What it holds: the generator's SCPI round trips, the harmonic fit of each step, the
   session file's atomic commit (copy, fsync, rename; it grows with the file), the
   synthesis of the records by the mock when it takes longer than the record itself.
   ``runner_s`` is the wall time outside the clock's sleeps and the acquisitions (the file is
   written during the next step's settle, which then sleeps that much less).
2. **Unpaced 200 steps.** The example setup's 200 steps (7.5 to 1500 Hz) on the simulated
   stand in virtual time: the wall time of the campaign, split into the mock's acquisitions
   (the virtual specimen solves its finite-element model at each new frequency) and the
   runner's own work, and the time of opening the stand apart.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np


class CountingClock:
    """The stand's clock, summing the settle time the campaign asks for."""

    def __init__(self, clock):
        self.clock = clock
        self.slept_s = 0.0

    def now_s(self):
        return self.clock.now_s()

    def sleep(self, seconds):
        self.slept_s += max(0.0, seconds)
        self.clock.sleep(seconds)


class CountingDaq:
    """The stand's DAQ, summing the duration of the records it takes."""

    def __init__(self, daq):
        self.daq = daq
        self.sample_rate_hz = daq.sample_rate_hz
        self.recorded_s = 0.0
        self.records = 0
        self.wall_s = 0.0  # wall time inside acquire: the mock's synthesis when unpaced

    def acquire(self, n_samples):
        self.recorded_s += n_samples / self.sample_rate_hz
        self.records += 1
        t = time.perf_counter()
        try:
            return self.daq.acquire(n_samples)
        finally:
            self.wall_s += time.perf_counter() - t

    def close(self):
        self.daq.close()


def warm_specimen(name: str, setup) -> float:
    """Solve the virtual specimen's H at every frequency the generator will play (and at its
    modes, for the transients) before the clock starts; returns the seconds it took."""
    from vibid.hardware_mocks.virtual_stand import lookup_stand

    virtual = lookup_stand(name)
    t = time.perf_counter()
    # the driver sends 12 significant digits; the instrument plays them on its own clock
    played = [
        virtual.instrument.played_at(float(format(f, ".12g")))
        for f in setup.excitation.frequencies_hz
    ]
    virtual.specimen.h(played)
    virtual.specimen.h(virtual.specimen.modes[0])
    return time.perf_counter() - t


def run(setup, config, *, realtime: bool, name: str, warm: bool = False) -> dict:
    from vibid.acquisition.campaign import run_campaign
    from vibid.acquisition.protocols import Stand
    from vibid.acquisition.stand import open_stand
    from vibid.session import read_session

    config = replace(config, generator=replace(config.generator, url=f"vibidsim://{name}"))
    t = time.perf_counter()
    stand = open_stand("simulated", setup, config, realtime=realtime)
    open_s = time.perf_counter() - t
    warm_s = warm_specimen(name, setup) if warm else 0.0
    clock, daq = CountingClock(stand.clock), CountingDaq(stand.daq)
    counted = Stand(stand.generator, daq, clock, stand.description)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "s.h5")
        with counted:
            t = time.perf_counter()
            result = run_campaign(setup, counted, path, config)
            wall_s = time.perf_counter() - t
        size = os.path.getsize(path)
        # what the stand had to spend: per step, the time from its frequency change to the
        # start of its (last) record, control moves and re-records included, plus that record
        with read_session(path) as s:
            busy_s = sum(
                float(s.step_attributes(i)["vibid_settle_s"])
                + s.step(i).n_samples / s.step(i).sample_rate_hz
                for i in range(len(s))
            )
    return {
        "steps": result.n_steps,
        "run_status": result.run_status,
        "open_stand_s": open_s,
        "campaign_wall_s": wall_s,
        "settle_s": clock.slept_s,
        "record_s": daq.recorded_s,
        "records": daq.records,
        "settle_and_record_s": busy_s,
        "overhead": wall_s / busy_s - 1.0 if realtime else None,
        "acquire_wall_s": daq.wall_s,
        "runner_s": wall_s - daq.wall_s - (clock.slept_s if realtime else 0.0),
        "file_bytes": size,
        "warm_specimen_s": warm_s,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--realtime-steps", type=int, default=40, help="steps of the real-time run (0: skip)"
    )
    ap.add_argument(
        "--unpaced-steps", type=int, default=200, help="steps of the unpaced run (0: skip)"
    )
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args(argv)
    from vibid.acquisition.stand_config import StandConfig
    from vibid.identify import configure
    from vibid.setup_model import Excitation, example_setup

    configure()
    base = example_setup()
    config = StandConfig()
    out = {}
    if args.realtime_steps:
        freqs = tuple(float(f) for f in np.linspace(200.0, 1500.0, args.realtime_steps))
        setup = replace(base, excitation=Excitation(freqs, base.excitation.settle_s))
        r = out["realtime"] = run(setup, config, realtime=True, name="bench-realtime", warm=True)
        print(
            f"real time, {r['steps']} steps ({r['records']} records): wall {r['campaign_wall_s']:.2f} s, "
            f"settle and record {r['settle_and_record_s']:.2f} s; overhead {100 * r['overhead']:.2f} % "
            f"(in acquisitions beyond their record time {r['acquire_wall_s'] - r['record_s']:.2f} s)"
        )
    if args.unpaced_steps:
        freqs = tuple(float(f) for f in np.linspace(7.5, 1500.0, args.unpaced_steps))
        setup = replace(base, excitation=Excitation(freqs, base.excitation.settle_s))
        r = out["unpaced"] = run(setup, config, realtime=False, name="bench-unpaced")
        print(
            f"unpaced, {r['steps']} steps ({r['records']} records): campaign {r['campaign_wall_s']:.2f} s "
            f"({1000 * r['campaign_wall_s'] / r['steps']:.1f} ms a step; {r['settle_s'] + r['record_s']:.0f} s "
            f"of virtual settle and record): in the mock's acquisitions {r['acquire_wall_s']:.2f} s, "
            f"the runner's own (fit, file, SCPI) {r['runner_s']:.2f} s; opening the stand "
            f"{r['open_stand_s']:.2f} s; file {r['file_bytes'] / 1e6:.1f} MB"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)
            fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
