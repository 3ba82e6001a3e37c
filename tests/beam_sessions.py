"""Sessions for the closed loop made by a model vibid did not write: the paper's strip
(100 x 20 x 1 mm steel) with nu = 0 and its 1 g sensor on the centre line, whose AFC is the
exact Rayleigh beam of tests/beam_reference.py (with nu = 0 and a centred sensor the strip
bends as that beam: no torsion is excited, no anticlastic coupling). The declared setup's
Poisson's ratio box reaches below 0, so that the truth lies inside it.

Effects enter the beam as their physics, not as vibid's terms: a stand resonance as the
base's rotation theta(f), a clamp as a root spring k_r = k_theta W (complex with its own
loss), a free length as a longer beam with the sensor further out, the sensor's height as
its rotary inertia m (h e + e²), an added mass as more mass on the sensor's body, a
fixture resonance as a mode of the table whose node line carries the base sensor while the
clamp moves in it (:func:`fixture_transmissibility`, with structural loss), a loss
factor that varies with frequency as the beam's complex EI at each frequency, a channel
delay and a gain as what they do to the measured ratio (exp(-i omega tau), g). One effect
outside vibid's library: a ``crosstalk`` c of the base channel into the response channel
(the response sensor's signal plus c times the base's, as a shared ground gives), which
adds c to the measured ratio."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

import beam_reference as beam
from loop_data import noisy
from plate_helpers import strip_setup
from vibid.setup_model import Identification

L, W, H_M, RHO = 0.100, 0.020, 0.001, 7920.0
TRUTH = {"D": 17.97, "nu": 0.0, "beta": 0.003}
F = np.linspace(1500.0 / 60, 1500.0, 60)


def setup(freqs=F):
    """The declared setup: the strip, its sensor centred, stepped at ``freqs``."""
    s = strip_setup(y_m=W / 2)
    return dataclasses.replace(
        s,
        excitation=dataclasses.replace(s.excitation, frequencies_hz=tuple(map(float, freqs))),
        identification=Identification(
            "isotropic", {"D": (1.0, 100.0), "nu": (-0.3, 0.5), "beta": (1e-4, 0.1)}
        ),
    )


def _beam(effects: dict) -> dict:
    r = setup().sensors.response
    D, beta = TRUTH["D"], TRUTH["beta"]
    kw = dict(
        L=L,
        EI=D * W * (1 + 1j * beta),
        rhoA=RHO * H_M * W,
        rhoI=RHO * H_M**3 / 12 * W,
        x_s=r.x_m,
        m=r.mass_kg,
        J=r.mass_kg * (r.radius_m**2 / 4 + H_M**2 / 12),
    )
    if "k_theta_N_per_rad" in effects:
        loss = effects.get("beta_clamp", beta)
        kw["k_root"] = effects["k_theta_N_per_rad"] * W * (1 + 1j * loss)
    if "dL_m" in effects:
        kw["L"] += effects["dL_m"]
        kw["x_s"] += effects["dL_m"]
    if "height_m" in effects:
        e = effects["height_m"]
        kw["J"] += r.mass_kg * (H_M * e + e**2)
    if "mass_kg" in effects:
        kw["m"] += effects["mass_kg"]
    return kw


def _loss_at(effects: dict, f_hz: float) -> float:
    """The beam's loss factor at ``f_hz``: beta (f / 1 kHz)^alpha."""
    return TRUTH["beta"] * (f_hz / 1000.0) ** effects.get("alpha", 0.0)


@functools.cache
def _afc(key: tuple) -> np.ndarray:
    effects = dict(key)
    omega = 2 * math.pi * F
    theta = 0.0
    if "f_hz_1" in effects:
        f0, q, t0 = effects["f_hz_1"], effects["q_1"], effects["theta_rad_per_m_1"]
        theta = t0 / (1 - (F / f0) ** 2 + 1j * F / (f0 * q))
    if "alpha" in effects:  # EI (1 + i beta(f)) at each frequency
        kw = _beam(effects)
        H = np.array(
            [
                beam.afc(
                    np.array([w]),
                    **(kw | {"EI": kw["EI"].real * (1 + 1j * _loss_at(effects, f))}),
                    rotation_per_translation=t,
                )[0]
                for w, f, t in zip(omega, F, np.broadcast_to(theta, omega.shape))
            ]
        )
    else:
        H = beam.afc(omega, **_beam(effects), rotation_per_translation=theta)
    if "f_fixture_hz" in effects:  # a mode of the table the base sensor does not see
        H = H * fixture_transmissibility(
            F, effects["f_fixture_hz"], effects["q_fixture"], effects["a_fixture"]
        )
    H = H * effects.get("gain", 1.0) * np.exp(-1j * omega * effects.get("tau_s", 0.0))
    H = H + effects.get("crosstalk", 0.0)
    H.setflags(write=False)
    return H


def fixture_transmissibility(f_hz, f0_hz: float, q: float, a: float) -> np.ndarray:
    """The clamp's motion per base sensor's motion when the table has a mode of its own at
    ``f0_hz`` with structural loss 1/q, whose node line carries the base accelerometer
    while the clamp moves ``a`` times the table's motion in it (a base-excited mode:
    relative motion r² / (1 - r² + i/q) per unit base motion, r = f / f0). The strip's own
    force on the table is left out (a 16 g strip on a table of kilograms). vibid's
    fixture_resonance writes the loss as viscous, i r / q: the two agree at the resonance
    only."""
    r2 = (np.asarray(f_hz, float) / f0_hz) ** 2
    return 1 + a * r2 / (1 - r2 + 1j / q)


def data(effects: dict, seed: int = 0):
    """(H, std) of the beam with ``effects`` on :data:`F`, 0.3 % noise drawn with ``seed``."""
    return noisy(_afc(tuple(sorted(effects.items()))).copy(), seed)


#: On these beam sessions (seed 1) nu comes back 0.027 to 0.036 below the beam's 0, 4 to
#: 4.6 std, with a clamp or without one (benchmarks/loop_beam.json's clean case too): a
#: model-form difference between the exact beam (a rigid sensor body) and vibid's plate (a
#: sensor disc on a plate that deforms under it) that the strip's weakly determined nu
#: takes up. D, beta and the effects' constants come back within 3 std.
NU_ON_BEAM_DATA = 0.04  # the declared fit bends nu to 0.17-0.19


def named_with_truth(loop, effects: dict, but=()) -> None:
    """Assert that the loop's final fit has the beam's truth and ``effects``' values (but
    those named in ``but``) within 3 std."""
    r = loop.final
    for n, v in (TRUTH | effects).items():
        if n in but:
            continue
        assert abs(r.parameters[n] - v) < 3 * r.parameter_std[n], (
            n,
            r.parameters[n],
            r.parameter_std[n],
        )
