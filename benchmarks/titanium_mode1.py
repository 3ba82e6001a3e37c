"""Is the titanium strip's first resonance one linear mode, two, or no linear mode at all?

    python benchmarks/titanium_mode1.py

The real AFC (``tests/data/titanium_afc.csv.gz``) from 150 to 260 Hz (901 bins), fitted with
linear rational models of 1-3 pole pairs plus a constant and a slope (the modes outside the
band), in relative terms (:func:`vibid.identify.assess.linearity.rational_fit`, the report's
linearity test), against the data's own point-to-point scatter. Two linear modes close
together would be fitted by two pole pairs down to that scatter; a response that depends on
its amplitude (a clamp whose friction grows with the motion) is fitted by no number of
linear modes. Prints, per model, the relative RMS residual and the poles, and the scatter.
"""

import gzip
import os
import sys

import numpy as np

from vibid.identify.assess.linearity import rational_fit, relative_scatter

HERE = os.path.dirname(os.path.abspath(__file__))
BAND_HZ = (150.0, 260.0)


def main() -> int:
    with gzip.open(os.path.join(HERE, "..", "tests", "data", "titanium_afc.csv.gz"), "rt") as fh:
        f, re, im, _ = np.loadtxt(fh, delimiter=",", skiprows=1, unpack=True)
    band = (f > BAND_HZ[0]) & (f < BAND_HZ[1])
    f, H = f[band], (re + 1j * im)[band]
    print(
        f"{f.size} bins {BAND_HZ[0]:g}-{BAND_HZ[1]:g} Hz; point-to-point scatter "
        f"{100 * relative_scatter(H):.2f} % of |H| (per part)"
    )
    for n in (1, 2, 3):
        rms, poles = rational_fit(f, H, n)
        print(
            f"{n} pole pair(s): relative RMS {100 * rms:.1f} % ("
            + ", ".join(f"{fp:.2f} Hz Q {q:.0f}" for fp, q in poles)
            + ")"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
