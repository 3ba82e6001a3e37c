"""Checks of the reference beam model (tests/beam_reference.py) against independent results:
classical frequency equations, a Hermite-cubic finite-element beam written here, static beam
theory for the low-frequency limit, and a one-mode approximation for damping."""

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.linalg import eigh
from scipy.optimize import brentq, minimize_scalar

import beam_reference as br

# a steel-like strip: 200 mm x 20 mm x 1 mm
L, EI, RHOA = 0.2, 0.333, 0.157
OMEGA_UNIT = np.sqrt(EI / (RHOA * L**4))  # omega = lambda^2 * OMEGA_UNIT
CLAMPED_LAMBDA = [1.875104068711961, 4.694091132974175, 7.854757438237613]


def lambdas(f_hz):
    return np.sqrt(2 * np.pi * np.asarray(f_hz) / OMEGA_UNIT)


def roots_in_lambda(f, n, lam_max=30.0, step=1e-3):
    """The first n sign changes of f(lambda) on a grid, refined with brentq."""
    grid = np.arange(step, lam_max, step)
    values = np.array([f(x) for x in grid])
    idx = np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))[:n]
    assert len(idx) == n
    return np.array([brentq(f, grid[i], grid[i + 1], xtol=1e-15) for i in idx])


# ---------------------------------------------------------------- finite-element beam
def _hermite(s, h):
    """Hermite cubics on an element of length h at s = xi / h: (N, N', N'') x 4 dofs
    (w_left, slope_left, w_right, slope_right)."""
    n = [1 - 3 * s**2 + 2 * s**3, h * (s - 2 * s**2 + s**3), 3 * s**2 - 2 * s**3, h * (s**3 - s**2)]
    d1 = [(6 * s**2 - 6 * s) / h, 1 - 4 * s + 3 * s**2, (6 * s - 6 * s**2) / h, 3 * s**2 - 2 * s]
    d2 = [(12 * s - 6) / h**2, (6 * s - 4) / h, (6 - 12 * s) / h**2, (6 * s - 2) / h]
    return np.array(n), np.array(d1), np.array(d2)


def fe_beam(*, EI, rhoA, rhoI=0.0, x_s, m=0.0, J=0.0, n_el=120):
    """Stiffness and consistent mass matrices of the whole beam (dofs
    w_i, w'_i at the nodes x_i = i L / n_el, root included), element integrals by 4-point
    Gauss (exact for these polynomials); rotary inertia rhoI int w' v'; the body as nodal m, J
    at x_s (which must be a node). Returns K, M, the body's node index, the node coordinates.
    n_el = 120: the discretisation error is < 1e-7 up to the 4th mode; more elements make the
    dense solves worse (K's condition number grows as n_el^4: ~1e-7 rounding at 200)."""
    h = L / n_el
    gx, gw = np.polynomial.legendre.leggauss(4)
    ke, me = np.zeros((4, 4), complex), np.zeros((4, 4))
    for s, wt in zip((gx + 1) / 2, gw * h / 2):
        n, d1, d2 = _hermite(s, h)
        ke += wt * EI * np.outer(d2, d2)
        me += wt * (rhoA * np.outer(n, n) + rhoI * np.outer(d1, d1))
    size = 2 * (n_el + 1)
    K, M = np.zeros((size, size), complex), np.zeros((size, size))
    for e in range(n_el):
        K[2 * e : 2 * e + 4, 2 * e : 2 * e + 4] += ke
        M[2 * e : 2 * e + 4, 2 * e : 2 * e + 4] += me
    node = round(x_s / h)
    assert abs(node * h - x_s) < 1e-12
    M[2 * node, 2 * node] += m
    M[2 * node + 1, 2 * node + 1] += J
    return K, M, node, np.linspace(0.0, L, n_el + 1)


def _free(K, k_root):
    """Relative dofs: w_0 = 0 always; the root slope is fixed (clamp) or on the spring."""
    K = K.copy()
    if k_root is None:
        return K, np.arange(2, K.shape[0])
    K[1, 1] += k_root
    return K, np.arange(1, K.shape[0])


def fe_frequencies_hz(n, *, k_root=None, **beam):
    K, M, _, _ = fe_beam(**beam)
    K, f = _free(K, k_root)
    # as 1 / omega^2 (largest first): the lowest modes to rounding, whatever K's conditioning
    inv = eigh(M[np.ix_(f, f)], K[np.ix_(f, f)].real, eigvals_only=True)[::-1][:n]
    return 1 / np.sqrt(inv) / (2 * np.pi)


