"""What the titanium loop's final residual is made of: where chi2 lies, the 664 Hz feature as
a factor on H, and the first resonance as a spread of one mode's frequency.

    python benchmarks/titanium_residual.py ti.json [--data ../shared/data/real-titanium]

``ti.json``: the report of ``vibid identify --afc ../shared/data/real-titanium/afc.csv
--setup ../shared/data/real-titanium/setup.json --json ti.json``. Its last stage's model
(the declared plate and the effects the loop added) is evaluated on all 11 960 points.
Prints, for each stage, the share of chi2 (the data's ``std`` as weights) per band; then
three fits that the library's effects do not make (a few seconds, scipy's least squares):

* a resonance of the base sensor's mount or of the fixture that multiplies H,
  ``c (1 + a e^{iφ} r² / (1 − r² + i r / Q))``, ``r = f / f₀``, fitted to data / model
  with the model held: how much of the misfit such a factor explains (the loop's
  ``stand_resonance``, a rocking base, explained 6.5-9.1 % of it in its refits);
* the first resonance from 150 to 260 Hz (901 bins, relative residuals) as one linear mode
  plus a constant and a slope, and as the same mode averaged over a Gaussian spread of its
  natural frequency (a resonance that wanders while the spectrum is averaged: an
  amplitude-dependent clamp under broadband excitation, or the temperature);
* the data's phase below the first resonance against a single mode's;
* the 664 Hz feature's phase against the phase a causal, minimum-phase factor with its
  magnitude would have (``−Hilbert{ln |R|}`` over 520-820 Hz, ``R`` = data / model, each
  detrended to its edges; on a factor of the first kind, Q 44, the two agree to 4°).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

EDGES_HZ = (40, 150, 185, 205, 260, 600, 720, 950, 1010, 1200, 1265, 1300, 1500)


def stage_afc(setup, f, parameters: dict) -> np.ndarray:
    from vibid.identify.effects import effects_for
    from vibid.identify.model.plate import build_forward_model, plate_model

    model = plate_model("isotropic", effects=effects_for(parameters))
    fm = build_forward_model(setup, f, model=model, theta0=parameters)
    return np.asarray(fm.afc(np.array([parameters[n] for n in model.names])))


def shares(f, r2) -> str:
    total = r2.sum()
    return " ".join(
        f"{a}-{b}: {100 * r2[(f >= a) & (f < b)].sum() / total:.1f} %"
        for a, b in zip(EDGES_HZ[:-1], EDGES_HZ[1:])
    )


def factor_fit(f, H, Hm, s):
    """The multiplying resonance fitted to H / Hm: (parameters, chi2 before, after)."""
    from scipy.optimize import least_squares

    def R(p):
        c, a, f0, q, ph = p
        r = f / f0
        return c * (1 + a * np.exp(1j * ph) * r**2 / (1 - r**2 + 1j * r / q))

    def res(p):
        d = (Hm * R(p) - H) / s
        return np.concatenate([d.real, d.imag])

    best = min(
        (
            least_squares(res, [1, 0.04, 661, q0, 0.0], x_scale=[0.01, 0.01, 1, 10, 0.1])
            for q0 in (20, 50, 150)
        ),
        key=lambda o: o.cost,
    )
    before = res([1, 0, 661, 50, 0])
    return best.x, float(before @ before), 2 * best.cost


def mode_fit(f, H, spread: bool):
    """One pole pair (its frequency spread by a Gaussian of relative std sigma when
    ``spread``) plus a constant and a slope, in relative terms: (rel. RMS, f1, Q, sigma)."""
    from scipy.optimize import least_squares

    fc = f[np.argmax(np.abs(H))]
    xi, wi = np.polynomial.hermite_e.hermegauss(41)
    wi = wi / wi.sum()

    def model(p):
        A, f1, beta = p[0] + 1j * p[1], p[2], p[3]
        fk, w = (f1 * (1 + p[8] * xi), wi) if spread else (np.array([f1]), np.array([1.0]))
        Hm = sum(wk * A * fj**2 / (fj**2 - f**2 + 1j * fj**2 * beta) for wk, fj in zip(w, fk))
        return Hm + p[4] + 1j * p[5] + (p[6] + 1j * p[7]) * (f - fc) / fc

    def res(p):
        d = (model(p) - H) / np.abs(H)
        return np.concatenate([d.real, d.imag])

    runs = []
    for sigma in (0.003, 0.01, 0.02) if spread else (None,):
        for beta in (0.002, 0.01):
            p0 = [0.0, -np.abs(H).max() * beta, fc, beta, 0, 0, 0, 0]
            runs.append(
                least_squares(res, p0 + ([sigma] if spread else []), x_scale="jac", max_nfev=2000)
            )
    best = min(runs, key=lambda o: o.cost)
    r, p = best.fun, best.x
    return (float(np.sqrt(r @ r / (r.size / 2))), p[2], 1 / abs(p[3]), abs(p[8]) if spread else 0.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("report")
    ap.add_argument("--data", default="../shared/data/real-titanium")
    args = ap.parse_args()
    from vibid.identify.engine.runtime import configure

    configure()
    from vibid.setup_model import parse_setup
    from vibid.signal.imported import read_afc_csv

    setup = parse_setup(open(f"{args.data}/setup.json").read())
    afc = read_afc_csv(f"{args.data}/afc.csv")
    f, H, s = afc.frequency_hz, afc.H, afc.std
    stages = json.load(open(args.report))["loop"]["stages"]
    Hm = None
    for stage in stages:
        Hm = stage_afc(setup, f, stage["parameters"])
        r2 = (np.abs(Hm - H) / s) ** 2
        print(
            f"{'+ ' + stage['added'] if stage['added'] else 'declared model'}: chi2_red "
            f"{r2.sum() / (2 * f.size):.4g} (the report's {stage['chi2_reduced']:.4g})\n"
            f"  share of chi2 per band (Hz): {shares(f, r2)}"
        )
    p, before, after = factor_fit(f, H, Hm, s)
    print(
        f"a resonance multiplying H, on the last stage: chi2 {before:.4g} -> {after:.4g} "
        f"({100 * (1 - after / before):.1f} % of it); f0 {p[2]:.1f} Hz, Q {p[3]:.0f}, "
        f"a {p[1]:.4f}, phase {np.degrees(p[4]):.0f} deg, c {p[0]:.4f}"
    )
    band = (f > 150) & (f < 260)
    for spread in (False, True):
        rms, f1, q, sigma = mode_fit(f[band], H[band], spread)
        print(
            f"first resonance, one mode{' spread' if spread else ''}: relative RMS "
            f"{100 * rms:.2f} % (f1 {f1:.2f} Hz, Q {q:.0f}"
            + (f", sigma {100 * sigma:.2f} % of f1)" if spread else ")")
        )
    for fc in (170, 180, 185, 190):
        i = int(np.argmin(np.abs(f - fc)))
        print(
            f"  at {f[i]:.1f} Hz the data lag by {-np.degrees(np.angle(H[i])):.1f} deg, "
            f"the last stage's model by {-np.degrees(np.angle(Hm[i])):.1f} deg"
        )
    print("the 664 Hz feature, data / model, against a minimum-phase factor of its magnitude:")
    for lo, magnitude, phase, minimum in minimum_phase_check(f, H, Hm):
        print(
            f"  {lo:.0f}-{lo + 8:.0f} Hz: |R| {magnitude:.2f}, phase {phase:+.1f} deg, "
            f"minimum phase {minimum:+.1f} deg"
        )


def minimum_phase_check(f, H, Hm, band=(520.0, 820.0)):
    """Per 8 Hz from 600 to 720 Hz: (from Hz, mean |R|, mean phase of R, the phase of the
    causal minimum-phase factor of the same magnitude, degrees), ``R = H / Hm`` detrended
    to its edges over ``band`` (the FFT grid is uniform, so the Hilbert transform applies)."""
    from scipy.signal import hilbert

    w = (f > band[0]) & (f < band[1])
    fw, R = f[w], H[w] / Hm[w]
    ln_mag, phase = np.log(np.abs(R)), np.unwrap(np.angle(R))
    ln_mag = ln_mag - np.interp(fw, fw[[0, -1]], ln_mag[[0, -1]])
    phase = phase - np.interp(fw, fw[[0, -1]], phase[[0, -1]])
    pad = np.zeros(4000)
    minimum = -np.imag(hilbert(np.concatenate([pad, ln_mag, pad])))[pad.size : -pad.size]
    rows = []
    for lo in range(600, 720, 8):
        m = (fw >= lo) & (fw < lo + 8)
        rows.append(
            (
                lo,
                np.exp(ln_mag[m]).mean(),
                np.degrees(phase[m]).mean(),
                np.degrees(minimum[m]).mean(),
            )
        )
    return rows


if __name__ == "__main__":
    main()
