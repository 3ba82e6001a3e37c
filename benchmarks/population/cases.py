"""The population's cases, drawn at random with fixed seeds from the independent forward
model of tests/population_model.py (numpy/scipy, no vibid), and written as
``cases/<name>/{afc.csv, setup.json, truth.json}``.

    python -m benchmarks.population.cases [--only 3,17]

Kinds: strips (0.5-3 mm thick, steel/aluminium/titanium, 100-200 x 20-30 mm) and plates
(isotropic metal, or an orthotropic laminate declared orthotropic, or declared isotropic:
the ``anisotropy`` effect), on a stepped sine (60-150 steps, half of them near the
resonances) or an FFT grid (uniform df, 200-500 points), 2-6 modes in the band. Each case
holds 0-3 library effects of physically plausible size, or one effect outside the
library (viscous air damping, a crosstalk of the base channel, a slipping first mode).
Every effect is checked DETECTABLE on its own: the declared model's least-squares refit
(scipy, this model's own, at a lower Ritz order) leaves chi2_red above
:data:`DETECTABLE` against the case's noise; an effect that is not is redrawn larger (x1.5), up to five
times, then left out (truth.json records it as ``<name>_not_detectable``). The lossy clamp's own loss (``clamp_loss``) is checked against the
declared model with a clamp spring of the plate's loss; a lossless clamp (beta_clamp = 0)
that is not detectable as such names ``clamp_loss`` optional. The whole case is checked
too. Complex Gaussian noise, its std per point (0.2-0.5 % of |H| plus a floor) written in
the CSV. The cases are split once (seeded) into a ``calibration`` and a ``measured`` half.

``--only`` regenerates the cases of those indices alone (each case draws from its own
seed [SEED, index], so one case regenerates without the others).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import pathlib
import sys

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")  # small matrices: threads only contend (15x slower)

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import population_model as pm

CASES_DIR = HERE / "cases"
SEED = 63
#: the declared model's best fit must leave chi2_red (noise-free data, so chi2 above the
#: noise's own 1) above this for an effect to count as detectable
DETECTABLE = 3.0
#: Ritz orders of the detectability refits (the truth's data use pm.STRIP/PLATE_ORDER):
#: what is compared there is the effect against its absence, on one discretisation
CHECK_ORDER = {"strip": (16, 7), "plate": (14, 12)}
TRUTH_ORDER = {"strip": pm.STRIP_ORDER, "plate": pm.PLATE_ORDER}

METALS = {
    "steel": (200e9, 0.29, 7850.0),
    "aluminium": (70e9, 0.33, 2700.0),
    "titanium": (110e9, 0.32, 4500.0),
}

STRIP_EFFECTS = [
    "channel_delay",
    "sensor_gain",
    "clamp_compliance",
    "clamp_loss",
    "free_length",
    "added_mass",
    "frequency_dependent_loss",
    "stand_resonance",
    "fixture_resonance",
    "sensor_position",
    "sensor_inertia",
]
PLATE_EFFECTS = [
    "channel_delay",
    "sensor_gain",
    "clamp_compliance",
    "clamp_loss",
    "free_length",
    "added_mass",
    "frequency_dependent_loss",
    "stand_resonance",
    "fixture_resonance",
    "anisotropy",
]
OUT_OF_LIBRARY = ["air_damping", "crosstalk", "amplitude_dependent_top"]


# -- drawing ----------------------------------------------------------------------------
def draw_specimen(rng, kind, ortho=False):
    """(pm.Plate, truth material dict, nominal material dict, name) of one specimen."""
    if kind == "strip":
        L, B = rng.uniform(0.100, 0.200), rng.uniform(0.020, 0.030)
        h = float(np.exp(rng.uniform(math.log(0.5e-3), math.log(3e-3))))
    else:
        L, B = rng.uniform(0.120, 0.200), rng.uniform(0.080, 0.150)
        h = rng.uniform(1.0e-3, 3.0e-3)
    if ortho:
        rho, mname = 1550.0, "laminate"
        E1, E2 = rng.uniform(40e9, 140e9), rng.uniform(6e9, 10e9)
        G12, nu12 = rng.uniform(3.5e9, 5.5e9), rng.uniform(0.25, 0.32)
        nu21 = nu12 * E2 / E1
        c = h**3 / (12 * (1 - nu12 * nu21))
        mat = {
            "D11": E1 * c,
            "D22": E2 * c,
            "D12": nu12 * E2 * c,
            "D66": G12 * h**3 / 12,
            "beta": rng.uniform(0.004, 0.01),
        }
        nominal = dict(mat)
        mat = {k: v * (rng.uniform(0.93, 1.07) if k != "beta" else 1.0) for k, v in mat.items()}
    else:
        mname = str(rng.choice(list(METALS)))
        E, nu, rho = METALS[mname]
        Et = E * rng.uniform(0.95, 1.05)  # the specimen's own modulus, not the handbook's
        nut = float(np.clip(nu + rng.uniform(-0.02, 0.02), 0.2, 0.4))
        mat = {
            "D": Et * h**3 / (12 * (1 - nut**2)),
            "nu": nut,
            "beta": float(np.exp(rng.uniform(math.log(0.0015), math.log(0.005)))),
        }
        nominal = {"D": E * h**3 / (12 * (1 - nu**2)), "nu": nu, "beta": 0.003}
    mass = rng.uniform(0.5e-3, 2.0e-3)
    radius = rng.uniform(1.0e-3, 3.5e-3) if kind == "strip" else rng.uniform(2e-3, 4e-3)
    xs = L * rng.uniform(0.85, 0.93)
    ys = B * (rng.uniform(0.35, 0.65) if kind == "strip" else rng.uniform(0.55, 0.8))
    plate = pm.Plate(
        float(L), float(B), float(h), rho, float(xs), float(ys), float(mass), float(radius)
    )
    name = f"{mname} {kind} {L * 1e3:.0f}x{B * 1e3:.0f}x{h * 1e3:.2f}"
    return plate, {k: float(v) for k, v in mat.items()}, nominal, name


def draw_effect(rng, name, ctx, grow=1.0):
    """Parameters (this model's names = the report format's) of one effect, its size
    scaled by ``grow`` after a failed detectability check."""
    plate, mat, modes, f_hi = ctx["plate"], ctx["material"], ctx["modes"], ctx["f_hi"]
    D = pm.stiffness(mat)["D11"]
    beta = mat["beta"]
    g = grow
    if name == "channel_delay":
        return {"tau_s": float(rng.uniform(5e-6, 4e-5) * g)}
    if name == "sensor_gain":
        return {"gain": float(1 + rng.choice([-1, 1]) * rng.uniform(0.005, 0.03) * g)}
    if name in ("clamp_compliance", "clamp_loss"):
        c = float(np.exp(rng.uniform(math.log(150), math.log(5000)))) / g  # k L / D
        out = {"k_theta_N_per_rad": c * D / plate.L}
        if name == "clamp_loss":  # lossless or far lossier than the plate
            out["beta_clamp"] = 0.0 if rng.uniform() < 0.4 else float(beta * rng.uniform(8, 30) * g)
        return out
    if name == "free_length":
        return {"dL_m": float(rng.uniform(0.3e-3, 2e-3) * g)}
    if name == "added_mass":
        return {"mass_kg": float(plate.mass * rng.uniform(0.03, 0.3) * g)}
    if name == "frequency_dependent_loss":
        return {"alpha": float(rng.choice([-1, 1]) * min(rng.uniform(0.3, 0.9) * g, 1.5))}
    if name in ("stand_resonance", "fixture_resonance"):
        f0 = _between_modes(rng, modes, ctx["f_lo"], f_hi)
        q = float(rng.uniform(10, 40))
        if name == "stand_resonance":
            return {
                "f_hz_1": f0,
                "q_1": q,
                "theta_rad_per_m_1": float(rng.uniform(0.01, 0.06) * g / (q * plate.xs)),
            }
        return {
            "f_fixture_hz": f0,
            "q_fixture": q,
            "a_fixture": float(rng.uniform(0.005, 0.03) * g),
        }
    if name == "sensor_position":
        room = plate.B / 2 - plate.radius - 1e-3
        dy = min(rng.uniform(2e-3, 5e-3) * g, room)
        return {"sensor_dy_m": float(dy if plate.ys < plate.B / 2 else -dy)}
    if name == "sensor_inertia":
        return {"height_m": float(rng.uniform(3e-3, 8e-3) * g)}
    if name == "air_damping":  # modal loss gamma / omega: 1-3 times beta at mode 1
        return {"air_gamma_per_s": float(rng.uniform(1, 3) * g * beta * 2 * math.pi * modes[0])}
    if name == "crosstalk":
        c = rng.uniform(0.005, 0.02) * g
        ph = rng.uniform(-0.3, 0.3)
        return {"crosstalk_re": float(c * math.cos(ph)), "crosstalk_im": float(c * math.sin(ph))}
    if name == "amplitude_dependent_top":
        return {
            "slip_kappa": float(rng.uniform(0.3, 1.0)),
            "slip_fraction": float(rng.uniform(0.3, 0.6) / g),
        }
    if name == "anisotropy":
        return {}
    raise ValueError(name)


def _between_modes(rng, modes, f_lo, f_hi):
    """A frequency in the band at least 4 % from every mode (a resonance where the plate has
    none)."""
    for _ in range(200):
        f = float(
            np.exp(rng.uniform(math.log(max(f_lo * 1.5, 0.5 * modes[0])), math.log(f_hi * 0.95)))
        )
        if np.all(np.abs(np.asarray(modes) / f - 1) > 0.04):
            return f
    return float(0.5 * (modes[0] + modes[1]))


def grid(rng, grid_kind, modes, f_lo, f_hi, beta):
    if grid_kind == "fft":
        n = int(rng.integers(200, 501))
        df = f_hi / n
        k0 = max(1, math.ceil(f_lo / df))
        return df * np.arange(k0, n + 1)
    n = int(rng.integers(60, 151))
    inband = [m for m in modes if f_lo < m < f_hi]
    n_near = n // 2
    per = max(3, n_near // max(len(inband), 1))
    near = np.concatenate([m * (1 + 2.5 * beta * np.linspace(-1, 1, per)) for m in inband])
    rest = np.exp(np.linspace(math.log(f_lo), math.log(f_hi), n - near.size))
    f = np.unique(np.round(np.concatenate([rest, near]), 4))
    return f[(f >= f_lo) & (f <= f_hi)]


# -- detectability ------------------------------------------------------------------------
def declared_start(case):
    mat = case["material"]
    if case["declared"] == "isotropic" and "D" not in mat:  # orthotropic declared isotropic
        D11 = mat["D11"]
        return {
            "D": D11,
            "nu": mat["D12"] / math.sqrt(mat["D11"] * mat["D22"]),
            "beta": mat["beta"],
        }
    return dict(mat)


def chi2_declared(case, effects, f, std, free=(), fixed=None, truth_model=False):
    """chi2_red of the declared model's refit to the noise-free AFC with ``effects``
    (``truth_model``: the truth's material model instead, so that an effect beside
    ``anisotropy`` is judged on its own)."""
    order = CHECK_ORDER[case["kind"]]
    H = pm.afc(f, case["plate"], case["material"], effects, order)
    c = dict(case)
    if truth_model:
        c["declared"] = "isotropic" if "D" in case["material"] else "orthotropic"
    start = declared_start(c) | {k: effects[k] for k in free}
    chi, _ = pm.refit(
        f,
        H,
        std,
        c["plate"],
        c["declared"],
        start,
        free_effects=free,
        fixed_effects=fixed,
        order=order,
    )
    return chi


def _merge(effects: dict) -> dict:
    """One parameter dict of this model from {effect name: parameters}."""
    out = {}
    for v in effects.values():
        out |= v
    return out


# -- one case ---------------------------------------------------------------------------
def make_case(index, spec, seed):
    """Draw one case from ``spec`` = (kind, grid, declared/ortho, [effects...])."""
    rng = np.random.default_rng([SEED, seed])
    kind, grid_kind, material_kind, wanted = spec
    ortho = material_kind != "isotropic"
    plate, mat, nominal, sname = draw_specimen(rng, kind, ortho)
    declared = "orthotropic" if material_kind == "orthotropic" else "isotropic"
    if "anisotropy" in wanted:
        declared = "isotropic"
    order = CHECK_ORDER[kind]
    n_modes = int(rng.integers(2, 5) if kind == "strip" else rng.integers(3, 7))
    modes = pm.natural_frequencies_hz(plate, mat, n=n_modes + 1, order=order)
    f_hi = float(modes[n_modes - 1] * 1.02 + 0.35 * (modes[n_modes] - modes[n_modes - 1]))
    f_lo = float(max(5.0, 0.15 * modes[0]))
    ctx = {"plate": plate, "material": mat, "modes": modes, "f_lo": f_lo, "f_hi": f_hi}
    case = {"kind": kind, "plate": plate, "material": mat, "declared": declared}
    noise_rel, floor = float(rng.uniform(0.002, 0.005)), float(rng.uniform(0.5e-4, 2e-4))
    f = grid(rng, grid_kind, modes, f_lo, f_hi, mat["beta"])
    H0 = pm.afc(f, plate, mat, {}, order)
    std = pm.noise_std(H0, noise_rel, floor)

    effects, required, optional, checks = {}, [], [], {}
    aniso = "anisotropy" in wanted
    for name in wanted:
        if name == "anisotropy":
            chi = chi2_declared(case, {}, f, std)
            checks[name] = chi
            required.append(name)
            continue
        ok = False
        for attempt in range(6):
            p = draw_effect(rng, name, ctx, grow=1.5**attempt)
            if name == "clamp_loss":
                # against a clamp spring of the plate's loss (k free): clamp_compliance alone
                with_spring = {"k_theta_N_per_rad": p["k_theta_N_per_rad"]}
                chi = chi2_declared(case, p, f, std, free=("k_theta_N_per_rad",), truth_model=aniso)
                chi_k = chi2_declared(case, with_spring, f, std, truth_model=aniso)
                checks["clamp_compliance"] = chi_k
                if chi_k < DETECTABLE:
                    continue
                if chi < DETECTABLE and p["beta_clamp"] == 0.0:
                    checks[name] = chi
                    optional.append("clamp_loss")
                    required.append("clamp_compliance")
                    effects["clamp_compliance"] = p
                    ok = True
                    break
            else:
                chi = chi2_declared(case, p, f, std, truth_model=aniso)
            checks[name] = chi
            if chi >= DETECTABLE:
                ok = True
                if name == "clamp_loss":
                    required += ["clamp_compliance", "clamp_loss"]
                    effects["clamp_loss"] = p
                else:
                    required.append(name)
                    effects[name] = p
                break
        if not ok:
            checks[name + "_not_detectable"] = chi
    if (
        "clamp_compliance" in required
        and "clamp_loss" not in required
        and "clamp_loss" not in optional
    ):
        optional.append("clamp_loss")  # its null is the plate's beta: a fit may add it
    truth_effects = _merge(effects)
    out_of_library = [n for n in wanted if n in OUT_OF_LIBRARY and n in effects]
    required = [n for n in required if n not in OUT_OF_LIBRARY]
    whole = None
    if len(effects) == 1:
        whole = next(v for k, v in checks.items() if k in effects or k == "clamp_compliance")
    elif effects:
        whole = chi2_declared(case, truth_effects, f, std)

    # the truth's data at the converged order, then the noise
    H = pm.afc(f, plate, mat, truth_effects, TRUTH_ORDER[kind])
    std = pm.noise_std(H, noise_rel, floor)
    Hn = pm.noisy(H, std, seed=int(rng.integers(2**31)))
    name = f"c{index:02d}-{kind}-{grid_kind}-" + ("+".join(wanted) if wanted else "clean")
    setup = setup_json(plate, sname, declared, nominal, mat)
    truth = {
        "name": name,
        "kind": kind,
        "grid": grid_kind,
        "material_model": "isotropic" if "D" in mat else "orthotropic",
        "declared_model": declared,
        "material": mat,
        "engineering": engineering(plate, mat),
        "effects": {
            k: {n: v for n, v in p.items()} for k, p in effects.items() if k not in OUT_OF_LIBRARY
        },
        "out_of_library": {k: effects[k] for k in out_of_library},
        "required": required,
        "optional": optional,
        "detectability_chi2_red": {k: round(v, 3) for k, v in checks.items()},
        "whole_case_chi2_red": None if whole is None else round(whole, 3),
        "band_hz": [float(f[0]), float(f[-1])],
        "n_points": int(f.size),
        "modes_hz": [float(m) for m in modes],
        "noise": {"rel": noise_rel, "floor": floor},
        "ritz_order": list(TRUTH_ORDER[kind]),
        "seed": [SEED, seed],
        "drawn": list(wanted),
    }
    return name, f, Hn, std, setup, truth


def engineering(plate, mat):
    h = plate.h
    if "D" in mat:
        E = mat["D"] * 12 * (1 - mat["nu"] ** 2) / h**3
        return {"E_Pa": E, "nu": mat["nu"], "G_Pa": E / (2 * (1 + mat["nu"]))}
    nu12 = mat["D12"] / mat["D22"]
    nu21 = mat["D12"] / mat["D11"]
    c = 12 * (1 - nu12 * nu21) / h**3
    return {
        "E1_Pa": mat["D11"] * c,
        "E2_Pa": mat["D22"] * c,
        "G12_Pa": mat["D66"] * 12 / h**3,
        "nu12": nu12,
    }


def setup_json(plate, sname, declared, nominal, mat):
    if declared == "isotropic":
        if "D" in nominal:
            D0 = nominal["D"]
        else:  # a laminate declared isotropic: its nominal along-length stiffness
            D0 = nominal["D11"]
        bounds = {"D": [D0 / 3, D0 * 3], "nu": [0.0, 0.5], "beta": [1e-4, 0.1]}
    else:
        bounds = {k: [nominal[k] / 3, nominal[k] * 3] for k in ("D11", "D22", "D66")}
        bounds["D12"] = [0.0, nominal["D12"] * 3]
        bounds["beta"] = [1e-4, 0.1]
    return {
        "specimen": {
            "name": sname,
            "length_m": plate.L,
            "width_m": plate.B,
            "thickness_m": plate.h,
            "density_kg_m3": plate.rho,
        },
        "sensors": {
            "base": {"sensitivity_mV_per_g": 100.0},
            "response": {
                "sensitivity_mV_per_g": 100.0,
                "x_m": plate.xs,
                "y_m": plate.ys,
                "mass_kg": plate.mass,
                "radius_m": plate.radius,
            },
        },
        "daq": {"sample_rate_hz": 25600.0},
        "identification": {
            "model": declared,
            "bounds": {k: [float(a), float(b)] for k, (a, b) in bounds.items()},
        },
    }


# -- the population -----------------------------------------------------------------------
def population():
    """The specs (kind, grid, material kind, effects) of every case, drawn with SEED."""
    rng = np.random.default_rng(SEED)
    specs = []

    def kind_grid(i):
        return ("strip" if i % 5 < 3 else "plate"), ("stepped" if i % 2 == 0 else "fft")

    # clean cases: 12 (strips and plates, one laminate declared orthotropic in three)
    for i in range(12):
        kind, g = kind_grid(i)
        mk = "orthotropic" if kind == "plate" and i % 3 == 0 else "isotropic"
        specs.append((kind, g, mk, []))
    # library cases: 16 with one effect, 14 with two, 10 with three
    for i, n in enumerate([1] * 16 + [2] * 14 + [3] * 10):
        kind, g = kind_grid(i + 1)
        pool = list(STRIP_EFFECTS if kind == "strip" else PLATE_EFFECTS)
        if n == 1:  # each library effect alone at least once
            order = STRIP_EFFECTS + [e for e in PLATE_EFFECTS if e not in STRIP_EFFECTS]
            eff = order[i % len(order)]
            if eff not in pool:
                kind, pool = "plate", list(PLATE_EFFECTS)
            if eff == "sensor_position" or eff == "sensor_inertia":
                kind, pool = "strip", list(STRIP_EFFECTS)
            chosen = [eff]
        else:
            chosen = list(rng.choice(pool, size=n, replace=False))
            if "clamp_loss" in chosen and "clamp_compliance" in chosen:
                chosen.remove("clamp_compliance")
        mk = "isotropic"
        if "anisotropy" in chosen:
            mk = "orthotropic-declared-isotropic"
        elif kind == "plate" and rng.uniform() < 0.3:
            mk = "orthotropic"
        specs.append((kind, g, mk, [str(c) for c in chosen]))
    # outside the library: 4 of each
    for i, eff in enumerate(OUT_OF_LIBRARY * 4):
        kind, g = kind_grid(i)
        if eff == "amplitude_dependent_top":
            kind, g = "strip", "stepped"  # a stepped sine through the slipping top
        specs.append((kind, g, "isotropic", [eff]))
    return specs


def split(names):
    """The seeded split into the calibration and measured halves."""
    rng = np.random.default_rng(SEED + 1)
    order = rng.permutation(len(names))
    half = len(names) // 2
    cal = sorted(names[i] for i in order[:half])
    return {"calibration": cal, "measured": sorted(names[i] for i in order[half:])}


def write_case(name, f, H, std, setup, truth, root=CASES_DIR):
    d = root / name
    d.mkdir(parents=True, exist_ok=True)
    rows = ["frequency_hz,re,im,std"] + [
        f"{a:.8f},{b.real:.10g},{b.imag:.10g},{s:.6g}" for a, b, s in zip(f, H, std)
    ]
    (d / "afc.csv").write_text("\n".join(rows) + "\n")
    (d / "setup.json").write_text(json.dumps(setup, indent=1) + "\n")
    (d / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")


def case_names(root=CASES_DIR):
    return sorted(p.name for p in root.iterdir() if (p / "truth.json").exists())


def digest(name, root=CASES_DIR):
    h = hashlib.sha256()
    for fn in ("afc.csv", "setup.json"):
        h.update((root / name / fn).read_bytes())
    return h.hexdigest()[:16]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", help="comma-separated case indices to (re)generate")
    args = ap.parse_args(argv)
    specs = population()
    only = None if not args.only else {int(i) for i in args.only.split(",")}
    names = []
    for i, spec in enumerate(specs):
        if only is not None and i not in only:
            continue
        name, f, H, std, setup, truth = make_case(i, spec, seed=i)
        write_case(name, f, H, std, setup, truth)
        names.append(name)
        print(
            f"{name}: {truth['n_points']} pts {truth['band_hz'][0]:.0f}-"
            f"{truth['band_hz'][1]:.0f} Hz required={truth['required']} "
            f"optional={truth['optional']} chi2={truth['detectability_chi2_red']}",
            flush=True,
        )
    allnames = case_names()
    (HERE / "split.json").write_text(json.dumps(split(allnames), indent=1) + "\n")


if __name__ == "__main__":
    main()
