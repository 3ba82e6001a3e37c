"""E of each real strip from each of its bending resonances, by an independent model.

    python benchmarks/real_strips_beam.py

The exact Euler–Bernoulli cantilever of ``tests/beam_reference.py`` (not vibid's plate: no
finite elements, no plate action), with the declared length, thickness, width and density
and the declared accelerometer as a point mass at its declared distance from the clamp.
For each strip, each resonance's measured frequency gives one E: with the declared sensor
the two must agree if the declared setup is the truth (a sensor mass off, a compliant clamp
or a wrong free length moves the two modes differently or alike). Then the free length
each resonance needs for the authors' nominal E, the sensor moving with the free end (a
clamp whose effective line lies inside its jaws lengthens the free span).

The measured frequencies are the peaks of |H| in the AFCs (``../shared/data/real-titanium``,
``examples/real-steel``). No vibid import: this is what vibid's figures are checked against
(BENCHMARKS.md, "The real strips: an independent beam").
"""

from __future__ import annotations

import os
import sys

from scipy.optimize import brentq

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from beam_reference import natural_frequencies_hz  # noqa: E402

WIDTH_M = 0.02
#: name: free length (m), thickness (m), density (kg/m³), sensor's distance from the clamp
#: (m), the two resonances' peaks (Hz), the authors' nominal E (Pa)
STRIPS = {
    "titanium": (0.0996, 0.003, 4550.0, 0.0956, (197.5, 1278.8), 106e9),
    "steel": (0.0999, 0.002, 7920.0, 0.0959, (139.0, 903.0), 198e9),
}
SENSOR_KG = (0.0, 0.0017, 0.0022)  # none, the declared AP1030, half a gram more


def modes_hz(E, L, h, rho, x_s, m):
    I, A = WIDTH_M * h**3 / 12, WIDTH_M * h
    return natural_frequencies_hz(2, L=L, EI=E * I, rhoA=rho * A, x_s=x_s, m=m)


def e_from(k, f_hz, L, h, rho, x_s, m):
    """The E (Pa) that puts mode ``k`` at ``f_hz``."""
    return brentq(lambda E: modes_hz(E, L, h, rho, x_s, m)[k] - f_hz, 20e9, 400e9, xtol=1e5)


def free_length_for(k, f_hz, E, L, h, rho, x_s, m):
    """The extra free length (m) that puts mode ``k`` at ``f_hz`` with modulus ``E``."""
    return brentq(
        lambda dL: modes_hz(E, L + dL, h, rho, x_s + dL, m)[k] - f_hz, -0.02, 0.02, xtol=1e-7
    )


def main():
    print("strip      sensor   E from f1   E from f2")
    for name, (L, h, rho, x_s, peaks, _) in STRIPS.items():
        for m in SENSOR_KG:
            e = [e_from(k, f, L, h, rho, x_s, m) / 1e9 for k, f in enumerate(peaks)]
            print(f"{name:9s} {m * 1e3:4.1f} g   {e[0]:6.1f} GPa  {e[1]:6.1f} GPa")
    print("\nthe free length each resonance needs for the authors' nominal E (declared sensor):")
    for name, (L, h, rho, x_s, peaks, E) in STRIPS.items():
        dl = [
            free_length_for(k, f, E, L, h, rho, x_s, SENSOR_KG[1]) * 1e3
            for k, f in enumerate(peaks)
        ]
        print(f"{name:9s} E {E / 1e9:g} GPa: f1 needs {dl[0]:+.2f} mm, f2 {dl[1]:+.2f} mm")


if __name__ == "__main__":
    main()
