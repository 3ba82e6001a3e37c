"""Independent reference model for tests: a cantilever TIMOSHENKO beam on a shaker, solved
exactly (shear deformation and rotary inertia).

numpy/scipy only; never import ``vibid`` here: this module is what ``vibid`` gets checked against.
It follows the conventions of the Rayleigh-beam reference ``tests/beam_reference.py``, which it
becomes when the shear stiffness grows without bound (psi -> w').

Model (SI units throughout)
---------------------------
A uniform beam of length ``L`` (m). ``x`` (m) runs along the beam from the clamp line (x = 0)
to the free tip (x = L). Two fields: ``w(x)`` (m), the ABSOLUTE transverse displacement,
positive in the direction in which the shaker pushes, and ``psi(x)`` (rad), the rotation of the
cross-section, positive when it turns the way a positive slope dw/dx does (psi = w' without
shear). Everything is harmonic: ``w(x, t) = Re(w(x) exp(+i omega t))``, likewise psi.

* Bending stiffness ``EI`` (N m^2) and shear stiffness ``kGA`` (N, kappa G A with the shear
  coefficient kappa), either may be complex: ``EI (1 + i beta)`` for a loss factor beta.
* Mass per length ``rhoA`` (kg/m); rotary inertia per length ``rhoI`` (kg m).
* Base (shaker table) motion: pure translation ``u_b`` (m), no rotation.
* Root: ``w(0) = u_b``, and either a rigid clamp ``psi(0) = 0`` or a rotational spring
  ``k_root`` (N m/rad, may be complex) on the cross-section's rotation:
  ``EI psi'(0) = k_root psi(0)``.
* A rigid body (accelerometer) at ``x_s`` (0 < x_s <= L): mass ``m`` (kg) and rotary inertia
  ``J`` (kg m^2, about the axis through the beam's neutral axis at x_s, perpendicular to the
  plane of bending), moving with the beam's ABSOLUTE displacement w(x_s) and its
  cross-section rotation psi(x_s).

Equations, from Hamilton's principle with the kinetic energy
T = 1/2 int(rhoA w_t^2 + rhoI psi_t^2) dx + 1/2 m w_t(x_s)^2 + 1/2 J psi_t(x_s)^2 and the
potential energy V = 1/2 int(EI psi_x^2 + kGA (w_x - psi)^2) dx + 1/2 k_root psi(0)^2:

* field equations (w_tt = -omega^2 w, psi_tt = -omega^2 psi)
  ``kGA (w' - psi)' + rhoA omega^2 w = 0`` and
  ``EI psi'' + kGA (w' - psi) + rhoI omega^2 psi = 0``;
* with the bending moment ``M = EI psi'`` and the shear force ``V = kGA (w' - psi)`` (so that
  ``M' = -V - rhoI omega^2 psi``, ``V' = -rhoA omega^2 w``): free tip ``M(L) = 0, V(L) = 0``;
  at the body, w and psi continuous and
  ``M(x_s+) - M(x_s-) = -J omega^2 psi(x_s)``, ``V(x_s+) - V(x_s-) = -m omega^2 w(x_s)``
  (the boundary terms -[M dpsi + V dw] of the variation of V, taken on both sides of x_s, plus
  the body's J omega^2 psi dpsi + m omega^2 w dw from the variation of T).
  With the body at the tip (x_s = L) the "+" side is zero: ``EI psi'(L) = J omega^2 psi(L)``
  and ``kGA (w'(L) - psi(L)) = m omega^2 w(L)``. In d'Alembert's terms: the shear force just
  inboard of the body carries its inertia force m omega^2 w(x_s) (and all inertia forces
  outboard: V(x) = int_x^L rhoA omega^2 w dt + [x < x_s] m omega^2 w(x_s)), the moment its
  inertia couple. In the shear-rigid limit psi = w', V = -Q with beam_reference's generalised
  shear Q = EI w''' + rhoI omega^2 w': the same jumps as there.

Solution: the state y = (w, psi, M, V) obeys y' = A(omega) y with the constant matrix
A = [[0, 1, 0, 1/kGA], [0, 0, 1/EI, 0], [0, -rhoI omega^2, 0, -1], [-rhoA omega^2, 0, 0, 0]].
Its eigenvalues lambda = +-sqrt(z), z the roots of
EI z^2 + (rhoI + EI rhoA / kGA) omega^2 z + rhoA omega^2 (rhoI omega^2 / kGA - 1) = 0,
grow with frequency, and a transfer matrix over a length l has entries up to exp(|lambda| l):
a single transfer matrix over the whole beam would lose that factor to cancellation. So the
beam is cut into sub-segments of length ell <= L / n with |lambda|max ell <= 1 (n = 1 at low
frequency; the body's point x_s is always a cut), and the sub-segments are joined by multiple
shooting: the unknowns are the states at all cuts, the equations the root conditions,
y_{i+1} = expm(A l_i) y_i on each sub-segment, the body's jump, and the tip conditions. This
system is as well conditioned as the boundary-value problem itself (it is singular exactly at
the natural frequencies). The state is scaled, (w / ell, psi, M ell / |EI|, V ell^2 / |EI|),
and x by ell, which keeps the entries of the scaled A of order 1 or below for slender beams.
scipy.linalg.expm computes each sub-segment's matrix (norm ~1: accurate to rounding).

Public functions: :func:`afc`, :func:`natural_frequencies_hz`.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm
from scipy.optimize import brentq

_STEP = 1.0  # the largest |lambda| * ell of a sub-segment (transfer-matrix entries <= ~e)
_LAMBDA_STEP = 0.01  # bracketing step in lambda = L (rhoA omega^2 / EI)^(1/4)


def _largest_exponent(w2, EI, kGA, rhoA, rhoI):
    """The largest |lambda| (1/m) of the four solutions exp(lambda x) at omega^2 = w2 (array)."""
    b = (rhoI + EI * rhoA / kGA) * w2
    c = rhoA * w2 * (rhoI * w2 / kGA - 1.0)
    disc = np.sqrt(b * b - 4.0 * EI * c + 0j)
    z = np.abs(np.stack([-b + disc, -b - disc])) / (2.0 * abs(EI))
    return np.sqrt(z.max(axis=0))


def _pieces(n, L, x_s):
    """Sub-segment counts (n1 on [0, x_s], n2 on [x_s, L]; n2 = 0 for a body at the tip) when
    the sub-segments are at most ell = L / n long."""
    tip = x_s >= L * (1.0 - 1e-12)
    n1 = max(1, int(np.ceil(x_s / L * n - 1e-9)))
    n2 = 0 if tip else max(1, int(np.ceil((L - x_s) / L * n - 1e-9)))
    return n1, n2


def _cuts(omega, L, EI, kGA, rhoA, rhoI):
    """n per frequency: the beam's sub-segments are at most L / n long."""
    rho = _largest_exponent(omega**2, EI, kGA, rhoA, rhoI)
    return np.maximum(1, np.ceil(rho * L / _STEP - 1e-9)).astype(int)


