"""Is the titanium strip's first resonance one linear mode, two, or no linear mode at all?

    python benchmarks/titanium_mode1.py

The real AFC (``tests/data/titanium_afc.csv.gz``) from 150 to 260 Hz (901 bins), fitted with
linear rational models of 1-3 pole pairs plus a constant and a slope (the modes outside the
band), in relative terms (weights 1/|H|, least squares from scikit-rf's VectorFitting
poles), against the data's own point-to-point scatter (second differences). Two linear modes
close together would be fitted by two pole pairs down to that scatter; a response that
depends on its amplitude (a clamp whose friction grows with the motion) is fitted by no
number of linear modes. Prints, per model, the relative RMS and largest residual, and the
scatter.
"""

import gzip
import os
import sys
import warnings

import numpy as np
from scipy.optimize import least_squares

HERE = os.path.dirname(os.path.abspath(__file__))
BAND_HZ = (150.0, 260.0)


def vector_fit(f, H, n):
    import skrf
    from skrf.vectorFitting import VectorFitting

    nw = skrf.Network(frequency=skrf.Frequency.from_f(f, unit="hz"), s=H.reshape(-1, 1, 1))
    vf = VectorFitting(nw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        vf.vector_fit(n_poles_real=0, n_poles_cmplx=n, fit_constant=True, fit_proportional=True)
    return vf


def rational(x, s, n, s0):
    out = (x[0] + 1j * x[1]) + (x[2] + 1j * x[3]) * s / s0
    for k in range(n):
        a, b, rr, ri = x[4 + 4 * k:8 + 4 * k]
        p, r = -a + 1j * b, rr + 1j * ri
        out = out + r / (s - p) + np.conj(r) / (s - np.conj(p))
    return out


def main() -> int:
    with gzip.open(os.path.join(HERE, "..", "tests", "data", "titanium_afc.csv.gz"), "rt") as fh:
        f, re, im, _ = np.loadtxt(fh, delimiter=",", skiprows=1, unpack=True)
    band = (f > BAND_HZ[0]) & (f < BAND_HZ[1])
    f, H = f[band], (re + 1j * im)[band]
    s, s0 = 2j * np.pi * f, 2j * np.pi * f.mean()
    d2 = H[2:] - 2 * H[1:-1] + H[:-2]  # white noise of std e per part: var(d2) = 6 e² per part
    scatter = np.sqrt(np.mean(np.abs(d2 / H[1:-1]) ** 2) / 12)
    print(f"{f.size} bins {BAND_HZ[0]:g}-{BAND_HZ[1]:g} Hz; point-to-point scatter "
          f"{100 * scatter:.2f} % of |H| (per part)")
    for n in (1, 2, 3):
        vf = vector_fit(f, H, n)
        x0 = [vf.constant_coeff[0].real, vf.constant_coeff[0].imag,
              (vf.proportional_coeff[0] * s0).real, (vf.proportional_coeff[0] * s0).imag]
        for p, r in zip(vf.poles, vf.residues[0]):
            if p.imag > 0:
                x0 += [-p.real, p.imag, r.real, r.imag]

        def residual(x):
            e = (rational(x, s, n, s0) - H) / np.abs(H)
            return np.concatenate([e.real, e.imag])

        x = least_squares(residual, x0, x_scale="jac", max_nfev=20000).x
        e = np.abs(rational(x, s, n, s0) - H) / np.abs(H)
        poles = ", ".join(f"{x[5 + 4 * k] / 2 / np.pi:.2f} Hz Q {x[5 + 4 * k] / (2 * x[4 + 4 * k]):.0f}"
                          for k in range(n))
        print(f"{n} pole pair(s): relative RMS {100 * np.sqrt(np.mean(e ** 2)):.1f} %, largest "
              f"{100 * e.max():.0f} % ({poles})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