def fe_afc(omega, *, rotation, k_root=None, **beam):
    """Absolute w(x_s) per unit base translation (rotation=False) or rotation (True), in the
    relative formulation (K - omega^2 M) q = omega^2 M r, r the base's rigid field."""
    K, M, node, x = fe_beam(**beam)
    K, f = _free(K, k_root)
    r = np.zeros(K.shape[0])
    r[0::2], r[1::2] = (x, 1.0) if rotation else (1.0, 0.0)
    out = []
    for w in np.atleast_1d(omega):
        q = np.zeros(K.shape[0], complex)
        q[f] = np.linalg.solve(K[np.ix_(f, f)] - w**2 * M[np.ix_(f, f)], w**2 * (M @ r)[f])
        out.append(r[2 * node] + q[2 * node])
    return np.array(out)


def static_slope(*, rhoI=0.0, k_root=None, x_s, m=0.0, J=0.0, rotation, **_):
    """d w(x_s) / d(omega^2) at omega = 0 (m s^2 per unit base motion), by beam statics: the
    inertia loads of the base's rigid motion r = 1 (or r = x for a rotation) -- rhoA r per
    length, m r(x_s) at x_s, couples rhoI r' per length and J r' at x_s, all per omega^2 --
    bend the cantilever with the moment M(x) = int_x^L rhoA r(t) (t - x) dt
    + rhoI r' (L - x) + [x < x_s] (m r(x_s) (x_s - x) + J r'); w'' = M / EI, the root turns by
    M(0) / k_root."""
    r = (lambda t: t) if rotation else (lambda t: 1.0)
    dr = 1.0 if rotation else 0.0

    def moment(x):
        dist = quad(lambda t: RHOA * r(t) * (t - x), x, L, epsabs=0, epsrel=1e-13)[0]
        return dist + rhoI * dr * (L - x) + ((m * r(x_s) * (x_s - x) + J * dr) if x < x_s else 0.0)

    bend = quad(lambda x: (x_s - x) * moment(x) / EI, 0.0, x_s, epsabs=0, epsrel=1e-13)[0]
    return bend + (0.0 if k_root is None else moment(0.0) / k_root * x_s)


# ---------------------------------------------------------------- 1: clamped, Euler-Bernoulli
def test_clamped_frequencies_match_the_classical_roots():
    f = br.natural_frequencies_hz(3, L=L, EI=EI, rhoA=RHOA, x_s=L)
    expected = np.array(CLAMPED_LAMBDA) ** 2 * OMEGA_UNIT / (2 * np.pi)
    np.testing.assert_allclose(f, expected, rtol=1e-8)


def test_clamped_frequencies_to_the_tenth_mode_wherever_the_split_is():
    """Roots of 1 + cos(lambda) cosh(lambda) = 0 (written cos + 1/cosh), modes 1..10; a point
    x_s without a body must not change anything (it only splits the beam in two segments)."""
    centre = (np.arange(1, 11) - 0.5) * np.pi
    ref = [brentq(lambda s: np.cos(s) + 1 / np.cosh(s), c - 1, c + 1, xtol=1e-15) for c in centre]
    for x_s in (L, 0.7 * L, 0.05 * L):
        f = br.natural_frequencies_hz(10, L=L, EI=EI, rhoA=RHOA, x_s=x_s)
        np.testing.assert_allclose(lambdas(f), ref, rtol=1e-10)


def test_tip_response_to_the_tenth_mode_matches_the_closed_form():
    """Euler-Bernoulli, clamped, sensor at the tip: w(L)/u_b = (cosh + cos) / (1 + cos cosh)
    and w(L)/phi_b = (sinh + sin) / (k (1 + cos cosh)) at lambda = k L (the 4 x 4 system of
    the classical solution w = A cosh kx + B sinh kx + C cos kx + D sin kx, solved by hand);
    checked between the resonances up to lambda = 33 (past the 10th mode)."""
    lam = np.linspace(0.05, 33.0, 661)
    lam = lam[np.abs(1 + np.cos(lam) * np.cosh(lam)) > 0.05 * np.cosh(lam)]
    omega, k = lam**2 * OMEGA_UNIT, lam / L
    ch, c, sh, s = np.cosh(lam), np.cos(lam), np.sinh(lam), np.sin(lam)
    beam = dict(L=L, EI=EI, rhoA=RHOA, x_s=L)
    np.testing.assert_allclose(
        br.afc_translation(omega, **beam), (ch + c) / (1 + c * ch), rtol=1e-10
    )
    np.testing.assert_allclose(
        br.afc_rotation(omega, **beam), (sh + s) / (k * (1 + c * ch)), rtol=1e-10
    )


