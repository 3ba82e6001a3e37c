"""Magnitude-only identification against the complex fit of the same data, side by side.

    python benchmarks/magnitude.py

Two data sets, each identified twice in one run (complex, then ``magnitude=True``) with the
same options: the paper's strip on 60 steps from the full FE model on a finer mesh with an
undeclared 20 µs channel delay and 0.3 % noise (``tests/loop_data.py``: declared global
fit, one restart), and the real titanium strip's 11 960 FFT bins (a local polish from the
declared fit's start, compressed bands). Prints the time of each and their ratio, χ²/dof,
and each parameter's magnitude_only_std_ratio.
"""

import os
import sys
import time

from vibid.identify.engine.runtime import configure

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))


def _pair(label, run):
    out = {}
    for mag in (False, True):
        run(mag)  # compile and warm the caches
        t = time.perf_counter()
        out[mag] = (run(mag), time.perf_counter() - t)
    (c, tc), (m, tm) = out[False], out[True]
    print(
        f"{label}: complex {tc:.2f} s, |H| alone {tm:.2f} s (ratio {tm / tc:.2f}); "
        f"chi2/dof {c.chi2_reduced_reported:.4g} -> {m.chi2_reduced_reported:.4g}"
    )
    for n in m.parameter_names:
        i = m.parameter_names.index(n)
        print(
            f"  {n:>5}: complex {c.values[i]:.6g} ± {c.std[i]:.2g}, |H| {m.values[i]:.6g} ± "
            f"{m.std[i]:.2g}, std ratio {m.magnitude_only_std_ratio[n]:.3g}"
        )


def main() -> int:
    configure()
    from loop_data import F, data, strip_on
    from test_identify_compress import titanium_problem
    from vibid.identify.fit import Measurement, SearchOptions, identify

    H, sd = data({"tau_s": 2e-5}, 7)
    _pair(
        "strip, 60 steps, undeclared delay (global search)",
        lambda mag: identify(
            strip_on(),
            Measurement(F, H, sd, magnitude=mag),
            search=SearchOptions(restarts=1, seed=0),
        ),
    )
    problem, u0 = titanium_problem()
    d = problem.data
    start = dict(zip(problem.space.names, problem.space.theta(u0)))
    from vibid.cli.modes import load_setup

    setup = load_setup(os.path.join(HERE, "..", "tests", "data", "titanium_setup.json"))
    _pair(
        f"titanium, {d.n_used} bins (local polish)",
        lambda mag: identify(
            setup,
            Measurement(d.frequency_hz, d.H, d.std, magnitude=mag),
            search=SearchOptions(method="local", start=start),
        ),
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
