"""The discretisation part of the reported std (issue 62): the finer step alone against
Richardson's extrapolation over three meshes, on data from converged and from
unconverged references.

    python benchmarks/disc_error.py [--json benchmarks/disc_error.json]

1. The paper's strip's first six natural frequencies along vibid's refinement family
   (coarser, default, finer, ...; conforming Argyris with exact quadrature, so each is an
   upper bound of the exact one) and on scikit-fem's own Argyris basis (global
   coordinates) on uniform 40 x 8 and 80 x 16 meshes with their h^2 Richardson value.
2. The cost of the error estimate at the estimate: the finer mesh's model (what the fit
   paid before) and the coarser one's (what the extrapolation adds), each in a fresh
   process state (assembly included, as an identification's first call).
3. Local fits from the truth (D 17.97 N m, nu 0.286, beta 0.003) of noise-free data
   weighted as a precise stand's (std 3e-5 |H| + 1e-5: nu's std about 1e-6, the
   precision of the issue's sessions), complex and |H| alone, on the loop tests' grid (60
   steps to 1500 Hz) and the CLI test's (40 steps to 900 Hz), from two references: the
   full FE model on the "fine" mesh (60 x 12 cells, 6 corner levels: what the virtual
   stand simulates), and the h^2 Richardson extrapolation of scikit-fem's Argyris on 40 x
   8 and 80 x 16 (the "independent converged" reference of tests/test_plate_reference.py).
   Each with the error estimate of before (the finer step alone) and of now.
4. A plate meshed by its bending wavelength (150 x 100 x 1 mm steel to 600 Hz, its sensor
   of 2 mm radius: 15 x 10 cells, 4 corner levels), whose meshes are not yet asymptotic:
   the AFC's error estimate against a mesh three levels finer (53 x 35 cells, 7 corner
   levels; itself a few per cent of the error off), in the 2-norm relative to |H|.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
GRIDS = {
    "loop, 60 steps to 1500 Hz": np.linspace(25.0, 1500.0, 60),
    "cli, 40 steps to 900 Hz": 22.5 * np.arange(1, 41),
}


def _frequencies(geometry, param, theta, disc, n=6):
    from vibid.identify.model.assembly import model_matrices
    from vibid.identify.model.modal import frequencies_and_decays, model_eigenvalues

    return frequencies_and_decays(
        model_eigenvalues(model_matrices(geometry, disc, ()), param, theta, n)
    )[0]


def convergence(geometry, param, theta) -> dict:
    from vibid.identify.model.mesh import (
        Discretisation,
        coarser_discretisation,
        discretisation,
        finer_discretisation,
    )

    d0 = discretisation(geometry)
    family = [coarser_discretisation(d0), d0]
    for _ in range(3):
        family.append(finer_discretisation(family[-1]))
    family.append(Discretisation("argyris", 90, 18, 8))
    out = {d.label: _frequencies(geometry, param, theta, d).tolist() for d in family}
    a, b = (
        _frequencies(geometry, param, theta, Discretisation("argyris-global", n, n // 5))
        for n in (40, 80)
    )
    out["scikit-fem argyris 40x8"] = a.tolist()
    out["scikit-fem argyris 80x16"] = b.tolist()
    out["scikit-fem argyris, h^2 Richardson"] = ((4 * b - a) / 3).tolist()
    best = np.array(out[family[-1].label])
    print("\n1. natural frequencies, Hz (relative to argyris 90x18 +8 corner levels)")
    for label, f in out.items():
        rel = np.array(f) / best - 1
        print(
            f"  {label:>38}: "
            + " ".join(f"{x:.10g}" for x in f[:4])
            + "   rel "
            + " ".join(f"{x:+.1e}" for x in rel)
        )
    return out


def cost(setup, F, theta) -> dict:
    from vibid.identify import build_forward_model
    from vibid.identify.model.mesh import coarser_discretisation, finer_discretisation

    fm = build_forward_model(setup, F, theta0=TRUTH)
    fm.afc(theta)
    out = {}
    for name, d in (
        ("finer", finer_discretisation(fm.discretisation)),
        ("coarser", coarser_discretisation(fm.discretisation)),
    ):
        t = time.perf_counter()
        fm._level_afc(d, theta)
        out[name + "_s"] = time.perf_counter() - t
    t = time.perf_counter()
    fm.discretisation_error(theta)
    out["estimate_after_levels_cached_s"] = time.perf_counter() - t
    print(
        f"\n2. the error estimate's meshes: finer {out['finer_s']:.2f} s (before), coarser "
        f"{out['coarser_s']:.2f} s (added)"
    )
    return out


def fits(F, H, sd, setup, label) -> list:
    from vibid.identify.fit import Measurement, SearchOptions, identify
    from vibid.identify.model import forward

    rows = []
    new_parts = forward.ForwardModel.model_error_parts

    def old_parts(self, theta):  # before: the finer step alone
        return self.discretisation_error(theta).finer, self.reduction_error(theta)

    for estimate, parts in (("finer step", old_parts), ("extrapolated", new_parts)):
        forward.ForwardModel.model_error_parts = parts
        try:
            for mag in (False, True):
                r = identify(
                    setup,
                    Measurement(F, H, sd, magnitude=mag),
                    search=SearchOptions(method="local", start=TRUTH),
                )
                bias = dict(zip(r.parameter_names, r.model_error_bias))
                for n, v, s in zip(r.parameter_names, r.values, r.std):
                    rows.append(
                        {
                            "data": label,
                            "estimate": estimate,
                            "fit": "|H|" if mag else "complex",
                            "parameter": n,
                            "value": float(v),
                            "std": float(s),
                            "discretisation": float(abs(bias[n])),
                            "z": float((v - TRUTH[n]) / s),
                        }
                    )
        finally:
            forward.ForwardModel.model_error_parts = new_parts
    return rows


def plate() -> dict:
    from plate_helpers import plate_setup
    from vibid.identify import build_forward_model
    from vibid.identify.model.mesh import finer_discretisation

    setup = plate_setup(0.15, 0.10, 0.001, mass_kg=0.001, radius_m=0.002)
    F = np.linspace(10.0, 600.0, 80)
    theta = np.array([TRUTH[n] for n in ("D", "nu", "beta")])
    fm = build_forward_model(setup, F, theta0=TRUTH)
    err = fm.discretisation_error(theta)
    ref = fm.discretisation
    for _ in range(3):
        ref = finer_discretisation(ref)
    H = np.asarray(fm.afc(theta))
    truth = fm._level_afc(ref, theta) - H

    def rel(x):
        return float(np.linalg.norm(x / np.abs(H)))

    out = {
        "meshes": list(err.meshes),
        "reference": ref.label,
        "order": err.extrapolation.order,
        "factor": err.extrapolation.factor,
        "reference_over_finer_step": rel(truth) / rel(err.finer),
        "extrapolated_off": rel(err.d - truth) / rel(truth),
        "finer_step_off": rel(err.finer - truth) / rel(truth),
    }
    print(
        f"\n4. plate 150 x 100 mm to 600 Hz ({err.meshes[1]}): order {out['order']:.2f}, "
        f"factor {out['factor']:.3f}; {ref.label} is {out['reference_over_finer_step']:.3f} "
        f"finer steps off; the estimate {out['extrapolated_off']:.1%} off it, the finer "
        f"step alone {out['finer_step_off']:.1%}"
    )
    return out


def main() -> int:
    from vibid.identify.engine.runtime import configure

    configure()
    parser = argparse.ArgumentParser()
    parser.add_argument("--json")
    args = parser.parse_args()
    from loop_data import strip_on
    from vibid.identify.model.assembly import Geometry, model_matrices
    from vibid.identify.model.full import model_afc_full
    from vibid.identify.model.mesh import Discretisation, discretisation
    from vibid.identify.model.plate import plate_model

    theta = np.array([TRUTH[n] for n in ("D", "nu", "beta")])
    setup0 = strip_on(next(iter(GRIDS.values())))
    geometry = Geometry.from_setup(setup0)
    param = plate_model("isotropic").for_geometry(geometry)
    report = {
        "cost": cost(setup0, next(iter(GRIDS.values())), theta),
        "frequencies_hz": convergence(geometry, param, theta),
        "fits": [],
    }
    fine = discretisation(geometry, "fine")
    for grid, F in GRIDS.items():
        setup = strip_on(F)
        H_fine = model_afc_full(model_matrices(geometry, fine, ()), param, theta, F)
        a, b = (
            model_afc_full(
                model_matrices(geometry, Discretisation("argyris-global", n, n // 5), ()),
                param,
                theta,
                F,
            )
            for n in (40, 80)
        )
        sd = 3e-5 * np.abs(H_fine) + 1e-5
        for label, H in (
            (f"{grid}: {fine.label} (converged)", H_fine),
            (f"{grid}: scikit-fem argyris h^2 Richardson", (4 * b - a) / 3),
        ):
            report["fits"] += fits(F, H, sd, setup, label)
    print(
        "\n3. noise-free fits from the truth, std 3e-5 |H| + 1e-5: value +- std "
        "(discretisation part) z"
    )
    for r in report["fits"]:
        if r["parameter"] in ("D", "nu"):
            print(
                f"  {r['data']:>62} | {r['estimate']:>12} | {r['fit']:>7} | {r['parameter']:>2} "
                f"{r['value']:.8g} +- {r['std']:.2g} ({r['discretisation']:.2g}) z {r['z']:+.2f}"
            )
    report["plate"] = plate()
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
