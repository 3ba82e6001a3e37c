"""Independent reference model for tests: a cantilever beam on a shaker, solved exactly.

numpy/scipy only; never import ``vibid`` here: this module is what ``vibid`` gets checked against.

Model (SI units throughout)
---------------------------
A uniform beam of length ``L`` (m). ``x`` (m) runs along the beam from the clamp line (x = 0)
to the free tip (x = L). ``w(x)`` (m) is the ABSOLUTE transverse displacement, positive in the
direction in which the shaker pushes. Everything is harmonic:
``w(x, t) = Re(w(x) exp(+i omega t))``.

* Bending stiffness ``EI`` (N m^2), may be complex: ``EI (1 + i beta)`` for a loss factor beta.
* Mass per length ``rhoA`` (kg/m); rotary inertia per length ``rhoI`` (kg m): rhoI = 0 is the
  Euler-Bernoulli beam, rhoI > 0 the Rayleigh beam.
* Base (shaker table) motion: the rigid field ``u_b + phi_b x``: translation ``u_b`` (m) and
  rotation ``phi_b`` (rad) about the clamp line. Positive phi_b moves the points at x > 0 in
  the +w direction: phi_b is the base's slope dw/dx.
* Root: ``w(0) = u_b``, and either a rigid clamp ``w'(0) = phi_b`` or a rotational spring
  ``k_root`` (N m/rad, may be complex: k_r (1 + i beta_r)) on the relative slope:
  ``EI w''(0) = k_r (w'(0) - phi_b)``.
* A rigid body (accelerometer) at ``x_s`` (0 < x_s <= L): mass ``m`` (kg) and rotary inertia
  ``J`` (kg m^2, about the axis through the beam's neutral axis at x_s, perpendicular to the
  plane of bending), moving with the beam's ABSOLUTE displacement w(x_s) and slope w'(x_s).

Equations, from Hamilton's principle with the kinetic energy
T = 1/2 int(rhoA w_t^2 + rhoI w_xt^2) dx + 1/2 m w_t(x_s)^2 + 1/2 J w_xt(x_s)^2 and the
potential energy V = 1/2 int EI w_xx^2 dx + 1/2 k_r (w_x(0) - phi_b)^2:

* field equation ``EI w'''' + rhoI omega^2 w'' - rhoA omega^2 w = 0`` (in time:
  EI w'''' + rhoA w_tt - rhoI w_xxtt = 0, and w_tt = -omega^2 w: the rotary-inertia term has
  the sign opposite to the translational one);
* with the bending moment ``M = EI w''`` and the generalised shear
  ``Q = EI w''' + rhoI omega^2 w'``: free tip ``M(L) = 0, Q(L) = 0``; at the body, w and w'
  continuous and
  ``M(x_s+) - M(x_s-) = -J omega^2 w'(x_s)``, ``Q(x_s+) - Q(x_s-) = +m omega^2 w(x_s)``.
  With the body at the tip (x_s = L) the "+" side is zero: ``EI w''(L) = J omega^2 w'(L)`` and
  ``EI w'''(L) + rhoI omega^2 w'(L) + m omega^2 w(L) = 0``.
  Integrated from the tip, these give the bending moment as the moment of the inertia loads
  (d'Alembert forces rhoA omega^2 w per length and m omega^2 w(x_s), couples rhoI omega^2 w'
  per length and J omega^2 w'(x_s)) outboard of x:
  M(x) = int_x^L rhoA omega^2 w(t) (t - x) dt + int_x^L rhoI omega^2 w'(t) dt
  + [x < x_s] (m omega^2 w(x_s) (x_s - x) + J omega^2 w'(x_s)).

Solution: on each segment [0, x_s] and [x_s, L], w is a combination of the four functions
exp(+-k1 xi), exp(+-k2 xi), where k^2 = z are the two roots of
EI z^2 + rhoI omega^2 z - rhoA omega^2 = 0 (z1 ~ +: hyperbolic pair, z2 ~ -: oscillatory pair)
and xi is the coordinate along the segment (length l). They are used as exp(-k xi) and
exp(k (xi - l)) with Re k >= 0, which are bounded by 1 on the segment at any frequency. On a
segment short compared to the wavelength (|k| l <= 1), where these exponentials become nearly
linearly dependent, the basis is instead the four solutions with unit initial derivatives
(B_j^(i)(0) = delta_ij, summed as the Taylor series of the field equation to rounding
accuracy). The 8 x 8 (4 x 4 for x_s = L) system of the root, body and free-end conditions is
solved at each frequency.

Public functions: :func:`afc`, :func:`afc_translation`, :func:`afc_rotation`,
:func:`natural_frequencies_hz`.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

_TAYLOR_TERMS = 48  # series terms for |k| l <= 1 (the terms fall faster than 2^n / n!)
_LAMBDA_STEP = 0.01  # bracketing step in lambda = L (rhoA omega^2 / EI)^(1/4)


def _wavenumber_squares(w2, EI, rhoA, rhoI):
    """The roots z = k^2 (1/m^2) of EI z^2 + rhoI w2 z - rhoA w2 = 0, without cancellation:
    z1 (~ positive, hyperbolic pair) and z2 (~ negative, oscillatory pair)."""
    q = -(rhoI * w2 + np.sqrt((rhoI * w2) ** 2 + 4.0 * EI * rhoA * w2 + 0j)) / 2.0
    return -rhoA * w2 / q, q / EI


def _segment_basis(z1, z2, ell, real):
    """Values at both ends of a segment of length ``ell`` of its four basis functions and of
    their first three x-derivatives: two arrays (N, 4 orders, 4 functions), at xi = 0 and at
    xi = ell. ``real``: the oscillatory pair as cos, sin (a real basis for real parameters)."""
    n = z1.shape[0]
    j = np.arange(4)[None, :]  # derivative order, broadcast over (N, 4)
    ks = np.sqrt(np.stack([z1, z2], axis=-1))  # (N, 2), principal root: Re k >= 0
    far = np.exp(-ks * ell)  # each exponential's value at the end it decays towards
    e0 = np.empty((n, 4, 4), complex)
    e1 = np.empty((n, 4, 4), complex)
    for p in range(2):  # exp(-k xi): derivatives (-k)^j; exp(k (xi - l)): k^j
        k, f = ks[:, p, None], far[:, p, None]
        e0[:, :, 2 * p], e0[:, :, 2 * p + 1] = (-k) ** j, k**j * f
        e1[:, :, 2 * p], e1[:, :, 2 * p + 1] = (-k) ** j * f, k**j
    if real:  # cos(beta xi), sin(beta xi), beta^2 = -z2: d^j/dxi^j = beta^j cos, sin(. + j pi/2)
        beta = np.sqrt(-z2.real)[:, None]
        for xi, out in ((0.0, e0), (ell, e1)):
            out[:, :, 2] = beta**j * np.cos(beta * xi + j * np.pi / 2)
            out[:, :, 3] = beta**j * np.sin(beta * xi + j * np.pi / 2)
    # short segment: B_j(t), t = xi / l, B'''' = -P B'' + Q B, B_j^(i)(0) = delta_ij; series
    # coefficients d[:, j, i] = B_j^(i)(0) from that recurrence
    short = np.max(np.abs(ks), axis=1) * ell <= 1.0
    P = np.where(short, -(z1 + z2) * ell**2, 0.0)[:, None]
    Q = np.where(short, -z1 * z2 * ell**4, 0.0)[:, None]
    d = np.zeros((n, 4, _TAYLOR_TERMS + 3), complex)
    d[:, np.arange(4), np.arange(4)] = 1.0
    for i in range(4, _TAYLOR_TERMS + 3):
        d[:, :, i] = -P * d[:, :, i - 2] + Q * d[:, :, i - 4]
    inv_fact = 1.0 / np.cumprod(np.r_[1.0, np.arange(1.0, _TAYLOR_TERMS)])
    per_x = ell ** -np.arange(4.0)[None, :, None]  # d/dx = (1/l) d/dt
    t0 = np.broadcast_to(np.eye(4), (n, 4, 4)) * per_x
    t1 = np.stack([d[:, :, i : i + _TAYLOR_TERMS] @ inv_fact for i in range(4)], axis=1) * per_x
    s = short[:, None, None]
    return np.where(s, t0, e0), np.where(s, t1, e1)


def _system(omega, u_b, phi_b, *, L, EI, rhoA, rhoI, k_root, x_s, m, J, real=False):
    """The linear system A c = b (A: (N, n, n), b: (N, n)) for the basis coefficients c at each
    omega > 0 (an array), rows scaled to max |entry| = 1, and e (N, n) with w(x_s) = e . c.
    Unknowns: 4 per segment, [0, x_s] first."""
    w2 = omega**2
    z1, z2 = _wavenumber_squares(w2, EI, rhoA, rhoI)
    tip = x_s >= L * (1.0 - 1e-12)  # body at the tip: one segment
    a0, a1 = _segment_basis(z1, z2, x_s, real)  # segment [0, x_s]: at x = 0 and at x = x_s
    n, size = w2.shape[0], 4 if tip else 8
    A = np.zeros((n, size, size), complex)
    b = np.zeros((n, size), complex)
    w2 = w2[:, None]
    left, right = slice(0, 4), slice(4, 8)
    # root: w(0) = u_b and the slope condition
    A[:, 0, left], b[:, 0] = a0[:, 0], u_b
    if k_root is None:
        A[:, 1, left], b[:, 1] = a0[:, 1], phi_b
    else:  # EI w''(0) - k_r w'(0) = -k_r phi_b
        A[:, 1, left], b[:, 1] = EI * a0[:, 2] - k_root * a0[:, 1], -k_root * phi_b
    # body: M(x_s+) - M(x_s-) + J w2 w'(x_s) = 0 and Q(x_s+) - Q(x_s-) - m w2 w(x_s) = 0,
    # M = EI w'', Q = EI w''' + rhoI w2 w'; the "+" side terms are absent for x_s = L
    A[:, 2, left] = -EI * a1[:, 2] + J * w2 * a1[:, 1]
    A[:, 3, left] = -(EI * a1[:, 3] + rhoI * w2 * a1[:, 1]) - m * w2 * a1[:, 0]
    if not tip:
        c0, c1 = _segment_basis(z1, z2, L - x_s, real)  # segment [x_s, L]: at x_s and at L
        A[:, 2, right] = EI * c0[:, 2]
        A[:, 3, right] = EI * c0[:, 3] + rhoI * w2 * c0[:, 1]
        for row, order in ((4, 0), (5, 1)):  # w, w' continuous at x_s
            A[:, row, left], A[:, row, right] = a1[:, order], -c0[:, order]
        A[:, 6, right] = EI * c1[:, 2]  # free end: M(L) = 0
        A[:, 7, right] = EI * c1[:, 3] + rhoI * w2 * c1[:, 1]  # and Q(L) = 0
    scale = np.abs(A).max(axis=2)
    e = np.zeros((n, size), complex)
    e[:, left] = a1[:, 0]
    return A / scale[:, :, None], b / scale, e


def _solve(omega, u_b, phi_b, *, L, EI, rhoA, rhoI=0.0, k_root=None, x_s, m=0.0, J=0.0):
    """w(x_s) (m) for the base motion (u_b (m), phi_b (rad)), scalars or arrays over omega."""
    omega = np.asarray(omega, float)
    if np.any(omega < 0) or not 0 < x_s <= L:
        raise ValueError("need omega >= 0 and 0 < x_s <= L")
    flat = omega.reshape(-1)
    u_b, phi_b = (
        np.broadcast_to(np.asarray(v, complex), omega.shape).reshape(-1) for v in (u_b, phi_b)
    )
    out = u_b + phi_b * x_s  # omega = 0: the base's rigid motion
    live = flat > 0
    if live.any():
        A, b, e = _system(
            flat[live],
            u_b[live],
            phi_b[live],
            L=L,
            EI=EI,
            rhoA=rhoA,
            rhoI=rhoI,
            k_root=k_root,
            x_s=x_s,
            m=m,
            J=J,
        )
        out[live] = np.einsum("ni,ni->n", e, np.linalg.solve(A, b[..., None])[..., 0])
    return out.reshape(omega.shape)


def afc(
    omega, *, L, EI, rhoA, rhoI=0.0, k_root=None, x_s, m=0.0, J=0.0, rotation_per_translation=0.0
):
    """H(omega) = w(x_s) / u_b: absolute displacement (= acceleration) at the body per base
    translation, the base rotating at the same time by phi_b = rotation_per_translation * u_b.

    omega: rad/s (>= 0), any shape. L, x_s: m; EI: N m^2 (complex allowed); rhoA: kg/m;
    rhoI: kg m; k_root: N m/rad (complex allowed), None = rigid clamp; m: kg; J: kg m^2;
    rotation_per_translation: phi_b / u_b in rad/m, complex, scalar or broadcastable to omega.
    Returns a complex array of omega's shape (dimensionless)."""
    return _solve(
        omega,
        1.0,
        rotation_per_translation,
        L=L,
        EI=EI,
        rhoA=rhoA,
        rhoI=rhoI,
        k_root=k_root,
        x_s=x_s,
        m=m,
        J=J,
    )


