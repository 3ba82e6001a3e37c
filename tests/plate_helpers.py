"""Shared fixtures of the plate-model tests (setups and cached models)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from vibid.identify.model.materials import flexural_rigidity
from vibid.setup_model import ResponseSensor, Sensors, Specimen, example_setup

#: The paper's strip: steel, E 198 GPa, nu 0.286, rho 7920, h 1 mm -> D = 17.97 N m.
PAPER_D = flexural_rigidity(198e9, 0.286, 0.001)
PAPER_THETA = np.array([PAPER_D, 0.286, 0.003])


def strip_setup(**sensor):
    s = example_setup()
    if sensor:
        r = dataclasses.replace(s.sensors.response, **sensor)
        s = dataclasses.replace(s, sensors=Sensors(s.sensors.base, r))
    return s


def plate_setup(length_m, width_m, thickness_m, density=7920.0, **sensor):
    s = example_setup()
    spec = Specimen("test plate", length_m, width_m, thickness_m, density)
    r = ResponseSensor(
        100.0,
        x_m=sensor.get("x_m", 0.9 * length_m),
        y_m=sensor.get("y_m", 0.5 * width_m),
        mass_kg=sensor.get("mass_kg", 0.0),
        radius_m=sensor.get("radius_m", 0.2 * width_m),
    )
    return dataclasses.replace(s, specimen=spec, sensors=Sensors(s.sensors.base, r))


@functools.cache
def strip_model(kind="local", accuracy="default", nf=200):
    """The paper's strip model on ``nf`` frequencies 7.5 .. 1500 Hz (cached per session)."""
    from vibid.identify import build_forward_model

    freqs = np.linspace(1500.0 / nf, 1500.0, nf)
    theta0 = dict(zip(("D", "nu", "beta"), PAPER_THETA)) if kind == "local" else None
    return build_forward_model(strip_setup(), freqs, theta0=theta0, accuracy=accuracy)
