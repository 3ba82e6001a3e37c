"""``sensor_gain``: a relative sensitivity error of the response channel.

The response accelerometer's declared sensitivity (mV/g) is off by a factor against the
base accelerometer's (a calibration a few per cent old, a cable, a temperature): every
measured |H| is scaled by ``gain``, the phase untouched. Null value ``gain = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import GAIN  # gain (1): the catalogue declares it


@dataclass(frozen=True)
class SensorGain(Term):
    """``H → gain H``."""

    name = "sensor_gain"
    explains = ("trend", "magnitude_offset")  # of a trend, its mean offset
    meaning = "a sensitivity error of the response sensor against the base sensor"
    parameters = (GAIN,)

    def afc_map(self, p: dict, omega, H, xp):
        return p["gain"] * H


EFFECT = SensorGain()
