"""An independent forward model of the stand for the population benchmark
(benchmarks/population/): a Ritz plate with the stand's effects written as their physics.

numpy/scipy only; never import ``vibid`` here: this module is what vibid's FE model and its
effect terms get judged against.

Plate (SI units). The specimen is the rectangle [0, L] x [0, B] of thickness h and density
rho, clamped along x = 0 to a base that translates by u_b and may rock about the clamp line
by theta (its rigid field r = u_b + theta x). The deflection relative to the base is the
Ritz series ``w_rel = sum q_mn X_m(x/L) Y_n(y/B)`` with Legendre polynomials
``Y_n(eta) = P_n(2 eta - 1)`` across and ``X_m(xi) = xi^p P_m(2 xi - 1)`` along: p = 2 holds
a rigid clamp (zero relative displacement and slope), p = 1 an elastic one (zero relative
displacement, the relative slope held by a rotational spring of potential energy
``1/2 k_theta int_0^B (dw_rel/dx)^2 dy`` at x = 0, k_theta in N m/rad per metre of edge,
complex ``k (1 + i beta_c)`` for the clamp's own loss). On a separable basis every plate
integral is a Kronecker product of 1-D Gauss-Legendre integrals (exact for polynomials).

* bending: ``V = 1/2 int D11 w,xx^2 + 2 D12 w,xx w,yy + D22 w,yy^2 + 4 D66 w,xy^2`` with the
  complex moduli ``D (1 + i beta(f))``, ``beta(f) = beta (f / 1 kHz)^alpha``;
* inertia: ``T = 1/2 int rho h (w_t^2 + h^2/12 |grad w_t|^2)`` (rotary inertia), w absolute;
* the response sensor: a disc of mass m and radius a centred at (x_s, y_s), its mass
  ``m / (pi a^2)`` per area spread over the disc and through the thickness (the same rotary
  term), read at its centre; an added mass at it (the report format's ``added_mass``: a
  point mass at the disc's centre, ``m psi psi^T``) and the rotary inertia of a tall sensor ``J = m ((h/2 + e)^2 - (h/2)^2)`` about both in-plane axes through the
  mid-plane (its centre of mass e above the surface, beyond the disc the setup declares),
  spread over the disc as the disc's own rotary term is (a point couple on a Kirchhoff
  plate meets no finite stiffness: its Ritz series would not converge);
* viscous air damping (outside vibid's library): a force ``-gamma rho h w_t`` per area on the
  absolute velocity, a modal loss factor gamma / omega that falls as 1/f.

Equation, per unit base translation (w_abs = r + w_rel, r = 1 + theta(f) x):
``(K_c - omega^2 M + i omega C) q = (omega^2 M - i omega C) r`` and
``H = w_abs(x_s, y_s) = 1 + theta(f) x_s + psi(x_s, y_s) . q``.

What the stand adds to H, each as its physics:

* ``stand_resonance`` (instances k = 1, 2, ...): the base rocks about the clamp line,
  ``theta(f) = theta_k / (1 - (f/f_k)^2 + i f/(f_k q_k))`` rad per m of base translation;
* ``fixture_resonance``: the clamp's fixture translates otherwise than the base sensor:
  H multiplied by ``1 + a r^2 / (1 - r^2 + i r / q)``, r = f / f0;
* ``free_length``: the clamp line dL inside the jaws: the free span L + dL, the sensor dL
  further from it; ``sensor_position``: the sensor at y_s + dy;
* ``sensor_gain``: H times g; ``channel_delay``: H times exp(-i omega tau);
* outside the library: ``crosstalk`` (H + c, the base channel leaking into the response
  channel) and an amplitude-dependent top (the first mode's stiffness through a modal
  Jenkins joint, tests/modal_slip.py's describing function on this plate's first mode).

Effect parameters carry the names of the report format's "Effect names" table
(``tau_s``, ``gain``, ``k_theta_N_per_rad``, ``beta_clamp``, ``dL_m``, ``mass_kg``,
``height_m``, ``sensor_dy_m``, ``alpha``, ``f_hz_k``/``q_k``/``theta_rad_per_m_k``,
``f_fixture_hz``/``q_fixture``/``a_fixture``) and, outside it, ``air_gamma_per_s``,
``crosstalk_re``/``crosstalk_im``, ``slip_kappa``/``slip_fraction``.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import scipy.linalg
from numpy.polynomial import legendre

#: Ritz orders (along, across) that converge the band's frequencies well below the noise
#: (tests/test_population_model.py checks it against a higher order).
STRIP_ORDER = (40, 16)
PLATE_ORDER = (32, 30)


@dataclasses.dataclass(frozen=True)
class Plate:
    """The specimen and its response sensor (the setup's declaration, SI units)."""

    L: float
    B: float
    h: float
    rho: float
    xs: float
    ys: float
    mass: float
    radius: float


def stiffness(material: dict) -> dict:
    """D11, D12, D22, D66 (N m) and beta from an isotropic (D, nu, beta) or orthotropic
    (D11, D12, D22, D66, beta) parameter set."""
    if "D" in material:
        D, nu = material["D"], material["nu"]
        return {
            "D11": D,
            "D12": nu * D,
            "D22": D,
            "D66": (1 - nu) * D / 2,
            "beta": material["beta"],
        }
    return {k: material[k] for k in ("D11", "D12", "D22", "D66", "beta")}


# -- the basis -------------------------------------------------------------------------
def _legendre(n, t):
    """P_0..P_{n-1}(2t - 1) and their first two derivatives in t: three (n, len(t))."""
    s = 2 * np.asarray(t, float) - 1
    V, D1, D2 = [], [], []
    for k in range(n):
        c = np.zeros(k + 1)
        c[k] = 1.0
        V.append(legendre.legval(s, c))
        D1.append(2 * legendre.legval(s, legendre.legder(c)))
        D2.append(4 * legendre.legval(s, legendre.legder(c, 2)))
    return np.array(V), np.array(D1), np.array(D2)


def _along(n, xi, p):
    """xi^p P_m(2 xi - 1), m < n, and its first two derivatives in xi."""
    P, P1, P2 = _legendre(n, xi)
    xi = np.asarray(xi, float)
    f = xi**p * P
    d1 = p * xi ** (p - 1) * P + xi**p * P1
    d2 = (
        (p * (p - 1) * xi ** max(p - 2, 0) * P if p >= 2 else 0.0)
        + 2 * p * xi ** (p - 1) * P1
        + xi**p * P2
    )
    return f, d1, d2


class Basis:
    """The Ritz basis of one plate geometry: fields at points, plate matrices."""

    def __init__(self, L, B, n_x, n_y, clamp="rigid", n_quad=None):
        self.L, self.B, self.n_x, self.n_y = L, B, n_x, n_y
        self.p = 2 if clamp == "rigid" else 1
        nq = n_quad or (n_x + n_y + 8)
        g, w = np.polynomial.legendre.leggauss(nq)
        t, wt = (g + 1) / 2, w / 2
        X = [a / L**i for i, a in enumerate(_along(n_x, t, self.p))]  # d^i/dx^i
        Y = [a / B**i for i, a in enumerate(_legendre(n_y, t))]
        self.A = {(i, j): (X[i] * wt * L) @ X[j].T for i in range(3) for j in range(3)}
        self.C = {(i, j): (Y[i] * wt * B) @ Y[j].T for i in range(3) for j in range(3)}
        self.a0 = X[0] @ (wt * L)  # int X dx
        self.ax = X[0] @ (wt * L * t * L)  # int X x dx
        self.a1 = X[1] @ (wt * L)  # int X' dx
        self.c0 = Y[0] @ (wt * B)  # int Y dy
        k = np.kron
        A, C = self.A, self.C
        self.K = {
            "D11": k(A[2, 2], C[0, 0]),
            "D12": k(A[2, 0], C[0, 2]) + k(A[0, 2], C[2, 0]),
            "D22": k(A[0, 0], C[2, 2]),
            "D66": 4 * k(A[1, 1], C[1, 1]),
        }
        self.M00 = k(A[0, 0], C[0, 0])
        self.Mgrad = k(A[1, 1], C[0, 0]) + k(A[0, 0], C[1, 1])
        self.load1 = k(self.a0, self.c0)  # int psi
        self.loadx = k(self.ax, self.c0)  # int psi x
        self.loadgx = k(self.a1, self.c0)  # int psi_x
        # the clamp spring: int_0^B psi_x(0, y) psi_x(0, y) dy
        xp0 = _along(n_x, np.array([0.0]), self.p)[1][:, 0] / L
        self.S = k(np.outer(xp0, xp0), C[0, 0])

    def fields(self, x, y):
        """(psi, psi_x, psi_y) at points x, y (m): three (n_basis, n_points)."""
        fx, dx, _ = _along(self.n_x, np.asarray(x) / self.L, self.p)
        fy, dy, _ = _legendre(self.n_y, np.asarray(y) / self.B)
        dx, dy = dx / self.L, dy / self.B
        prod = lambda a, b: (a[:, None, :] * b[None, :, :]).reshape(-1, a.shape[1])
        return prod(fx, fy), prod(dx, fy), prod(fx, dy)


@functools.lru_cache(maxsize=64)
def _basis(L, B, n_x, n_y, clamp):
    return Basis(L, B, n_x, n_y, clamp)


@functools.lru_cache(maxsize=64)
def _disc(basis_key, xs, ys, radius, n_disc=16):
    """Integrals over the sensor's disc per unit areal density: (int psi psi, int grad psi .
    grad psi, int psi, int psi x, int psi_x)."""
    b = _basis(*basis_key)
    gr, wr = np.polynomial.legendre.leggauss(n_disc)
    r = (gr + 1) / 2 * radius
    t = np.arange(2 * n_disc) * math.pi / n_disc
    R, T = np.meshgrid(r, t, indexing="ij")
    wd = np.outer(wr * radius / 2 * r, np.full(t.size, math.pi / n_disc)).ravel()
    xq, yq = xs + (R * np.cos(T)).ravel(), ys + (R * np.sin(T)).ravel()
    f, fx, fy = b.fields(xq, yq)
    return ((f * wd) @ f.T, (fx * wd) @ fx.T + (fy * wd) @ fy.T, f @ wd, f @ (wd * xq), fx @ wd)


@dataclasses.dataclass
class System:
    """The assembled matrices of one true geometry (plate, sensor, clamp kind)."""

    K: dict
    S: np.ndarray | None
    M: np.ndarray
    Mplate: np.ndarray  # the plate's translational mass alone (air damping acts on it)
    load1: np.ndarray  # M r for r = 1
    loadx: np.ndarray  # M r for r = x
    plate1: np.ndarray  # Mplate r for r = 1
    platex: np.ndarray
    probe: np.ndarray
    xs: float


@functools.lru_cache(maxsize=64)
def system(plate: Plate, order, clamp, dL=0.0, dy=0.0, added_mass=0.0, height=0.0) -> System:
    """The true stand's matrices: ``plate`` as declared, its clamp line dL inside the jaws,
    the sensor dy across, an added point mass and a tall sensor's rotary inertia."""
    L, xs, ys = plate.L + dL, plate.xs + dL, plate.ys + dy
    key = (L, plate.B, order[0], order[1], clamp)
    b = _basis(*key)
    rh, h = plate.rho * plate.h, plate.h
    M = rh * (b.M00 + h**2 / 12 * b.Mgrad)
    load1, loadx = rh * b.load1, rh * (b.loadx + h**2 / 12 * b.loadgx)
    Mf, Mg, d1, dx, dgx = _disc(key, xs, ys, plate.radius)
    area = math.pi * plate.radius**2
    rho_a = plate.mass / area  # the declared disc: its mass over the disc, through h
    M = M + rho_a * (Mf + h**2 / 12 * Mg)
    load1, loadx = load1 + rho_a * d1, loadx + rho_a * (dx + h**2 / 12 * dgx)
    f = b.fields(np.array([xs]), np.array([ys]))[0][:, 0]
    if added_mass:  # the report format's added_mass: a point mass at the sensor's centre
        M = M + added_mass * np.outer(f, f)
        load1, loadx = load1 + added_mass * f, loadx + added_mass * xs * f
    if height:
        # spread over the disc: a point couple on a plate has no finite stiffness
        J = plate.mass * ((h / 2 + height) ** 2 - (h / 2) ** 2) / area
        M = M + J * Mg
        loadx = loadx + J * dgx
    return System(
        b.K,
        b.S if clamp == "elastic" else None,
        M,
        rh * b.M00,
        load1,
        loadx,
        rh * b.load1,
        rh * b.loadx,
        f,
        xs,
    )


def _theta(f_hz, effects):
    """The base's rotation per base translation (rad/m) of the stand resonances."""
    th = np.zeros(np.size(f_hz), complex)
    k = 1
    while f"f_hz_{k}" in effects:
        f0, q, t0 = effects[f"f_hz_{k}"], effects[f"q_{k}"], effects[f"theta_rad_per_m_{k}"]
        th += t0 / (1 - (f_hz / f0) ** 2 + 1j * f_hz / (f0 * q))
        k += 1
    return th


def plate_afc(
    f_hz, plate: Plate, material: dict, effects: dict | None = None, order=STRIP_ORDER
) -> np.ndarray:
    """H(f) of the plate alone with the mechanical effects (no channel effects)."""
    e = dict(effects or {})
    f_hz = np.asarray(f_hz, float)
    D = stiffness(material)
    elastic = "k_theta_N_per_rad" in e
    sy = system(
        plate,
        tuple(order),
        "elastic" if elastic else "rigid",
        e.get("dL_m", 0.0),
        e.get("sensor_dy_m", 0.0),
        e.get("mass_kg", 0.0),
        e.get("height_m", 0.0),
    )
    Kr = sum(D[n] * sy.K[n] for n in ("D11", "D12", "D22", "D66"))
    beta, alpha = D["beta"], e.get("alpha", 0.0)
    spring = None
    if elastic:
        spring = e["k_theta_N_per_rad"] * (1 + 1j * e.get("beta_clamp", beta)) * sy.S
    gamma = e.get("air_gamma_per_s", 0.0)
    theta = _theta(f_hz, e)
    omega = 2 * math.pi * f_hz
    out = np.empty(f_hz.size, complex)
    modal = alpha == 0.0 and gamma == 0.0 and (not elastic or "beta_clamp" not in e)
    if modal:  # one loss factor throughout: the real modes diagonalise the system
        Kreal = Kr + (e["k_theta_N_per_rad"] * sy.S if elastic else 0.0)
        lam, phi = scipy.linalg.eigh(Kreal, sy.M)
        a = sy.probe @ phi
        b1, bx = phi.T @ sy.load1, phi.T @ sy.loadx
        w2 = omega**2
        g = w2[:, None] / (lam[None, :] * (1 + 1j * beta) - w2[:, None])
        out = 1 + theta * sy.xs + g @ (a * b1) + theta * (g @ (a * bx))
    else:
        for i, (w, f) in enumerate(zip(omega, f_hz)):
            Kc = Kr * (1 + 1j * beta * (f / 1000.0) ** alpha)
            if spring is not None:
                Kc = Kc + spring
            Z = Kc - w * w * sy.M + 1j * w * gamma * sy.Mplate
            rhs = w * w * (sy.load1 + theta[i] * sy.loadx) - 1j * w * gamma * (
                sy.plate1 + theta[i] * sy.platex
            )
            out[i] = 1 + theta[i] * sy.xs + sy.probe @ np.linalg.solve(Z, rhs)
    if "slip_kappa" in e:
        out = _slip(f_hz, out, plate, material, e, order)
    return out


def natural_frequencies_hz(
    plate: Plate, material: dict, effects: dict | None = None, n=6, order=STRIP_ORDER
) -> np.ndarray:
    """The first ``n`` undamped natural frequencies (Hz), base fixed."""
    e = dict(effects or {})
    D = stiffness(material)
    elastic = "k_theta_N_per_rad" in e
    sy = system(
        plate,
        tuple(order),
        "elastic" if elastic else "rigid",
        e.get("dL_m", 0.0),
        e.get("sensor_dy_m", 0.0),
        e.get("mass_kg", 0.0),
        e.get("height_m", 0.0),
    )
    K = sum(D[k] * sy.K[k] for k in ("D11", "D12", "D22", "D66"))
    if elastic:
        K = K + e["k_theta_N_per_rad"] * sy.S
    lam = scipy.linalg.eigh(K, sy.M, eigvals_only=True)[:n]
    return np.sqrt(lam) / (2 * math.pi)


def _slip(f_hz, H, plate, material, e, order):
    """The first mode's stiffness through a modal Jenkins joint (tests/modal_slip.py)."""
    from modal_slip import stepped_sine  # numpy only: the describing function

    lin = {k: v for k, v in e.items() if not k.startswith("slip_")}
    f1 = natural_frequencies_hz(plate, material, lin, n=1, order=order)[0]
    beta = stiffness(material)["beta"]
    w1 = 2 * math.pi * f1
    c = 1j * beta * plate_afc(np.array([f1]), plate, material, lin, order)[0]
    kappa = e["slip_kappa"]
    w0_sq = w1**2 / (1 + kappa)
    omega = 2 * math.pi * np.asarray(f_hz)
    slip_amp = e["slip_fraction"] / (beta * w1**2)
    z = stepped_sine(omega, lambda w: w0_sq + 1j * beta * w1**2 - w * w, kappa * w0_sq, slip_amp)
    z_lin = 1 / (w1**2 * (1 + 1j * beta) - omega**2)
    return H + c * omega**2 * (z - z_lin)


def afc(
    f_hz, plate: Plate, material: dict, effects: dict | None = None, order=STRIP_ORDER
) -> np.ndarray:
    """The measured ratio H(f): the plate with the mechanical effects, then the fixture, the
    channels' gain and delay and the crosstalk."""
    e = dict(effects or {})
    f_hz = np.asarray(f_hz, float)
    H = plate_afc(f_hz, plate, material, e, order)
    if "f_fixture_hz" in e:
        r = f_hz / e["f_fixture_hz"]
        H = H * (1 + e["a_fixture"] * r**2 / (1 - r**2 + 1j * r / e["q_fixture"]))
    H = H * e.get("gain", 1.0) * np.exp(-2j * math.pi * f_hz * e.get("tau_s", 0.0))
    return H + complex(e.get("crosstalk_re", 0.0), e.get("crosstalk_im", 0.0))


def noise_std(H, rel, floor):
    """The reported std per point (per real and imaginary part)."""
    return rel * np.abs(H) + floor


def noisy(H, std, seed):
    """H plus complex Gaussian noise of ``std`` per part, drawn with ``seed``."""
    rng = np.random.default_rng(seed)
    return H + std * (rng.standard_normal(H.size) + 1j * rng.standard_normal(H.size))


# -- the declared model's least-squares refit ------------------------------------------
def refit(
    f_hz,
    H,
    std,
    plate: Plate,
    declared: str,
    start: dict,
    free_effects=(),
    fixed_effects=None,
    order=STRIP_ORDER,
):
    """The declared material model (``"isotropic"``: D, nu, beta; ``"orthotropic"``: D11,
    D12, D22, D66, beta) fitted to (H, std) by least squares from ``start`` (its values and
    those of ``free_effects``, names of this module's effect parameters), on the declared
    geometry with ``fixed_effects``. Returns (chi2_reduced, fitted dict)."""
    from scipy.optimize import least_squares

    names = (
        ["D", "nu", "beta"] if declared == "isotropic" else ["D11", "D12", "D22", "D66", "beta"]
    ) + list(free_effects)
    logs = [n not in ("nu", "D12", "alpha", "sensor_dy_m", "dL_m") for n in names]
    x0 = np.array([math.log(start[n]) if lg else start[n] for n, lg in zip(names, logs)])
    fixed = dict(fixed_effects or {})

    def unpack(x):
        return {n: (math.exp(v) if lg else v) for n, v, lg in zip(names, x, logs)}

    def resid(x):
        p = unpack(x)
        mat = {n: p[n] for n in names if n not in free_effects}
        eff = fixed | {n: p[n] for n in free_effects}
        r = (afc(f_hz, plate, mat, eff, order) - H) / std
        return np.concatenate([r.real, r.imag])

    sol = least_squares(resid, x0, method="lm", x_scale=np.where(logs, 0.01, 0.01), max_nfev=400)
    dof = 2 * len(H) - len(names)
    return float(2 * sol.cost / dof), unpack(sol.x)
