"""Parameter spaces: physical parameters <-> one unconstrained, well-scaled vector ``u``.

Every optimiser of the identification (differential evolution, trust-region Newton, BFGS,
Levenberg-Marquardt) works on ``u``. Each parameter has a :class:`Transform`: a map
``phi`` from its physical domain onto the real line, followed by an affine
normalisation chosen so that the prior box ``[low, high]`` of the setup maps onto
``[-1, 1]``:

    u = (phi(theta) - centre) / half_width

``phi`` is

* ``log`` for quantities that are positive and known to within orders of magnitude
  (stiffnesses, loss factor, masses, gains): peaks move with sqrt(D), so log D makes
  their spacing uniform and the landscape far less skewed;
* ``logit`` onto the open physical interval ``(a, b)`` for quantities with hard physical
  limits (Poisson's ratio in (-1, 1/2)): no step of any optimiser can leave it;
* ``linear`` for signed quantities without limits (D12, D16, D26, delays).

Each parameter's term declares its map (``Parameter.kind``,
:mod:`vibid.parameters`); a name no term declares falls back to ``log`` for a
positive box that spans more than a factor 10, else ``linear``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.special

from vibid.errors import VibidError

#: Fraction of a prior box kept away from a hard edge of the physical domain (a prior
#: bound at 0 for a log parameter, or nu's bound at 1/2), so that its image is finite.
EDGE_MARGIN = 1e-3


def _xp(x):
    """The array namespace for ``x``: jnp for JAX arrays and tracers, else numpy."""
    return jnp if isinstance(x, jax.Array) else np


def _sigmoid(z):
    """1 / (1 + exp(-z)) without overflow for either namespace."""
    return jax.nn.sigmoid(z) if _xp(z) is jnp else scipy.special.expit(z)


@dataclass(frozen=True)
class Transform:
    """The map of one parameter between its physical value and its coordinate ``u``.

    Attributes
    ----------
    name: the parameter's name, e.g. ``"D"``.
    kind: ``"log"``, ``"logit"`` or ``"linear"``.
    low, high: the prior box (physical units), from ``setup.identification.bounds``.
    a, b: the open physical interval of a ``logit`` parameter (else nan).
    centre, half_width: the affine normalisation of ``phi`` (prior box -> [-1, 1]).
    """

    name: str
    kind: str
    low: float
    high: float
    a: float
    b: float
    centre: float
    half_width: float

    # phi and its inverse, written for both numpy (plain values: no JAX dispatch, which
    # compiles each operation on first use) and jnp (traced under jit/grad)
    def _phi(self, theta):
        xp = _xp(theta)
        if self.kind == "log":
            return xp.log(theta)
        if self.kind == "logit":
            s = (theta - self.a) / (self.b - self.a)
            return xp.log(s) - xp.log1p(-s)
        return theta

    def _phi_inv(self, z):
        xp = _xp(z)
        if self.kind == "log":
            return xp.exp(z)
        if self.kind == "logit":
            return self.a + (self.b - self.a) * _sigmoid(z)
        return z

    def dfrom_u(self, u):
        """d theta / d u at ``u`` (array-friendly)."""
        z = self.centre + self.half_width * u
        if self.kind == "log":
            return self.half_width * _xp(z).exp(z)
        if self.kind == "logit":
            sig = _sigmoid(z)
            return self.half_width * (self.b - self.a) * sig * (1 - sig)
        return self.half_width * _xp(z).ones_like(z)

    def to_u(self, theta):
        """Coordinate ``u`` of a physical value (array-friendly)."""
        return (self._phi(theta) - self.centre) / self.half_width

    def from_u(self, u):
        """Physical value of a coordinate ``u`` (array-friendly, differentiable)."""
        return self._phi_inv(self.centre + self.half_width * u)

    def inside_domain(self, theta: float) -> bool:
        """Whether ``theta`` lies in the physical domain of the map."""
        if self.kind == "log":
            return theta > 0
        if self.kind == "logit":
            return self.a < theta < self.b
        return math.isfinite(theta)


def make_transform(name: str, low: float, high: float, kind: tuple | None = None) -> Transform:
    """The transform of parameter ``name`` with prior box ``[low, high]``.

    Raises :class:`VibidError` when the box is empty or outside the physical domain.
    """
    low, high = float(low), float(high)
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise VibidError(f"bounds of {name}: need finite low < high, got [{low!r}, {high!r}]")
    if kind is None:
        from vibid.parameters import known_parameter

        declared = known_parameter(name)
        kind = None if declared is None else declared.kind
    if kind is None:
        kind = ("log",) if (low > 0 and high / low > 10) else ("linear",)
    a = b = math.nan
    lo, hi = low, high
    if kind[0] == "log":
        if high <= 0:
            raise VibidError(f"bounds of {name}: {name} is positive, got [{low!r}, {high!r}]")
        # only a prior bound at 0 (e.g. mass >= 0) is moved in: a positive one is kept, however
        # many decades the box spans (clipped to a thousandth of its top, the clamp's
        # 1e2-1e9 N/rad box was 1e6-1e9, and a stiff clamp of 1.6e4 lay outside it)
        lo = low if low > 0 else high * EDGE_MARGIN
    elif kind[0] == "logit":
        a, b = float(kind[1]), float(kind[2])
        if high <= a or low >= b:
            raise VibidError(
                f"bounds of {name}: [{low!r}, {high!r}] lies outside its physical range ({a}, {b})"
            )
        margin = EDGE_MARGIN * (b - a)
        lo, hi = max(low, a + margin), min(high, b - margin)
    elif kind[0] != "linear":
        raise VibidError(f"unknown transform kind {kind[0]!r} for parameter {name}")
    proto = Transform(name, kind[0], low, high, a, b, 0.0, 1.0)
    z_lo, z_hi = float(proto._phi(lo)), float(proto._phi(hi))
    return Transform(name, kind[0], low, high, a, b, (z_lo + z_hi) / 2, (z_hi - z_lo) / 2)


@dataclass(frozen=True)
class ParameterSpace:
    """The ordered parameters of one fit and their transforms.

    ``to_u``/``from_u`` map whole vectors; ``from_u`` is differentiable, so the loss
    can be written as a function of ``u``.
    """

    transforms: tuple[Transform, ...]

    @classmethod
    def from_bounds(cls, names, bounds: dict, kinds: dict | None = None) -> ParameterSpace:
        """Build the space of ``names`` with their prior boxes ``bounds[name] = (low, high)``."""
        missing = [n for n in names if n not in bounds]
        if missing:
            raise VibidError(f"no bounds given for {', '.join(missing)}")
        kinds = kinds or {}
        return cls(tuple(make_transform(n, *bounds[n], kind=kinds.get(n)) for n in names))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.transforms)

    @property
    def size(self) -> int:
        return len(self.transforms)

    def to_u(self, theta) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        return np.array([float(t.to_u(v)) for t, v in zip(self.transforms, theta)])

    def from_u(self, u):
        """Physical vector(s) of ``u`` (last axis = parameters); numpy for numpy input,
        jnp (differentiable) for JAX arrays and tracers."""
        xp = _xp(u)
        u = xp.asarray(u)
        return xp.stack([t.from_u(u[..., i]) for i, t in enumerate(self.transforms)], axis=-1)

    def coefficients(self, length: int | None = None) -> dict:
        """The transforms as arrays (kind flags, normalisation, logit interval), for
        :func:`from_u_coefficients`: compiled code that takes them as arguments serves every
        space of the same size, whatever its names and boxes. With ``length``, padded to
        that many entries (identity maps: ``u = 0`` is 0)."""
        n = self.size if length is None else int(length)
        out = {
            "log": np.zeros(n, bool),
            "logit": np.zeros(n, bool),
            "centre": np.zeros(n),
            "half_width": np.ones(n),
            "a": np.zeros(n),
            "b": np.ones(n),
        }
        for i, t in enumerate(self.transforms):
            out["log"][i], out["logit"][i] = t.kind == "log", t.kind == "logit"
            out["centre"][i], out["half_width"][i] = t.centre, t.half_width
            if t.kind == "logit":
                out["a"][i], out["b"][i] = t.a, t.b
        return jax.device_put(out)

    def theta(self, u) -> np.ndarray:
        """``from_u`` as a numpy float array."""
        return np.asarray(self.from_u(u), dtype=float)

    def dtheta_du(self, u) -> np.ndarray:
        """Diagonal of the Jacobian d theta / d u at ``u`` (one entry per parameter)."""
        return np.array(
            [float(t.dfrom_u(float(ui))) for t, ui in zip(self.transforms, np.asarray(u))]
        )

    def du_dtheta(self, theta) -> np.ndarray:
        """The derivative of each coordinate by its parameter at ``theta``: the inverse of
        :meth:`dtheta_du` (0 where a coordinate lies at infinity, a null on a log box's
        edge)."""
        with np.errstate(all="ignore"):
            return 1.0 / self.dtheta_du(self.to_u(np.asarray(theta, float)))

    def inside_domain(self, theta) -> bool:
        return all(t.inside_domain(float(v)) for t, v in zip(self.transforms, theta))

    def out_of_bounds(self, theta, rel_tol: float = 1e-6) -> list[str]:
        """Names of parameters whose value is outside (or on) its prior box."""
        out = []
        for t, v in zip(self.transforms, np.asarray(theta, dtype=float)):
            tol = rel_tol * (t.high - t.low)
            if not (t.low + tol < v < t.high - tol):
                out.append(t.name)
        return out

    def as_dict(self, theta) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, np.asarray(theta, dtype=float))}


def from_u_coefficients(c: dict, u):
    """``ParameterSpace.from_u`` in JAX from the space's :meth:`~ParameterSpace.coefficients`
    (last axis of ``u`` = parameters; differentiable). Each branch's input is kept finite
    where another branch is taken, so that no derivative is a NaN."""
    z = c["centre"] + c["half_width"] * jnp.asarray(u)
    log_value = jnp.exp(jnp.where(c["log"], z, 0.0))
    logit_value = c["a"] + (c["b"] - c["a"]) * jax.nn.sigmoid(z)
    return jnp.where(c["log"], log_value, jnp.where(c["logit"], logit_value, z))


def box_covers(outer: dict, inner: dict, names) -> bool:
    """Whether the box ``outer`` contains ``inner`` for every parameter in ``names``."""

    def inside(n):
        (a, b), (c, d) = outer[n], inner[n]
        tol = 1e-12 * max(abs(a), abs(b), abs(c), abs(d))
        return a <= c + tol and d <= b + tol

    return all(n in outer and n in inner and inside(n) for n in names)
