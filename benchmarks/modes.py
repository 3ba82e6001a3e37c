"""The reduced basis's eigensolve: how many modes to ask ARPACK for first.

    python benchmarks/modes.py [--repeat 10] [--busy]

:func:`vibid.identify.model.reduced._modes` asks for :data:`~vibid.identify.model.reduced.
FIRST_MODES` (8) modes first and, where they stop short of the cut-off, for as many as a
plate's mode count (in proportion to the frequency) says it needs. Before, it asked for 16
and doubled. Both are timed here side by side, in one run, on the matrices of two setups:
the real titanium strip's calibrated setup (2922 unknowns) up to the cut-offs of a loop's
local basis and of the declared fit's wide one (of the calibrated run's 218 bases, 217 kept
6 or 7 modes, one 9), and a 150 x 100 x 2 mm steel plate (46 modes to 9 kHz). Prints each policy's solves, its time per call and
the largest relative difference of the kept frequencies. ``--busy`` runs
one CPU-bound process beside it (a lab PC's other work).
"""

import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "tests"))


def doubling_from_16(K, M, lu, n_min, n_max, f_top):
    """The policy before: 16 modes first, then twice as many until the cut-off."""
    import scipy.sparse.linalg as spla

    from vibid.identify.model.modal import arpack_start

    opinv = spla.LinearOperator(K.shape, matvec=lu.solve, dtype=float)
    k = min(max(n_min, 16), n_max, K.shape[0] - 2)
    while True:
        lam, Phi = spla.eigsh(
            K, k=k, M=M, sigma=0.0, OPinv=opinv, which="LM", v0=arpack_start(K.shape[0])
        )
        order = np.argsort(lam)
        freqs = np.sqrt(np.abs(lam[order])) / (2 * np.pi)
        if freqs[-1] >= f_top or k >= n_max or k >= K.shape[0] - 2:
            break
        k = min(2 * k, n_max, K.shape[0] - 2)
    n_keep = min(k, int(max(n_min, np.searchsorted(freqs, f_top, side="right") + 1)))
    return Phi[:, order][:, :n_keep], freqs[:n_keep]


def pencil(setup, frequencies_hz, theta0=None):
    from vibid.identify.model import reduced
    from vibid.identify.model.plate import build_forward_model

    model = build_forward_model(setup, frequencies_hz, theta0=theta0)
    s, m = reduced._coefficients(model.param, model.theta0)
    K = model.mats.stiffness_matrix(dict(zip(model.mats.stiffness, s))).tocsc()
    M = model.mats.inertia_matrix(dict(zip(model.mats.inertia, m))).tocsc()
    return K, M


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--busy", action="store_true", help="one CPU-bound process beside it")
    args = ap.parse_args(argv)

    from vibid.identify.engine.runtime import configure

    configure()
    import scipy.sparse.linalg as spla

    from paper_table import busy_cpu
    from plate_helpers import plate_setup
    from vibid.identify.model import reduced
    from vibid.pipeline import read_setup

    titanium = read_setup(os.path.join(HERE, "..", "examples", "real-steel", "titanium_setup.json"))
    strip = pencil(titanium, np.linspace(150, 1500, 50))
    cases = [
        ("titanium strip, to a loop's local-basis cut-off", *strip, 7415.0),
        ("titanium strip, to the declared fit's wide-basis cut-off", *strip, 9209.0),
        (
            "150 x 100 x 2 mm steel plate",
            *pencil(
                plate_setup(0.15, 0.10, 0.002),
                np.linspace(50, 3200, 20),
                {"D": 50.0, "nu": 0.3, "beta": 0.01},
            ),
            9000.0,
        ),
    ]
    real_eigsh = spla.eigsh
    with busy_cpu(args.busy):
        for name, K, M, f_top in cases:
            lu = reduced.spd_lu(K)
            print(f"{name}: {K.shape[0]} unknowns, modes to {f_top:.0f} Hz")
            results = {}
            for label, run in (
                ("16, doubling (before)", doubling_from_16),
                ("8, then by the count (now)", None),
            ):
                solves = []

                def counting(*a, **kw):
                    solves.append(kw["k"])
                    return real_eigsh(*a, **kw)

                reduced.spla.eigsh = counting
                try:
                    t0 = time.perf_counter()
                    for _ in range(args.repeat):
                        solves.clear()
                        if run is None:
                            Phi, f = reduced._modes(K, M, lu, 6, 96, f_top)
                        else:
                            Phi, f = run(K, M, lu, 6, 96, f_top)
                    dt = (time.perf_counter() - t0) / args.repeat
                finally:
                    reduced.spla.eigsh = real_eigsh
                results[label] = f
                print(
                    f"  {label:28s} solves {solves}  {1e3 * dt:7.1f} ms a call, {f.size} modes kept"
                )
            a, b = results.values()
            print(
                f"  kept frequencies: {'the same count' if a.size == b.size else 'DIFFER'}, "
                f"largest relative difference {np.max(np.abs(a / b - 1)):.1e}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
