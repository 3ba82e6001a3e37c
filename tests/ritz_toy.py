"""A small, independent forward model for the identification tests: a Ritz plate.

Cantilever plate [0, L] x [0, B], clamped along x = 0, base-excited (the clamp moves
with unit displacement). The deflection relative to the clamp is expanded in products
of beam functions, X_m(x) Y_n(y): clamped-free beam modes along x, and along y the
rigid-body pair (1, linear) plus free-free beam modes (the classical Ritz basis of
Leissa, "Vibration of plates", NASA SP-160, 1969). Stiffness is the paper's sum of
D_alpha K^alpha (moment convention of the session format, so K^66 carries 4 w,xy v,xy),
mass is rho h over the plate plus the sensor as a point mass. The AFC at the sensor is

    H(w) = 1 + psi_s^T q,   (K (1 + i beta) - w^2 M) q = w^2 (M_plate 1 + m_s psi_s).

It has nothing in common with vibid's FE model (no mesh, no Morley elements), which is
what makes it useful to test the inverse half on its own; it is not meant to be accurate
against the real plate. It satisfies the ForwardModel protocol of vibid.identify.fit.problem.
"""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

_LAMBDA_CF = [
    1.875104068711961,
    4.694091132974175,
    7.854757438237613,
    10.99554073487547,
    14.13716839104647,
    17.27875953208824,
]
_LAMBDA_FF = [4.730040744862704, 7.853204624095838, 10.99560783800167, 14.13716549125746]


def _clamped_free(lam, xi):
    """Value, first and second derivative (w.r.t. xi in [0, 1]) of a clamped-free mode."""
    s = (np.cosh(lam) + np.cos(lam)) / (np.sinh(lam) + np.sin(lam))
    a, b = lam * xi, lam
    f = np.cosh(a) - np.cos(a) - s * (np.sinh(a) - np.sin(a))
    d1 = b * (np.sinh(a) + np.sin(a) - s * (np.cosh(a) - np.cos(a)))
    d2 = b**2 * (np.cosh(a) + np.cos(a) - s * (np.sinh(a) + np.sin(a)))
    return f, d1, d2


def _free_free(k, eta):
    """Free-free beam function number k (0: rigid translation, 1: rigid rotation)."""
    if k == 0:
        return np.ones_like(eta), np.zeros_like(eta), np.zeros_like(eta)
    if k == 1:
        return (
            np.sqrt(3.0) * (2 * eta - 1),
            2 * np.sqrt(3.0) * np.ones_like(eta),
            np.zeros_like(eta),
        )
    lam = _LAMBDA_FF[k - 2]
    s = (np.cosh(lam) - np.cos(lam)) / (np.sinh(lam) - np.sin(lam))
    a = lam * eta
    f = np.cosh(a) + np.cos(a) - s * (np.sinh(a) + np.sin(a))
    d1 = lam * (np.sinh(a) - np.sin(a) - s * (np.cosh(a) + np.cos(a)))
    d2 = lam**2 * (np.cosh(a) - np.cos(a) - s * (np.sinh(a) - np.sin(a)))
    return f, d1, d2