def _system(omega, n, *, L, EI, kGA, rhoA, rhoI, x_s, m, J, k_root, u_b=1.0):
    """The multiple-shooting system G u = r (G: (N, size, size), r: (N, size)) at the
    frequencies ``omega`` (array, rad/s) for the common cut number ``n``, rows scaled to
    max |entry| = 1, and the index of the scaled w(x_s) in u with its factor ell
    (w(x_s) = ell u[idx]). Unknowns: the scaled states at the cuts of [0, x_s] (n1 + 1 of them,
    the last at x_s-), then those of [x_s, L] (n2 + 1, the first at x_s+)."""
    n1, n2 = _pieces(n, L, x_s)
    ell = L / n
    E0 = abs(EI)
    w2 = omega**2
    N = w2.shape[0]
    # the scaled A: d/d(x / ell) of (w / ell, psi, M ell / E0, V ell^2 / E0)
    A = np.zeros((N, 4, 4), complex)
    A[:, 0, 1] = 1.0
    A[:, 0, 3] = E0 / (kGA * ell**2)
    A[:, 1, 2] = E0 / EI
    A[:, 2, 1] = -rhoI * w2 * ell**2 / E0
    A[:, 2, 3] = -1.0
    A[:, 3, 0] = -rhoA * w2 * ell**4 / E0
    T1 = expm(A * (x_s / n1 / ell))
    T2 = expm(A * ((L - x_s) / n2 / ell)) if n2 else None
    # the body's jump y(x_s+) = P y(x_s-): M -= J w2 psi, V -= m w2 w (scaled)
    P = np.broadcast_to(np.eye(4, dtype=complex), (N, 4, 4)).copy()
    P[:, 2, 1] = -J * w2 * ell / E0
    P[:, 3, 0] = -m * w2 * ell**3 / E0
    size = 4 * (n1 + 1) + 4 * (n2 + 1)
    G = np.zeros((N, size, size), complex)
    r = np.zeros((N, size), complex)
    eye = np.eye(4)
    first = 4 * (n1 + 1)  # column of the state at x_s+
    # root: w(0) = u_b, and psi(0) = 0 or M(0) - k_root psi(0) = 0
    G[:, 0, 0], r[:, 0] = ell, u_b
    if k_root is None:
        G[:, 1, 1] = 1.0
    else:
        G[:, 1, 2], G[:, 1, 1] = E0 / ell, -k_root
    row = 2
    for i in range(n1):  # y_{i+1} - T1 y_i = 0
        G[:, row : row + 4, 4 * (i + 1) : 4 * (i + 2)] = eye
        G[:, row : row + 4, 4 * i : 4 * (i + 1)] = -T1
        row += 4
    G[:, row : row + 4, first : first + 4] = eye  # y(x_s+) - P y(x_s-) = 0
    G[:, row : row + 4, 4 * n1 : 4 * (n1 + 1)] = -P
    row += 4
    for j in range(n2):
        c = first + 4 * j
        G[:, row : row + 4, c + 4 : c + 8] = eye
        G[:, row : row + 4, c : c + 4] = -T2
        row += 4
    end = first + 4 * n2  # state at L (at x_s+ = L+ for a body at the tip)
    G[:, row, end + 2] = 1.0  # M(L) = 0
    G[:, row + 1, end + 3] = 1.0  # V(L) = 0
    scale = np.abs(G).max(axis=2)
    return G / scale[:, :, None], r / scale, 4 * n1, ell


