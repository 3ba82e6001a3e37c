"""A whole session recorded on a simulated stand: the virtual specimen is the plate model.

:func:`simulate_session` plays the setup's stepped sine on a plate with known parameters and
writes what the two accelerometers would have recorded, step by step, with the session
writer. The specimen is the same :class:`~vibid.hardware_mocks.specimen.VirtualSpecimen` and
the records the same :func:`~vibid.hardware_mocks.records.synthetic_step` as the virtual
stand's (:mod:`vibid.hardware_mocks.virtual_stand`), which plays them through the real drivers. The truth is the full finite-element model (not the reduced one that the
identification uses), on a finer mesh than the identification's default so that the
model's own discretisation error is really there to be accounted for. The records carry
what real ones do (clock offset, harmonics, DC, drift, noise; see :class:`StandConditions`).

Notes (where this differs from a real stand): every step is steady state (no transient),
the base amplitude is the same at every frequency, and the stand adds nothing but what
:class:`StandConditions` lists.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

import numpy as np

from vibid.hardware_mocks.records import synthetic_step, true_frequency_hz
from vibid.hardware_mocks.specimen import VirtualSpecimen
from vibid.session import SessionWriter
from vibid.setup_model import Setup


@dataclass(frozen=True)
class StandConditions:
    """What the simulated stand adds to perfect sinusoids (all SI)."""

    record_s: float = 0.25
    base_amplitude_m_s2: float = 5.0
    noise_std_m_s2: tuple[float, float] = (0.002, 0.002)
    clock_offset_ppm: float = 40.0
    harmonics_db: tuple[float, ...] = (-45.0, -52.0)
    dc_m_s2: tuple[float, float] = (0.02, -0.01)
    drift_m_s2_per_s: tuple[float, float] = (0.004, -0.003)


def true_afc(
    setup: Setup, params: dict, frequencies_hz, *, accuracy: str = "default", effects=()
) -> np.ndarray:
    """The AFC at ``frequencies_hz`` (Hz) from the full FE model, for ``params``: a
    material's parameters, and any effect's (e.g. ``k_theta_N_per_rad``, ``tau_s``), which
    puts that effect into the data whatever the setup declares; ``effects`` names effects
    without parameters of their own (``transverse_shear`` on an isotropic plate). The
    virtual specimen (:class:`~vibid.hardware_mocks.specimen.VirtualSpecimen`) meshed for
    the highest of ``frequencies_hz``."""
    specimen = VirtualSpecimen(
        setup, params, f_max_hz=float(np.max(frequencies_hz)), accuracy=accuracy, effects=effects
    )
    return specimen.h(frequencies_hz)


def simulate_session(
    path: str | os.PathLike,
    setup: Setup,
    params: dict,
    *,
    conditions: StandConditions = StandConditions(),
    seed: int = 0,
    accuracy: str = "fine",
    effects=(),
    progress=None,
) -> str:
    """Write a session of ``setup``'s stepped sine on a plate with material ``params`` (and
    the effects their names imply, plus ``effects`` by name: see :func:`true_afc`).
    ``progress(label, done, total, None)`` is called as the specimen is solved (most of the
    time) and the steps are written.

    Returns the path written. The same arguments and seed give the same file contents
    (but for times and the session id).
    """
    c = conditions
    fs = setup.daq.sample_rate_hz
    commanded = np.asarray(setup.excitation.frequencies_hz, float)
    # the specimen answers at the frequency the generator really plays
    played = np.array([true_frequency_hz(f, c.clock_offset_ppm) for f in commanded])
    specimen = VirtualSpecimen(
        setup, params, f_max_hz=float(np.max(played)), accuracy=accuracy, effects=effects
    )
    h = np.empty(played.size, complex)
    for done, idx in enumerate(np.array_split(np.arange(played.size), -(-played.size // 10)), 1):
        h[idx] = specimen.h(played[idx])  # ten frequencies at a time, for the progress
        if progress is not None:
            progress("solving the virtual specimen", int(idx[-1]) + 1, played.size, None)
    n = max(1, int(round(c.record_s * fs)))
    start = datetime.now(UTC)
    elapsed_s = 0.0  # the stand's clock since the first step began
    rng = np.random.default_rng(seed)
    with SessionWriter(path, setup, software="vibid simulated stand") as writer:
        for k, (f, hk) in enumerate(zip(commanded, h)):
            base, response = synthetic_step(
                f,
                hk,
                sample_rate_hz=fs,
                n_samples=n,
                base_amplitude_m_s2=c.base_amplitude_m_s2,
                base_phase_rad=float(rng.uniform(0, 2 * np.pi)),
                clock_offset_ppm=c.clock_offset_ppm,
                dc_m_s2=c.dc_m_s2,
                drift_m_s2_per_s=c.drift_m_s2_per_s,
                harmonics_db=c.harmonics_db,
                noise_std_m_s2=c.noise_std_m_s2,
                dtype=np.float32,
                rng=rng,
            )
            elapsed_s += setup.excitation.settle_at(k)
            t0 = start + timedelta(seconds=elapsed_s)
            elapsed_s += c.record_s
            writer.append(
                frequency_hz=f,
                sample_rate_hz=fs,
                base=base,
                response=response,
                t0_utc=t0.isoformat(),
            )
    return os.fspath(path)