def ritz_matrices(
    length_m,
    width_m,
    thickness_m,
    density_kg_m3,
    sensor_xy_m,
    sensor_mass_kg,
    n_x=5,
    n_y=4,
    n_quad=48,
):
    """Constant matrices of the Ritz model: K^alpha (alpha in 11, 12, 22, 66), M, b, psi_s."""
    gx, wx = np.polynomial.legendre.leggauss(n_quad)
    xi, wxi = (gx + 1) / 2, wx / 2
    X = [_clamped_free(_LAMBDA_CF[m], xi) for m in range(n_x)]
    Y = [_free_free(n, xi) for n in range(n_y)]
    L, B = length_m, width_m
    # basis on the tensor grid, derivatives in physical units
    psi, pxx, pyy, pxy = [], [], [], []
    for m in range(n_x):
        for n in range(n_y):
            fx, dx, ddx = X[m]
            fy, dy, ddy = Y[n]
            psi.append(np.outer(fx, fy))
            pxx.append(np.outer(ddx, fy) / L**2)
            pyy.append(np.outer(fx, ddy) / B**2)
            pxy.append(np.outer(dx, dy) / (L * B))
    w = np.outer(wxi, wxi) * L * B
    P, Pxx, Pyy, Pxy = (np.array(a).reshape(len(a), -1) for a in (psi, pxx, pyy, pxy))
    wf = w.ravel()

    def gram(a, c):
        return (a * wf) @ c.T

    K = {
        "11": gram(Pxx, Pxx),
        "12": gram(Pxx, Pyy) + gram(Pyy, Pxx),
        "22": gram(Pyy, Pyy),
        "66": 4 * gram(Pxy, Pxy),
    }
    xs, ys = sensor_xy_m[0] / L, sensor_xy_m[1] / B
    psi_s = np.array(
        [
            _clamped_free(_LAMBDA_CF[m], np.array(xs))[0] * _free_free(n, np.array(ys))[0]
            for m in range(n_x)
            for n in range(n_y)
        ]
    )
    rho_h = density_kg_m3 * thickness_m
    M = rho_h * gram(P, P) + sensor_mass_kg * np.outer(psi_s, psi_s)
    b = rho_h * (P * wf).sum(axis=1) + sensor_mass_kg * psi_s
    return K, M, b, psi_s


class RitzPlateModel:
    """A ForwardModel (vibid.identify.fit.problem.ForwardModel) backed by the Ritz plate."""

    def __init__(self, setup, frequencies_hz, model="isotropic", **kw):
        sp, r = setup.specimen, setup.sensors.response
        K, M, b, psi_s = ritz_matrices(
            sp.length_m,
            sp.width_m,
            sp.thickness_m,
            sp.density_kg_m3,
            (r.x_m, r.y_m),
            r.mass_kg,
            **kw,
        )
        self.model = model
        self.parameter_names = {
            "isotropic": ("D", "nu", "beta"),
            "orthotropic": ("D11", "D12", "D22", "D66", "beta"),
        }[model]
        self.frequencies_hz = np.asarray(frequencies_hz, dtype=float)
        self._K = {k: jnp.asarray(v) for k, v in K.items()}
        self._M, self._b, self._psi = jnp.asarray(M), jnp.asarray(b), jnp.asarray(psi_s)
        self._w2 = jnp.asarray((2 * np.pi * self.frequencies_hz) ** 2)
        self.afc = jax.jit(self._afc)
        self.afc_batch = jax.jit(jax.vmap(self._afc))

    def moduli(self, theta):
        if self.model == "isotropic":
            D, nu, beta = theta[0], theta[1], theta[2]
            return {"11": D, "12": nu * D, "22": D, "66": (1 - nu) * D / 2}, beta
        return {"11": theta[0], "12": theta[1], "22": theta[2], "66": theta[3]}, theta[4]

    def _afc(self, theta):
        theta = jnp.asarray(theta)
        d, beta = self.moduli(theta)
        K = sum(d[k] * self._K[k] for k in self._K) * (1 + 1j * beta)
        A = K[None, :, :] - self._w2[:, None, None] * self._M[None, :, :]
        rhs = self._w2[:, None] * self._b[None, :]
        q = jnp.linalg.solve(A, rhs.astype(A.dtype)[..., None])[..., 0]
        return 1.0 + q @ self._psi

    def model_error(self, theta):
        return np.zeros(self.frequencies_hz.shape)

    def afc_full(self, theta):
        return self.afc(theta)

    def refresh(self, theta):
        return self

    def natural_frequencies_hz(self, theta):
        d, _ = self.moduli(np.asarray(theta))
        K = sum(float(d[k]) * np.asarray(self._K[k]) for k in self._K)
        import scipy.linalg

        lam = scipy.linalg.eigh(K, np.asarray(self._M), eigvals_only=True)
        return np.sqrt(np.abs(lam)) / (2 * np.pi)
