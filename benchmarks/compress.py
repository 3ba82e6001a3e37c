"""A long AFC's local fits on its compressed problem against every point, side by side.

    python benchmarks/compress.py

The real titanium strip (``tests/data/titanium_afc.csv.gz``, the 11 960 FFT bins of
``../shared/data/real-titanium``), its declared isotropic model from the declared fit's
start: the compressed problem's size and build time, then one trust-region Newton run and
the continuation in beta, each on every point and compressed (``identify/fit/compress.py``),
with the compressed estimate's distance from the full one in Fisher standard deviations.
"""

import os
import sys
import time

import numpy as np

from vibid.identify.engine.runtime import configure

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
from test_identify_compress import titanium_problem  # noqa: E402  (the test's problem)


def main() -> int:
    configure()
    import vibid.identify.fit.local as local
    from vibid.identify.fit.compress import compressed

    problem, u0 = titanium_problem()
    compressed(problem, u0)  # compile
    t = time.perf_counter()
    short = compressed(problem, u0)
    print(
        f"{problem.n_points} points -> {short.n_points} nodes (padded) in "
        f"{time.perf_counter() - t:.3f} s"
    )
    local._METHODS["newton"](problem, u0, 2), local.LOCAL_METHODS["newton"](problem, u0, 2)
    t = time.perf_counter()
    full = local._METHODS["newton"](problem, u0)
    t_full = time.perf_counter() - t
    t = time.perf_counter()
    small = local.LOCAL_METHODS["newton"](problem, u0)
    t_small = time.perf_counter() - t
    J = problem.jacobian_theta(full.theta)
    std = np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    print(
        f"Newton: every point {t_full:.2f} s, compressed {t_small:.2f} s; "
        f"shift / std {np.round((small.theta - full.theta) / std, 4)}"
    )
    t = time.perf_counter()
    c_small = local.polish_by_continuation(problem, u0)[0]
    t_small = time.perf_counter() - t
    plain = local.compressed
    local.compressed = lambda p, u: p  # every point
    try:
        t = time.perf_counter()
        c_full = local.polish_by_continuation(problem, u0)[0]
        t_full = time.perf_counter() - t
    finally:
        local.compressed = plain
    print(
        f"continuation: every point {t_full:.2f} s, compressed {t_small:.2f} s; "
        f"shift / std {np.round((c_small.theta - c_full.theta) / std, 4)}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
