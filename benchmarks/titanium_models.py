"""What the real titanium AFC determines: bounded local fits of physically distinct models.

    python benchmarks/titanium_models.py [--data ../shared/data/real-titanium]

The loop's answer on this strip (E 91 GPa, below titanium's 100-125 GPa) could be the
model's choice rather than the data's. Each row here is one model, fitted by bounded
least squares (scipy's trust-region reflective, exact Jacobian of the reduced JAX model)
on every fifth point of the AFC and every point of its two resonances (about 2900
points), from a titanium start (D 277 N m, nu 0.33), with the basis rebuilt at the end
point and polished again. Prints chi2_red (the AFC's ``std`` as weights), the relative RMS
residual, the residual's autocorrelation time tau along frequency (how many neighbouring
points carry one independent one: ``fit.noise.autocorrelation_time``), E and the values.
A few minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

#: Starts (titanium, a 664 Hz stand resonance) and bounds of every parameter.
START = {
    "D": 277.0,
    "nu": 0.33,
    "beta": 0.004,
    "alpha": -0.5,
    "gain": 0.9,
    "dL_m": 0.0,
    "k_theta_N_per_rad": 3e4,
    "beta_clamp": 0.05,
    "f_hz": 664.0,
    "q": 30.0,
    "theta_rad_per_m": 0.3,
    "mass_kg": 1e-4,
}
LIMITS = {
    "D": (50, 1000),
    "nu": (0.0, 0.49),
    "beta": (1e-4, 0.1),
    "alpha": (-1.5, 1.0),
    "gain": (0.7, 1.3),
    "dL_m": (-5e-3, 5e-3),
    "k_theta_N_per_rad": (1e3, 1e8),
    "beta_clamp": (1e-4, 0.5),
    "f_hz": (600, 720),
    "q": (5, 200),
    "theta_rad_per_m": (-5, 5),
    "mass_kg": (1e-6, 5e-3),
}
LOGS = ("D", "beta", "gain", "k_theta_N_per_rad", "beta_clamp", "f_hz", "q", "mass_kg")
#: (effects, parameters held at their start)
MODELS = [
    (("sensor_gain", "frequency_dependent_loss"), ()),
    (("sensor_gain", "frequency_dependent_loss"), ("nu",)),
    (("sensor_gain", "frequency_dependent_loss", "added_mass"), ()),
    (("sensor_gain", "frequency_dependent_loss", "added_mass", "stand_resonance"), ()),
    (("sensor_gain", "frequency_dependent_loss", "added_mass", "stand_resonance"), ("nu",)),
    (("sensor_gain", "frequency_dependent_loss", "free_length"), ("nu",)),
    (("sensor_gain", "clamp_compliance", "clamp_loss"), ("nu",)),
    (("sensor_gain", "clamp_compliance", "clamp_loss", "added_mass", "stand_resonance"), ()),
    (("sensor_gain", "clamp_compliance", "clamp_loss", "added_mass", "stand_resonance"), ("nu",)),
]


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
    from vibid.identify.fit.noise import autocorrelation_time
    from vibid.identify.model.plate import build_forward_model, plate_model

    setup, f_all, f, H, s = titanium_subset(args.data)
    h = setup.specimen.thickness_m

    def base(n):
        return n.removesuffix("_1")

    def to_x(n, v):
        return np.log(v) if base(n) in LOGS else v

    def fit(effects, held):
        model = plate_model("isotropic", effects=effects)
        names = model.names
        start = {n: START[base(n)] for n in names}
        box = model.default_bounds(
            dict(setup.identification.bounds) | {"alpha": (-1.5, 1.0), "gain": (0.7, 1.3)}
        )
        fm = build_forward_model(setup, f, model=model, theta0=start, bounds=box)
        free = [n for n in names if n not in held]
        th0 = np.array([start[n] for n in names])

        def theta(x):
            t = jnp.asarray(th0)
            for k, n in enumerate(free):
                t = t.at[names.index(n)].set(jnp.exp(x[k]) if base(n) in LOGS else x[k])
            return t

        lo = np.array([to_x(n, LIMITS[base(n)][0]) for n in free])
        hi = np.array([to_x(n, LIMITS[base(n)][1]) for n in free])
        x = np.clip([to_x(n, start[n]) for n in free], lo + 1e-9, hi - 1e-9)
        t0 = time.perf_counter()
        for _ in range(2):  # fit, then again on a basis rebuilt at the end point

            def res(x, fm=fm):
                r = (fm.afc(theta(x)) - H) / s
                return jnp.concatenate([r.real, r.imag])

            R, J = jax.jit(res), jax.jit(jax.jacfwd(res))
            out = least_squares(
                lambda x: np.asarray(R(x)),
                x,
                jac=lambda x: np.asarray(J(x)),
                method="trf",
                bounds=(lo, hi),
                x_scale="jac",
                max_nfev=300,
            )
            x, th = out.x, np.asarray(theta(out.x))
            fm = fm.refresh(th)
        Hm = np.asarray(fm.afc(th))
        r = np.asarray(out.fun)
        chi = float(r @ r) / (r.size - len(free))
        tau = np.mean([autocorrelation_time(part) for part in (r[: r.size // 2], r[r.size // 2 :])])
        rel = np.sqrt(np.sum(abs(Hm - H) ** 2) / np.sum(abs(H) ** 2))
        p = dict(zip(names, th))
        E = p["D"] * 12 * (1 - p["nu"] ** 2) / h**3
        vals = ", ".join(f"{n} {v:.4g}" for n, v in p.items() if n not in ("D", "nu"))
        print(
            f"| {' + '.join(effects)}{' (nu held)' if held else ''} | {chi:.4g} | {rel:.3f} "
            f"| {tau:.0f} | {E / 1e9:.1f} | {p['nu']:.3f} | {vals} | "
            f"{time.perf_counter() - t0:.0f} |",
            flush=True,
        )

    print(f"{f.size} points of {f_all.size}")
    print("| model | chi2_red | rel. RMS | tau | E (GPa) | nu | the others | s |")
    print("|---|---|---|---|---|---|---|---|")
    for effects, held in MODELS:
        fit(effects, held)


if __name__ == "__main__":
    main()
