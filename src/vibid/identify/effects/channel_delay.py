"""``channel_delay``: a time skew between the two channels.

Multiplexed sampling or different anti-alias filters delay the response channel by ``τ``
against the base channel; the measured AFC is then the plate's times ``exp(-i ω τ)``
(convention ``exp(+iωt)``): a phase that grows linearly with frequency and no change of
|H|. Null value ``τ = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.model.terms import Term
from vibid.parameters import TAU  # tau_s (s): the catalogue declares it


@dataclass(frozen=True)
class ChannelDelay(Term):
    """``H → H exp(-i ω τ_s)``."""

    name = "channel_delay"
    explains = ("trend", "phase_slope")  # of a trend, its phase across the band
    phase_only = True  # |H exp(-iωτ)| = |H|
    meaning = "a time skew between the two measurement channels"
    parameters = (TAU,)

    def afc_map(self, p: dict, omega, H, xp):
        return H * xp.exp(-1j * omega * p["tau_s"])


EFFECT = ChannelDelay()
