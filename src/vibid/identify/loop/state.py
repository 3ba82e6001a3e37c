"""What the loop's rounds share: the inputs that stay the same, the state between rounds."""

from __future__ import annotations

from dataclasses import dataclass

from vibid.identify.fit.data import FitData
from vibid.identify.fit.result import IdentificationResult
from vibid.identify.loop.policy import DEFAULT, Policy
from vibid.identify.loop.verdicts import Score, Stage
from vibid.identify.model.plate import Plate

STOP = None  # the explanation "the current model, nothing added"


@dataclass(frozen=True)
class Inputs:
    """What stays the same across the rounds: the declared plate (the model every
    question of the loop is asked of), the data, the candidates, the local method."""

    plate: Plate
    data: FitData
    pool: tuple
    local: str
    #: (lo, hi) Hz: the bands the fit leaves out (a resonance's top whose response depends
    #: on its amplitude): no diagnosed pole inside one is a feature
    left_out_hz: tuple = ()
    policy: Policy = DEFAULT


@dataclass(frozen=True)
class State:
    """The loop between rounds: its stages (the last is the current fit), the box its fits
    search within (a placed resonance's span around its pole), the physical prior box of
    the current model's parameters (the evidence's), and the rounds so far."""

    stages: tuple[Stage, ...]
    box: dict
    prior: dict
    rounds: tuple[tuple[Score, ...], ...] = ()
    #: the refits compared that were not chosen (the models the loop compared)
    alternatives: tuple[IdentificationResult, ...] = ()

    @property
    def current(self) -> Stage:
        return self.stages[-1]
