"""The data of the closed-loop tests (test_identify_loop*.py): the paper's strip on 60 steps
to 1500 Hz, its AFC from the full FE model on a finer mesh than the fit's, with noise of
0.3 % of |H| per point (and a floor), as the signal stage reports for a 0.3 % channel
noise.

The fine model's AFC takes about ten seconds per call (a full sparse solve per frequency)
and several tests ask for the same one (the five clean-data seeds share one noise-free
AFC; the undeclared-delay data appear in two files), so it is computed once per test
session; likewise the declared model's fit of one data set that two loop tests start
from. Every cached array is handed out as a copy."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from plate_helpers import strip_setup

TRUTH = {"D": 17.97, "nu": 0.286, "beta": 0.003}
F = np.linspace(1500.0 / 60, 1500.0, 60)
#: Restarts of the declared model's global search (and peak matching) in the loop tests: on
#: these data every restart reaches the same basin, so a second one only repeats the first
#: (about 8 s a fit); a search that missed it would fail the tests, not pass them. The
#: loop's own global refits keep their restarts.
RESTARTS = 1


def strip_on(freqs=F, setup=None):
    """``setup`` (default: the paper's strip) stepped at ``freqs`` (Hz)."""
    s = setup or strip_setup()
    return dataclasses.replace(
        s,
        excitation=dataclasses.replace(
            strip_setup().excitation, frequencies_hz=tuple(float(f) for f in freqs)
        ),
    )


def _key(params: dict) -> tuple:
    return tuple(sorted(params.items()))


@functools.cache
def _fine_afc(key: tuple) -> np.ndarray:
    from vibid.hardware_mocks.simulated_session import true_afc

    H = true_afc(strip_on(), dict(key), F, accuracy="fine")
    H.setflags(write=False)
    return H


def fine_afc(effects: dict) -> np.ndarray:
    """The strip's AFC on :data:`F` with the true material and ``effects``' parameters."""
    return _fine_afc(_key(TRUTH | effects)).copy()


def noisy(H, seed, rel=0.003, floor=1e-3):
    """``H`` plus complex normal noise of std ``rel |H| + floor``; returns (data, std)."""
    sd = rel * np.abs(H) + floor
    rng = np.random.default_rng(seed)
    return H + sd * (rng.standard_normal(H.size) + 1j * rng.standard_normal(H.size)), sd


def data(effects: dict, seed: int):
    """(H, std): the strip with ``effects`` on :data:`F`, noise drawn with ``seed``."""
    return noisy(fine_afc(effects), seed)


@functools.cache
def _declared(key: tuple, seed: int, restarts: int):
    from vibid.identify.fit import Measurement, SearchOptions, identify

    H, sd = data(dict(key), seed)
    return identify(
        strip_on(), Measurement(F, H, sd), search=SearchOptions(restarts=restarts, seed=0)
    )


def declared_fit(effects: dict, seed: int, restarts: int = RESTARTS):
    """The declared model's fit of :func:`data` ``(effects, seed)``: what
    ``close_loop(strip_on(), F, H, sd, seed=0, restarts=restarts)`` fits first (a frozen
    result that neither the loop nor the tests write to, so it is shared as it is)."""
    return _declared(_key(effects), seed, restarts)