def _check(omega, L, x_s):
    if np.any(omega < 0) or not 0 < x_s <= L:
        raise ValueError("need omega >= 0 and 0 < x_s <= L")


def afc(omega, *, L, EI, kGA, rhoA, rhoI, x_s, m=0.0, J=0.0, k_root=None):
    """H(omega) = w(x_s) / u_b: absolute displacement (= acceleration) at the body per base
    translation (the base does not rotate).

    omega: rad/s (>= 0, omega = 0 allowed: H = 1), any shape. L, x_s: m (0 < x_s <= L);
    EI: N m^2, kGA: N (kappa G A), both complex allowed; rhoA: kg/m; rhoI: kg m; m: kg;
    J: kg m^2; k_root: N m/rad (complex allowed), None = rigid clamp.
    Returns a complex array of omega's shape (dimensionless)."""
    omega = np.asarray(omega, float)
    _check(omega, L, x_s)
    flat = omega.reshape(-1)
    out = np.empty(flat.shape, complex)
    beam = dict(L=L, EI=EI, kGA=kGA, rhoA=rhoA, rhoI=rhoI, x_s=x_s, m=m, J=J, k_root=k_root)
    cuts = _cuts(flat, L, EI, kGA, rhoA, rhoI)
    for n in np.unique(cuts):
        sel = cuts == n
        G, r, idx, ell = _system(flat[sel], int(n), **beam)
        out[sel] = ell * np.linalg.solve(G, r[..., None])[:, idx, 0]
    return out.reshape(omega.shape)


def natural_frequencies_hz(n, *, L, EI, kGA, rhoA, rhoI, x_s=None, m=0.0, J=0.0, k_root=None):
    """The first ``n`` undamped natural frequencies (Hz) of the beam, base held fixed.

    Real parameters only (units as in :func:`afc`; x_s defaults to L, which matters only with
    a body). They are the roots of the determinant of the multiple-shooting system with
    u_b = 0 (real for real parameters), bracketed on a grid of step 0.01 in
    lambda = L (rhoA omega^2 / EI)^(1/4) and refined with brentq; two roots closer than the
    step would be missed. Each block of 1000 grid steps uses one fixed set of cuts (the one
    its highest frequency needs), so the determinant is continuous within the block; the
    blocks share their end points."""
    if any(np.iscomplexobj(v) for v in (EI, kGA, k_root)):
        raise ValueError("natural frequencies need real EI, kGA and k_root")
    x_s = L if x_s is None else x_s
    _check(np.zeros(1), L, x_s)
    beam = dict(L=L, EI=EI, kGA=kGA, rhoA=rhoA, rhoI=rhoI, x_s=x_s, m=m, J=J, k_root=k_root)

    def omega_of(lam):
        return lam**2 * np.sqrt(EI / (rhoA * L**4))

    def det(lam, cuts):
        G = _system(np.atleast_1d(omega_of(lam)), cuts, u_b=0.0, **beam)[0]
        return np.linalg.det(G.real)

    roots, start = [], _LAMBDA_STEP / 2
    while len(roots) < n:
        lam = start + _LAMBDA_STEP * np.arange(1001)
        cuts = int(_cuts(omega_of(lam[-1:]), L, EI, kGA, rhoA, rhoI)[0])
        d = det(lam, cuts)
        for i in np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)[: n - len(roots)]:
            roots.append(
                brentq(lambda s: det(s, cuts)[0], lam[i], lam[i + 1], xtol=1e-300, rtol=1e-15)
            )
        start = lam[-1]
    return omega_of(np.array(roots)) / (2 * np.pi)