# ---------------------------------------------------------------- 2: root spring
def _spring_det(K):
    def det(s):
        ch, sh, c, sn = np.cosh(s), np.sinh(s), np.cos(s), np.sin(s)
        return np.linalg.det([[ch + c, sh, -sn], [sh - sn, ch, -c], [2 * s, -K, -K]])

    return det


@pytest.mark.parametrize("K", [0.5, 5.0, 50.0])
def test_root_spring_frequencies_match_the_frequency_equation(K):
    expected = roots_in_lambda(_spring_det(K), 3, lam_max=9.0)
    f = br.natural_frequencies_hz(3, L=L, EI=EI, rhoA=RHOA, k_root=K * EI / L, x_s=0.6 * L)
    np.testing.assert_allclose(lambdas(f), expected, rtol=1e-8)


def test_a_very_stiff_root_spring_is_a_clamp():
    f = br.natural_frequencies_hz(3, L=L, EI=EI, rhoA=RHOA, k_root=1e10 * EI / L, x_s=L)
    np.testing.assert_allclose(lambdas(f), CLAMPED_LAMBDA, rtol=1e-8)


# ---------------------------------------------------------------- 3: tip mass
@pytest.mark.parametrize("mu", [0.1, 1.0])
def test_tip_mass_frequencies_match_the_frequency_equation(mu):
    def eq(s):
        ch, sh, c, sn = np.cosh(s), np.sinh(s), np.cos(s), np.sin(s)
        return (1 + c * ch + mu * s * (c * sh - sn * ch)) / ch

    expected = roots_in_lambda(eq, 3, lam_max=9.0)
    f = br.natural_frequencies_hz(3, L=L, EI=EI, rhoA=RHOA, x_s=L, m=mu * RHOA * L)
    np.testing.assert_allclose(lambdas(f), expected, rtol=1e-8)


# ---------------------------------------------------------------- 4: finite-element beam
def test_the_fe_beam_itself_reproduces_the_clamped_roots():
    f = fe_frequencies_hz(3, EI=EI, rhoA=RHOA, x_s=L)
    np.testing.assert_allclose(lambdas(f), CLAMPED_LAMBDA, rtol=1e-7)


@pytest.mark.parametrize("m", [0.0, 0.3 * RHOA * L])
def test_tip_rotary_inertia_frequencies_match_fe(m):
    beam = dict(EI=EI, rhoA=RHOA, x_s=L, m=m, J=0.02 * RHOA * L**3)
    f = br.natural_frequencies_hz(3, L=L, **beam)
    np.testing.assert_allclose(f, fe_frequencies_hz(3, **beam), rtol=1e-6)
    # J matters here: far more than the tolerance
    without_j = br.natural_frequencies_hz(3, L=L, EI=EI, rhoA=RHOA, x_s=L, m=m)
    assert np.all(np.abs(f / without_j - 1) > 1e-3)


FORCED_CASES = {
    "tip body, lossy EI, clamp": dict(
        EI=EI * (1 + 0.02j), rhoA=RHOA, x_s=L, m=0.2 * RHOA * L, J=0.01 * RHOA * L**3
    ),
    "inner body, Rayleigh, lossy spring": dict(
        EI=EI * (1 + 0.01j),
        rhoA=RHOA,
        rhoI=RHOA * (L / 30) ** 2,
        k_root=5 * EI / L * (1 + 0.1j),
        x_s=0.7 * L,
        m=0.1 * RHOA * L,
        J=0.02 * RHOA * L**3,
    ),
    "inner body, Rayleigh, clamp, undamped": dict(
        EI=EI,
        rhoA=RHOA,
        rhoI=RHOA * (L / 20) ** 2,
        x_s=0.35 * L,
        m=0.5 * RHOA * L,
        J=0.005 * RHOA * L**3,
    ),
}


@pytest.mark.parametrize("name", FORCED_CASES)
@pytest.mark.parametrize("rotation", [False, True])
def test_forced_response_matches_fe(name, rotation):
    beam = FORCED_CASES[name]
    real = {k: (v.real if isinstance(v, complex) else v) for k, v in beam.items()}
    f = br.natural_frequencies_hz(4, L=L, **real)
    omega = 2 * np.pi * np.r_[0.5 * f[0], np.sqrt(f[:-1] * f[1:]), 1.3 * f[-1]]
    fn = br.afc_rotation if rotation else br.afc_translation
    h = fn(omega, L=L, **beam)
    np.testing.assert_allclose(h, fe_afc(omega, rotation=rotation, **beam), rtol=1e-6)