def afc_translation(omega, *, L, EI, rhoA, rhoI=0.0, k_root=None, x_s, m=0.0, J=0.0):
    """w(x_s) / u_b for a pure base translation (phi_b = 0); dimensionless, -> 1 as omega -> 0.
    Arguments as :func:`afc`."""
    return _solve(
        omega, 1.0, 0.0, L=L, EI=EI, rhoA=rhoA, rhoI=rhoI, k_root=k_root, x_s=x_s, m=m, J=J
    )


def afc_rotation(omega, *, L, EI, rhoA, rhoI=0.0, k_root=None, x_s, m=0.0, J=0.0):
    """w(x_s) / phi_b (m/rad) for a pure base rotation about the clamp line (u_b = 0);
    -> x_s as omega -> 0. Arguments as :func:`afc`. By linearity
    afc = afc_translation + rotation_per_translation * afc_rotation."""
    return _solve(
        omega, 0.0, 1.0, L=L, EI=EI, rhoA=rhoA, rhoI=rhoI, k_root=k_root, x_s=x_s, m=m, J=J
    )


def natural_frequencies_hz(n, *, L, EI, rhoA, rhoI=0.0, k_root=None, x_s, m=0.0, J=0.0):
    """The first ``n`` undamped natural frequencies (Hz) of the beam, base held fixed.

    Real parameters only (units as in :func:`afc`). They are the roots of the determinant of
    the system written in a real basis, bracketed on a grid of step 0.01 in
    lambda = L (rhoA omega^2 / EI)^(1/4) (the clamped beam's roots are ~pi apart) and refined
    with brentq; two roots closer than the step would be missed. The determinant's sign is
    consistent where the basis of a segment switches (exponential <-> series): both bases have
    a positive Wronskian (for the exponential one, 2 a b (a^2 + b^2)^2 exp(-a l) with
    k1 = a, k2 = i b)."""
    if np.iscomplexobj(EI) or np.iscomplexobj(k_root):
        raise ValueError("natural frequencies need real EI and k_root")
    beam = dict(L=L, EI=EI, rhoA=rhoA, rhoI=rhoI, k_root=k_root, x_s=x_s, m=m, J=J)

    def omega_of(lam):
        return lam**2 * np.sqrt(EI / (rhoA * L**4))

    def det(lam):
        A = _system(np.atleast_1d(omega_of(lam)), 0.0, 0.0, real=True, **beam)[0]
        return np.linalg.det(A.real)

    roots, start = [], _LAMBDA_STEP / 2
    while len(roots) < n:
        lam = start + _LAMBDA_STEP * np.arange(1001)
        d = det(lam)
        for i in np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)[: n - len(roots)]:
            roots.append(brentq(lambda s: det(s)[0], lam[i], lam[i + 1], xtol=1e-300, rtol=1e-15))
        start = lam[-1]
    return omega_of(np.array(roots)) / (2 * np.pi)
