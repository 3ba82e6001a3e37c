"""Open a stand by kind: ``ni`` (the real instruments, built in) or a kind registered under
the ``vibid.stands`` entry points, such as ``simulated`` (the mocks behind the same drivers).

The registry is pyproject.toml's ``[project.entry-points."vibid.stands"]``: each entry is a
kind's name and its factory, ``factory(setup, config, *, realtime=False) -> Stand``;
vibid's own is ``simulated = "vibid.hardware_mocks.virtual_stand:open_simulated_stand"``.
A factory is loaded only when its kind is asked for, so acquisition/ never imports the mocks.
"""

from __future__ import annotations

from importlib.metadata import entry_points

from vibid.acquisition.daq import NiDaq
from vibid.acquisition.generator import open_generator
from vibid.acquisition.protocols import Stand, WallClock
from vibid.acquisition.stand_config import StandConfig
from vibid.errors import VibidError

#: the entry-point group the stand kinds other than ``ni`` are registered in
STAND_GROUP = "vibid.stands"


def stand_kinds() -> tuple[str, ...]:
    """The kinds :func:`open_stand` knows: those registered in :data:`STAND_GROUP`, then
    ``ni``."""
    registered = sorted({ep.name for ep in entry_points(group=STAND_GROUP)} - {"ni"})
    return (*registered, "ni")


def open_stand(
    kind: str, setup, config: StandConfig = StandConfig(), *, realtime: bool = False
) -> Stand:
    """Open the generator and the DAQ of a stand.

    Parameters
    ----------
    kind : ``"ni"``: the generator at ``config.generator.url`` and the NI-DAQmx device of
        ``config.daq``, on the wall clock; ``"simulated"``: the virtual stand; any other kind
        registered in the ``vibid.stands`` entry points: its factory's stand.
    setup : the declared setup (sample rate, sensor sensitivities; the specimen when simulated).
    config : the stand configuration.
    realtime : simulated only: pace it on the wall clock (the real stand always is).

    The generator's output is left as it is: the caller switches it off first thing.
    Errors (a port that does not open, NI-DAQmx missing, an unknown kind) are one
    :class:`VibidError` line; whatever was opened is closed again.
    """
    if kind == "ni":
        return _open_ni_stand(setup, config)
    registered = entry_points(group=STAND_GROUP).select(name=kind)
    if not registered:
        raise VibidError(f"unknown stand {kind!r}, expected one of {', '.join(stand_kinds())}")
    factory = next(iter(registered)).load()
    return factory(setup, config, realtime=realtime)


def _open_ni_stand(setup, config: StandConfig) -> Stand:
    """The real stand: the NI-DAQmx device first (without NI-DAQmx, say so first), then the
    generator (the DAQ closed again if it does not open)."""
    g = config.generator
    daq = NiDaq.from_setup(setup, config.daq)
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
