"""An independent Ritz plate for tests: polynomials, not vibid's finite elements. The deflection relative to the clamp is ``Σ q_mn ξ² P_m(2ξ − 1) P_n(2η − 1)``
(``ξ = x/L``, ``η = y/B``, Legendre polynomials ``P``; ``ξ²`` holds the clamp's zero
displacement and slope), the energies are those of the session format's plate with its
rotary inertia ``ρh h²/12 ∫ ∇u·∇v``, and the sensor is a disc of spread mass (its mass
``m/(π r²)`` over the disc, with the same rotary term), read at its centre; the AFC of base
excitation ``H = 1 + ψ_s·q``, ``(K (1 + iβ) − ω² M) q = ω² M 1``. numpy only, nothing of
vibid's.

Its strip is the paper's (100 x 20 x 1 mm steel, nu = 0, a 1 g sensor of 1 mm radius 10 mm
from the tip, as tests/beam_sessions.py declares it): a sensor off the centre line excites
the torsion modes, which a centred one does not (the exact beam of tests/beam_reference.py
cannot hold them)."""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.polynomial import legendre


def _legendre(n, t):
    """Values, first and second derivatives in t of P_0..P_{n-1}(2t - 1): three (n, len(t))."""
    s = 2 * t - 1
    out = []
    for k in range(n):
        c = np.zeros(k + 1)
        c[k] = 1.0
        out.append(
            (
                legendre.legval(s, c),
                2 * legendre.legval(s, legendre.legder(c)),
                4 * legendre.legval(s, legendre.legder(c, 2)),
            )
        )
    return [np.array(v) for v in zip(*out)]


def _along(n, xi):
    """xi² P_m(2 xi − 1), m < n, and its first two derivatives in xi."""
    p, d1, d2 = _legendre(n, xi)
    return xi**2 * p, 2 * xi * p + xi**2 * d1, 2 * p + 4 * xi * d1 + xi**2 * d2


@functools.lru_cache(maxsize=8)
def matrices(L, B, h, rho, xs, ys, mass, radius, n_x=30, n_y=16, n_quad=64, n_disc=24):
    """(K by modulus name, M, load M·1, probe at the sensor centre) of the Ritz plate."""
    gx, wx = np.polynomial.legendre.leggauss(n_quad)
    xi, wxi = (gx + 1) / 2, wx / 2

    def fields(x, y):
        """Values, first and second derivatives of every basis function at points (x, y)
        in metres: arrays (n_basis, n_points)."""
        out = {k: [] for k in ("f", "x", "y", "xx", "yy", "xy")}
        FX, DX, DDX = _along(n_x, x / L)
        FY, DY, DDY = _legendre(n_y, y / B)
        for fx, dx, ddx in zip(FX, DX, DDX):
            for fy, dy, ddy in zip(FY, DY, DDY):
                out["f"].append(fx * fy)
                out["x"].append(dx * fy / L)
                out["y"].append(fx * dy / B)
                out["xx"].append(ddx * fy / L**2)
                out["yy"].append(fx * ddy / B**2)
                out["xy"].append(dx * dy / (L * B))
        return {k: np.array(v) for k, v in out.items()}

    X, Y = np.meshgrid(xi * L, xi * B, indexing="ij")
    w = (np.outer(wxi, wxi) * L * B).ravel()
    P = fields(X.ravel(), Y.ravel())

    def gram(a, c, weights):
        return (a * weights) @ c.T

    K = {
        "11": gram(P["xx"], P["xx"], w),
        "12": gram(P["xx"], P["yy"], w) + gram(P["yy"], P["xx"], w),
        "22": gram(P["yy"], P["yy"], w),
        "66": 4 * gram(P["xy"], P["xy"], w),
    }
    rho_h = rho * h
    M = rho_h * (
        gram(P["f"], P["f"], w) + h**2 / 12 * (gram(P["x"], P["x"], w) + gram(P["y"], P["y"], w))
    )
    # the disc: Gauss-Legendre in r (area weight r dr) times equal steps in angle
    gr, wr = np.polynomial.legendre.leggauss(n_disc)
    r = (gr + 1) / 2 * radius
    t = np.arange(2 * n_disc) * math.pi / n_disc
    R, T = np.meshgrid(r, t, indexing="ij")
    wd = (np.outer(wr * radius / 2 * r, np.full(t.size, math.pi / n_disc))).ravel()
    Q = fields(xs + (R * np.cos(T)).ravel(), ys + (R * np.sin(T)).ravel())
    density = mass / (math.pi * radius**2)
    M = M + density * (
        gram(Q["f"], Q["f"], wd) + h**2 / 12 * (gram(Q["x"], Q["x"], wd) + gram(Q["y"], Q["y"], wd))
    )
    load = rho_h * (P["f"] @ w) + density * (Q["f"] @ wd)
    probe = fields(np.array([xs]), np.array([ys]))["f"][:, 0]
    return K, M, load, probe


def afc(
    f_hz,
    D,
    nu,
    beta,
    *,
    L=0.100,
    B=0.020,
    h=0.001,
    rho=7920.0,
    xs=0.090,
    ys=0.010,
    mass=1e-3,
    radius=0.001,
    **kw,
):
    """H (complex, per f_hz) of the isotropic Ritz plate, sensor at (xs, ys) m."""
    K, M, load, probe = matrices(L, B, h, rho, xs, ys, mass, radius, **kw)
    Kc = (D * K["11"] + nu * D * K["12"] + D * K["22"] + (1 - nu) * D / 2 * K["66"]) * (
        1 + 1j * beta
    )
    out = []
    for f in np.atleast_1d(f_hz):
        w2 = (2 * math.pi * f) ** 2
        q = np.linalg.solve(Kc - w2 * M, w2 * load)
        out.append(1.0 + probe @ q)
    return np.array(out)


def natural_frequencies_hz(D, nu, n=6, **geometry):
    """The first ``n`` natural frequencies (Hz), base fixed, of the isotropic Ritz plate."""
    import scipy.linalg

    kw = (
        dict(L=0.100, B=0.020, h=0.001, rho=7920.0, xs=0.090, ys=0.010, mass=1e-3, radius=0.001)
        | geometry
    )
    K, M, _, _ = matrices(
        kw["L"], kw["B"], kw["h"], kw["rho"], kw["xs"], kw["ys"], kw["mass"], kw["radius"]
    )
    Kr = D * K["11"] + nu * D * K["12"] + D * K["22"] + (1 - nu) * D / 2 * K["66"]
    lam = scipy.linalg.eigh(Kr, M, eigvals_only=True)[:n]
    return np.sqrt(lam) / (2 * math.pi)