# ---------------------------------------------------------------- 5: limits, linearity
LIMIT_CASES = [
    dict(EI=EI, rhoA=RHOA, x_s=L),
    dict(EI=EI, rhoA=RHOA, x_s=L, m=RHOA * L, J=0.02 * RHOA * L**3),
    dict(
        EI=EI,
        rhoA=RHOA,
        rhoI=RHOA * (L / 20) ** 2,
        k_root=3 * EI / L,
        x_s=0.7 * L,
        m=0.3 * RHOA * L,
        J=0.02 * RHOA * L**3,
    ),
]


@pytest.mark.parametrize("beam", LIMIT_CASES)
def test_low_frequency_limit_is_the_base_motion_plus_static_inertia_loads(beam):
    w1 = 2 * np.pi * br.natural_frequencies_hz(1, L=L, **beam)[0]
    x_s = beam["x_s"]
    for rotation, rigid, fn in ((False, 1.0, br.afc_translation), (True, x_s, br.afc_rotation)):
        assert fn(0.0, L=L, **beam) == rigid
        slope = static_slope(rotation=rotation, **beam)
        # at 1e-4 of the first mode: H = rigid + omega^2 slope, to 1e-9 (slope term ~1e-8)
        w = 1e-4 * w1
        h = fn(w, L=L, **beam)
        assert abs(h - rigid) / abs(rigid) < 1e-7
        assert abs(h - (rigid + w**2 * slope)) / abs(rigid) < 1e-9
        # at 1e-3 of the first mode the omega^2 coefficient itself, to 1e-5
        w = 1e-3 * w1
        h = fn(w, L=L, **beam)
        assert abs((h - rigid) / w**2 / slope - 1) < 1e-5


def test_combined_base_motion_is_the_sum_of_translation_and_rotation():
    beam = LIMIT_CASES[2] | dict(EI=EI * (1 + 0.03j))
    f3 = br.natural_frequencies_hz(3, L=L, **LIMIT_CASES[2])[-1]
    omega = np.linspace(0.0, 2 * np.pi * 3 * f3, 37)
    phi = (0.7 - 2.0j) * np.cos(omega / omega[-1] * 5)  # rad/m, varying over omega
    h = br.afc(omega, L=L, rotation_per_translation=phi, **beam)
    expected = br.afc_translation(omega, L=L, **beam) + phi * br.afc_rotation(omega, L=L, **beam)
    np.testing.assert_allclose(h, expected, rtol=1e-12, atol=1e-14)
    scalar = br.afc(omega, L=L, rotation_per_translation=0.4, **beam)
    np.testing.assert_allclose(
        scalar, expected + (0.4 - phi) * br.afc_rotation(omega, L=L, **beam), rtol=1e-12, atol=1e-14
    )


# ---------------------------------------------------------------- 6: loss factor
def test_loss_factor_resonance_matches_one_mode_approximation():
    """EI (1 + i beta), clamped, sensor at the tip. Near mode 1, H ~ 1 + phi(L) G w^2 /
    (w1^2 (1 + i beta) - w^2) with phi the mode shape and G = int phi / int phi^2 its
    participation: |H| peaks at w1 sqrt(1 + beta^2) with phi(L) G sqrt(1 + beta^2) / beta, and
    H(w1) ~ 1 - i phi(L) G / beta, i.e. a phase of about -90 degrees."""
    beta, lam = 0.01, CLAMPED_LAMBDA[0]
    sigma = (np.cosh(lam) + np.cos(lam)) / (np.sinh(lam) + np.sin(lam))

    def phi(x):
        s = lam * x / L
        return np.cosh(s) - np.cos(s) - sigma * (np.sinh(s) - np.sin(s))

    gain = phi(L) * quad(phi, 0, L)[0] / quad(lambda x: phi(x) ** 2, 0, L)[0]  # ~ 2 x 0.783
    w1 = lam**2 * OMEGA_UNIT
    beam = dict(L=L, EI=EI * (1 + 1j * beta), rhoA=RHOA, x_s=L)
    peak = minimize_scalar(
        lambda w: -abs(br.afc_translation(w, **beam)),
        bounds=(0.99 * w1, 1.01 * w1),
        method="bounded",
        options=dict(xatol=1e-9 * w1),
    )
    assert abs(peak.x / (w1 * np.sqrt(1 + beta**2)) - 1) < 1e-4
    assert abs(-peak.fun / (gain * np.sqrt(1 + beta**2) / beta) - 1) < 5e-3
    phase = np.degrees(np.angle(br.afc_translation(w1, **beam)))
    assert abs(phase + 90) < 2
