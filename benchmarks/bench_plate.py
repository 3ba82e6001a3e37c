"""Plate forward model benchmarks (issue #3): accuracy of the discretisation, full-model
AFC time, reduced-model loss / Jacobian / exact Hessian times and error.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_plate.py

The paper's strip (100 x 20 x 1 mm steel, D = 17.97 N m, nu 0.286, beta 0.003, 1 g sensor
of radius 1 mm at (90, 15) mm), 200 frequencies from 7.5 to 1500 Hz. Single-threaded BLAS:
with several processes sharing the cores, OpenBLAS threads make small dense eigensolvers
(n > 64) up to 100x slower.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import time  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from vibid.identify import build_forward_model  # noqa: E402
from vibid.identify.engine.runtime import configure  # noqa: E402
from vibid.identify.model.assembly import Geometry, assemble_plate  # noqa: E402
from vibid.identify.model.mesh import (  # noqa: E402
    ACCURACY,
    Discretisation,  # noqa: E402
    discretisation,
)
from vibid.identify.model.modal import complex_eigenvalues, frequencies_and_decays  # noqa: E402
from vibid.setup_model import example_setup  # noqa: E402

configure()

THETA = np.array([17.97, 0.286, 0.003])


def timeit(fn, *args, repeat=50):
    jax.block_until_ready(fn(*args))
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeat):
            jax.block_until_ready(fn(*args))
        best = min(best, (time.perf_counter() - t0) / repeat)
    return best


def frequencies(mats, n=6):
    lam = complex_eigenvalues(
        mats,
        (THETA[0], THETA[1] * THETA[0], 0, THETA[0], 0, (1 - THETA[1]) * THETA[0] / 2),
        (THETA[2],) * 6,
        n,
    )
    return frequencies_and_decays(lam)[0]


def main():
    setup = example_setup()
    geom = Geometry.from_setup(setup)
    freqs = np.linspace(7.5, 1500.0, 200)

    print("== discretisation: first six natural frequencies vs argyris 80x16 +8 corner levels")
    ref_mats = assemble_plate(geom, Discretisation("argyris", 80, 16, 8))
    ref = frequencies(ref_mats)
    print(f"reference ({ref_mats.n_dof} dof): {np.round(ref, 4)}")
    for acc in ACCURACY:
        d = discretisation(geom, acc)
        t0 = time.perf_counter()
        mats = assemble_plate(geom, d)
        ta = time.perf_counter() - t0
        err = np.abs(frequencies(mats) / ref - 1).max()
        print(
            f"{acc:8s} {d.label:40s} {mats.n_dof:6d} dof  max rel error {err:.1e}  assembly {ta:.2f} s"
        )
    for d in (Discretisation("argyris-global", 40, 8), Discretisation("morley", 120, 24)):
        mats = assemble_plate(geom, d)
        print(
            f"{'(ref)':8s} {d.label:40s} {mats.n_dof:6d} dof  max rel error "
            f"{np.abs(frequencies(mats) / ref - 1).max():.1e}"
        )

    print("\n== full model (default discretisation), 200 frequencies")
    model = build_forward_model(setup, freqs, theta0=dict(zip(("D", "nu", "beta"), THETA)))
    t0 = time.perf_counter()
    Hf = model.afc_full(THETA)
    print(
        f"full AFC: {time.perf_counter() - t0:.2f} s ({model.mats.n_dof} dof, sparse LU per frequency)"
    )

    data = jnp.asarray(Hf * (1 + 1e-3))
    for kind in ("local", "wide"):
        t0 = time.perf_counter()
        m = model if kind == "local" else build_forward_model(setup, freqs)
        tb = time.perf_counter() - t0
        H = np.asarray(m.afc(THETA))
        err = np.abs(H - Hf).max() / np.abs(Hf).max()

        def loss(t, m=m):
            return jnp.sum(jnp.abs(m.afc(t) - data) ** 2)

        fl = jax.jit(loss)
        fj = jax.jit(jax.jacfwd(lambda t, m=m: m.afc(t)))
        fh = jax.jit(jax.hessian(loss))
        fboth = jax.jit(lambda t: (loss(t), jax.hessian(loss)(t)))
        th = jnp.asarray(THETA)
        print(
            f"\n== reduced model, {kind} basis: size {m.basis.size} ({m.basis.n_modes} modes), "
            f"built in {tb:.2f} s"
        )
        print(f"max |H_red - H_full| / max |H_full| = {err:.1e}")
        print(
            f"loss {timeit(fl, th) * 1e3:.2f} ms, Jacobian {timeit(fj, th) * 1e3:.2f} ms, "
            f"exact Hessian {timeit(fh, th) * 1e3:.2f} ms, loss + Hessian (one jit) "
            f"{timeit(fboth, th) * 1e3:.2f} ms"
        )
        pop = jnp.asarray(THETA * (1 + 0.1 * np.random.default_rng(0).standard_normal((64, 3))))
        print(f"afc_batch of 64: {timeit(m.afc_batch, pop, repeat=5) * 1e3:.1f} ms")

    t0 = time.perf_counter()
    me = model.model_error(THETA)
    print(
        f"\nmodel_error: {time.perf_counter() - t0:.2f} s (first call builds the finer level); "
        f"max {me.max() / np.abs(Hf).max():.1e} of max |H|"
    )


if __name__ == "__main__":
    main()
