"""Where does the real titanium strip's non-physical nu come from? Local fits with and
without the sensor's offset across the width (``sensor_position``).

    python benchmarks/titanium_sensor.py [--data ../shared/data/real-titanium]

Plain Levenberg-Marquardt (scipy) on the reduced JAX model, on every fifth point of the AFC
and every point of the two resonance regions (about 3100 points), from a physical start
(D 220 N m, nu 0.33, gain 0.9, alpha -0.9, offset -2 mm): isotropic plate with
``sensor_gain`` and ``frequency_dependent_loss``, then the same with nu held at 0.33, then
with ``sensor_position`` free as well. Prints chi2_red (the AFC's ``std`` as weights; the
points are correlated, see the data's README), the relative RMS residual and the values.
About a minute on 2 cores.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="../shared/data/real-titanium")
    args = ap.parse_args()
    from vibid.identify.engine.runtime import configure

    configure()
    import jax
    import jax.numpy as jnp
    from scipy.optimize import least_squares

    from titanium_subset import titanium_subset
    from vibid.identify.model.plate import build_forward_model, plate_model

    setup, f_all, f, H, s = titanium_subset(args.data)
    start = {
        "D": 220.0,
        "nu": 0.33,
        "beta": 0.004,
        "alpha": -0.9,
        "gain": 0.9,
        "sensor_dy_m": -2e-3,
    }
    logs = ("D", "beta", "gain")

    def fit(effects, fixed=()):
        model = plate_model("isotropic", effects=effects)
        names = model.names
        box = model.default_bounds(
            dict(setup.identification.bounds) | {"alpha": (-1.5, 1.0), "gain": (0.7, 1.3)}
        )
        fm = build_forward_model(
            setup, f, model=model, theta0={n: start[n] for n in names}, bounds=box
        )
        free = [n for n in names if n not in fixed]
        th0 = np.array([start[n] for n in names])

        def theta(x):
            t = jnp.asarray(th0)
            for k, n in enumerate(free):
                t = t.at[names.index(n)].set(jnp.exp(x[k]) if n in logs else x[k])
            return t

        def res(x):
            r = (fm.afc(theta(x)) - H) / s
            return jnp.concatenate([r.real, r.imag])

        R, J = jax.jit(res), jax.jit(jax.jacfwd(res))
        x0 = np.array([np.log(start[n]) if n in logs else start[n] for n in free])
        t0 = time.perf_counter()
        out = least_squares(
            lambda x: np.asarray(R(x)),
            x0,
            jac=lambda x: np.asarray(J(x)),
            method="lm",
            max_nfev=300,
        )
        th = np.asarray(theta(out.x))
        Hm = np.asarray(fm.afc(th))
        chi = np.sum(out.fun**2) / (out.fun.size - len(free))
        rel = np.sqrt(np.sum(abs(Hm - H) ** 2) / np.sum(abs(H) ** 2))
        vals = ", ".join(f"{n} {v:.4g}" for n, v in zip(names, th))
        held = f" (held: {', '.join(fixed)})" if fixed else ""
        print(
            f"{' + '.join(effects)}{held}: chi2_red {chi:.4g}, rel. RMS {rel:.3f}; {vals} "
            f"[{time.perf_counter() - t0:.0f} s]",
            flush=True,
        )

    print(f"{f.size} points of {f_all.size}")
    fit(("sensor_gain", "frequency_dependent_loss"))
    fit(("sensor_gain", "frequency_dependent_loss"), fixed=("nu",))
    fit(("sensor_gain", "frequency_dependent_loss", "sensor_position"))


if __name__ == "__main__":
    main()
