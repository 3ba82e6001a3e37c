"""``sensor_gain``: a relative sensitivity error of the response channel.

The response accelerometer's declared sensitivity (mV/g) is off by a factor against the
base accelerometer's (a calibration a few per cent old, a cable, a temperature): every
measured |H| is scaled by ``gain``, the phase untouched. Null value ``gain = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import Parameter, Term

GAIN = Parameter("gain", "1", ("log",), bounds=(0.8, 1.25), null=1.0, rule="positive",
                 noun="a gain")


@dataclass(frozen=True)
class SensorGain(Term):
    """``H → gain H``."""

    name = "sensor_gain"
    meaning = "a sensitivity error of the response sensor against the base sensor"
    parameters = (GAIN,)

    def afc_map(self, p: dict, omega, H, xp):
        return p["gain"] * H


EFFECT = SensorGain()
