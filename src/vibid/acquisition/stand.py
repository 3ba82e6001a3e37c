"""Open a stand by kind: ``ni`` (the real instruments) or ``simulated`` (the mocks behind the
same drivers).

``simulated`` is looked up by name (``vibid.hardware_mocks.virtual_stand.
open_simulated_stand``) when it is asked for, so acquisition/ never imports the mocks.
"""

from __future__ import annotations

import importlib

from vibid.acquisition.daq import NiDaq
from vibid.acquisition.generator import open_generator
from vibid.acquisition.protocols import Stand, WallClock
from vibid.acquisition.stand_config import StandConfig
from vibid.errors import VibidError

STAND_KINDS = ("simulated", "ni")
#: where the simulated stand's factory lives: module, function
SIMULATED_FACTORY = ("vibid.hardware_mocks.virtual_stand", "open_simulated_stand")


def open_stand(
    kind: str, setup, config: StandConfig = StandConfig(), *, realtime: bool = False
) -> Stand:
    """Open the generator and the DAQ of a stand.

    Parameters
    ----------
    kind : ``"ni"``: the generator at ``config.generator.url`` and the NI-DAQmx device of
        ``config.daq``, on the wall clock; ``"simulated"``: the virtual stand.
    setup : the declared setup (sample rate, sensor sensitivities; the specimen when simulated).
    config : the stand configuration.
    realtime : simulated only: pace it on the wall clock (the real stand always is).

    The generator's output is left as it is: the caller switches it off first thing.
    Errors (a port that does not open, NI-DAQmx missing) are one :class:`VibidError` line;
    whatever was opened is closed again.
    """
    if kind == "simulated":
        module, name = SIMULATED_FACTORY
        factory = getattr(importlib.import_module(module), name)
        return factory(setup, config, realtime=realtime)
    if kind != "ni":
        raise VibidError(f"unknown stand {kind!r}, expected one of {', '.join(STAND_KINDS)}")
    g = config.generator
    daq = NiDaq.from_setup(setup, config.daq)  # first: without NI-DAQmx, say so first
    try:
        generator = open_generator(
            g.url, baudrate=g.baudrate, timeout_s=g.timeout_s, max_vpp=config.drive.max_vpp
        )
    except BaseException:
        daq.close()
        raise
    return Stand(
        generator,
        daq,
        WallClock(),
        description=f"NI stand: generator at {g.url}, DAQ {config.daq.device}",
    )
