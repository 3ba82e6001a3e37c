"""The sampled basis of the harmonic model on a centred, normalised time axis.

A record of ``N`` samples at ``fs_hz`` is placed on

    u_n = (2 n - (N - 1)) / (N - 1)  ∈ [-1, 1],     n = 0 .. N-1,

so that ``u = 0`` is the record centre and, for angular frequency ω,
``ω (t_n - t_centre) = ν u_n`` with the normalised frequency ``ν = ω (N - 1) / (2 fs_hz)``.
One DFT bin (``Δf = fs / (N - 1)``) is ``Δν = π``.

Columns of the model ``D`` (``Layout``), every one O(1) on the grid: ``u^j`` for
``j = 0 .. degree`` (offset, drift), then ``cos(kνu)`` for ``k = 1 .. K``, then
``sin(kνu)`` for ``k = 1 .. K`` (fundamental and harmonics).

Each column is even or odd in ``u`` and the grid is symmetric, so every sum over the record
folds onto the half ``u > 0``: for a column pair ``p, q`` the full-record sum is
``Σ_{u>0} D_p D_q (1 + s_p s_q)`` (+ the centre sample when ``N`` is odd), ``s`` the parities.
Only half the grid is ever built.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class Layout:
    """Which columns the model holds: polynomial ``degree`` and ``n_harmonics`` (K ≥ 1)."""

    degree: int = 1
    n_harmonics: int = 3

    @property
    def n_model(self) -> int:
        """Number of columns of ``D`` (linear parameters per channel)."""
        return self.degree + 1 + 2 * self.n_harmonics

    def cos_index(self, k: int) -> int:
        """Column of ``cos(kνu)``, ``k`` from 1."""
        return self.degree + k

    def sin_index(self, k: int) -> int:
        """Column of ``sin(kνu)``, ``k`` from 1."""
        return self.degree + self.n_harmonics + k

    @property
    def cos_columns(self) -> slice:
        return slice(self.degree + 1, self.degree + 1 + self.n_harmonics)

    @property
    def sin_columns(self) -> slice:
        return slice(self.degree + 1 + self.n_harmonics, self.n_model)

    @cached_property
    def parity(self) -> np.ndarray:
        """+1 for an even column, -1 for an odd one, in column order."""
        poly = [1.0 if j % 2 == 0 else -1.0 for j in range(self.degree + 1)]
        trig = [1.0] * self.n_harmonics + [-1.0] * self.n_harmonics  # cos even, sin odd
        return np.array(poly + trig)

    @cached_property
    def centre_row(self) -> np.ndarray:
        """The columns at ``u = 0``."""
        row = np.zeros(self.n_model)
        row[0] = 1.0
        row[self.cos_columns] = 1.0
        return row


def normalised_frequency(f_hz, fs_hz, n_samples: int):
    """``ν = 2π f (N - 1) / (2 fs)``: the phase advance from record centre to record end, rad."""
    return (
        np.pi
        * np.asarray(f_hz, dtype=np.float64)
        * (n_samples - 1)
        / np.asarray(fs_hz, dtype=np.float64)
    )


def frequency_hz(nu, fs_hz, n_samples: int):
    """Inverse of :func:`normalised_frequency`."""
    return np.asarray(nu) * np.asarray(fs_hz) / (np.pi * (n_samples - 1))


def half_grid(n_samples: int) -> np.ndarray:
    """``u`` at the samples after the centre, ``N // 2`` values in increasing order."""
    if n_samples < 2:
        raise ValueError("a record needs at least 2 samples")
    first = 1 if n_samples % 2 == 0 else 2
    return (first + 2.0 * np.arange(n_samples // 2)) / (n_samples - 1)


def split_halves(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``(after, before_mirrored, centre)`` of records ``x[..., N]``.

    ``after[..., m]`` is the sample at ``+u_m`` and ``before_mirrored[..., m]`` the sample at
    ``-u_m`` (see :func:`half_grid`); ``centre`` is the middle sample when ``N`` is odd.
    """
    n = x.shape[-1]
    h = n // 2
    after = x[..., n - h :]
    before = x[..., :h][..., ::-1]
    centre = x[..., h] if n % 2 else None
    return after, before, centre


def unit_phasors(start_rad: np.ndarray, step_rad: np.ndarray, count: int) -> np.ndarray:
    """``exp(i (start + m step))`` for ``m = 0 .. count-1``, shape ``(S, count)``.

    Built as the outer product of two short tables of ``exp`` (blocks of ``~√count``), which
    costs one complex product per value instead of one ``sin`` and one ``cos``; each value is
    within a few ulp of the direct one.
    """
    start = np.asarray(start_rad, dtype=np.float64).reshape(-1)
    step = np.asarray(step_rad, dtype=np.float64).reshape(-1)
    block = max(1, int(np.sqrt(count)))
    n_blocks = -(-count // block)
    fine = np.exp(1j * step[:, None] * np.arange(block))
    coarse = np.exp(1j * (start[:, None] + step[:, None] * (block * np.arange(n_blocks))))
    return (coarse[:, :, None] * fine[:, None, :]).reshape(start.size, -1)[:, :count]


def columns(
    nu: np.ndarray, u: np.ndarray, layout: Layout, out: np.ndarray | None = None
) -> np.ndarray:
    """The model's columns at normalised frequencies ``nu`` (S,) on the half grid ``u``,
    shape ``(S, n_model, len(u))``, written into ``out`` when given."""
    nu = np.asarray(nu, dtype=np.float64).reshape(-1)
    step = (u[1] - u[0]) if u.size > 1 else 0.0
    e1 = unit_phasors(nu * u[0], nu * step, u.size)
    if out is None:
        out = np.empty((nu.size, layout.n_model, u.size))
    for j in range(layout.degree + 1):
        out[:, j, :] = u**j
    c, s = out[:, layout.cos_columns], out[:, layout.sin_columns]
    c[:, 0], s[:, 0] = e1.real, e1.imag
    for k in range(
        1, layout.n_harmonics
    ):  # cos/sin((k+1)x) = 2 cos x · cos/sin(kx) - cos/sin((k-1)x)
        np.multiply(c[:, 0], c[:, k - 1], out=c[:, k])
        np.multiply(c[:, 0], s[:, k - 1], out=s[:, k])
        c[:, k] *= 2.0
        s[:, k] *= 2.0
        if k == 1:
            c[:, k] -= 1.0
        else:
            c[:, k] -= c[:, k - 2]
            s[:, k] -= s[:, k - 2]
    return out
