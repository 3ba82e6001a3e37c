"""Reduced model: a Galerkin projection of the full model on a small parameter-aware basis.

Basis (built once around ``theta0``, from the full matrices of one discretisation):

* the real modes of ``K0 = Σ D_α(θ0) K_α`` with ``M``, up to a cut-off frequency chosen so
  that the band ``[0, f_max]`` stays covered, with margin, for the softest parameters in
  the prior box (an isotropic ``K = D (K_a + ν K_b)`` scales its frequencies by ``√D``,
  its mode shapes do not change with ``D``);
* the static correction ``K0⁻¹ M 1`` (the quasi-static response to the base motion, which
  carries the truncated modes' share);
* parameter-sensitivity vectors ``K0⁻¹ K_k φ_j`` and ``K0⁻¹ K_k (K0⁻¹ M 1)`` for every
  stiffness direction ``K_k = ∂K/∂θ_k`` of the parameterisation, which span the first-order
  changes of the mode shapes when the moduli move relative to one another.

The basis is made ``M``-orthonormal (directions below a relative tolerance dropped) and the
matrices are projected once: ``K_α → Vᵀ K_α V`` (n x n), ``M → I``, ``M 1 → Vᵀ M 1``,
probe ``c → Vᵀ c``.

Evaluation (JAX, float64, pure, jit-able, differentiable to any order):

* ``modal`` path, when all moduli share one loss factor: with ``A = Σ D_α K̃_α``,
  ``A = Q Λ Qᵀ`` (``eigh``), ``H(ω) = 1 + Σ_j (cᵀq_j)(q_jᵀ f) ω² / ((1 + iβ) λ_j − ω²)``;
* ``direct`` path (one loss per modulus): a batched dense solve of
  ``(Σ D̂_α K̃_α − ω² I) q = ω² f`` per frequency.

Extension points (the closed loop's effects; only ``post`` is wired today):
``post(theta, omega, H)`` maps the plate's AFC to the observed one (delay, gain); an extra
stiffness term (edge spring: :func:`vibid.identify.assembly.edge_rotation_matrix`) is one
more projected matrix in ``K`` with a real coefficient from ``theta`` (and a sensitivity
vector in the basis); a frequency-dependent loss replaces the scalar ``beta`` by an
``(nf, 1)`` array in the modal denominator; a point mass at the sensor adds
``m_p (Vᵀc)(Vᵀc)ᵀ`` to ``M`` and ``m_p Vᵀc`` to the load. Each stays inside the projected
space, so the reduced model remains valid when the basis spans its effect.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse.linalg as spla

from vibid.identify.forms import MODULI
from vibid.identify.modes import arpack_start

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ReducedBasis:
    """An ``M``-orthonormal basis and the projected matrices.

    Attributes
    ----------
    V : (N, n) basis on the free dofs of the full model, orthonormal in the energy norm
        ``K(θ0) + ω_max² M`` (so that the projected matrices are well conditioned).
    K : (T, n, n) projected stiffness per term (``MODULI`` first, in that order).
    M : (n, n) projected inertia.
    load : (n,) projected inertia load ``Vᵀ M 1``; probe : (n,) projected probe ``Vᵀ c``.
    probe_rigid : value of the probe on the rigid translation (1).
    n_modes : how many modes it holds; f_top_hz : the highest of them at ``theta0``.
    theta0 : where it was built; moduli0 : (6,) its moduli there.
    """

    V: np.ndarray
    K: np.ndarray
    M: np.ndarray
    load: np.ndarray
    probe: np.ndarray
    probe_rigid: float
    n_modes: int
    f_top_hz: float
    theta0: np.ndarray
    term_names: tuple = MODULI
    moduli0: np.ndarray | None = None

    @property
    def size(self) -> int:
        return self.V.shape[1]


def stiffness_scale_ratio(param, theta0, bounds) -> float:
    """How much softer than at ``theta0`` the plate may get inside ``bounds`` (>= 1).

    The ratio of the smallest eigenvalue of the 3 x 3 moduli matrix at ``theta0`` to its
    smallest over the corners of the box's positive moduli, a bound on how far down the
    natural frequencies scale (squared)."""
    names = param.stiffness_names
    ratios = [1.0]
    for i, n in enumerate(names):
        if n in ("D", "D11", "D22", "D66") and n in bounds:
            lo = bounds[n][0]
            if lo > 0:
                ratios.append(float(theta0[i]) / lo)
    return max(ratios)


def _moduli_jacobian(param, theta0) -> np.ndarray:
    """(6, k) derivative of the moduli with respect to the stiffness parameters."""
    k = len(param.stiffness_names)
    J = jax.jacfwd(lambda t: param.moduli(t, jnp))(jnp.asarray(theta0, float))
    return np.asarray(J)[:, :k]


def snapshot_points(param, theta0, bounds) -> list[np.ndarray]:
    """``theta0`` and, for each stiffness parameter that changes the mode shapes (not the
    overall scale), the two points where it sits at its bounds, the others at ``theta0``.
    Points whose moduli matrix is not positive definite are skipped."""
    theta0 = np.asarray(theta0, float)
    pts = [theta0]
    names = param.stiffness_names
    for i, n in enumerate(names):
        if param.model == "isotropic" and n == "D":
            continue  # D only scales K
        if n not in bounds:
            continue
        for v in bounds[n]:
            t = theta0.copy()
            t[i] = v
            if np.isclose(v, theta0[i]) or not _positive_definite(param.moduli(t)):
                continue
            pts.append(t)
    return pts


def _positive_definite(m) -> bool:
    d11, d12, d16, d22, d26, d66 = np.asarray(m, float)
    D = np.array([[d11, d12, d16], [d12, d22, d26], [d16, d26, d66]])
    return bool(np.linalg.eigvalsh(D).min() > 1e-12 * np.abs(D).max())


def _modes(K, M, lu, n_min, n_max, f_top):
    opinv = spla.LinearOperator(K.shape, matvec=lu.solve, dtype=float)
    k = min(max(n_min, 16), n_max, K.shape[0] - 2)
    while True:
        lam, Phi = spla.eigsh(K, k=k, M=M, sigma=0.0, OPinv=opinv, which="LM",
                              v0=arpack_start(K.shape[0]))
        order = np.argsort(lam)
        lam, Phi = lam[order], Phi[:, order]
        freqs = np.sqrt(np.abs(lam)) / (2 * np.pi)
        if freqs[-1] >= f_top or k >= n_max or k >= K.shape[0] - 2:
            break
        k = min(2 * k, n_max, K.shape[0] - 2)
    n_keep = min(k, int(max(n_min, np.searchsorted(freqs, f_top, side="right") + 1)))
    return Phi[:, :n_keep], freqs[:n_keep]


def _orthonormal(V, E, tol):
    """An E-orthonormal basis of span(V), dropping directions below ``tol`` (relative).

    Columns are scaled to unit E-norm, then orthonormalised twice through the Gram matrix
    (the second pass restores the digits the first loses to its squared conditioning).
    ``E`` should be an energy norm (stiffness plus mass): judging rank by the mass alone
    would drop curvature-rich directions that matter to the stiffness."""
    V = V / np.sqrt(np.einsum("ij,ij->j", V, E @ V))
    for k in range(2):
        G = V.T @ (E @ V)
        s, U = np.linalg.eigh(0.5 * (G + G.T))
        keep = s > (tol * s.max() if k == 0 else 0.0)
        V = V @ (U[:, keep] / np.sqrt(s[keep]))
    return V


def build_basis(mats, param, theta0, bounds, f_max_hz: float, *, margin: float = 2.0,
                max_modes: int = 40, min_modes: int = 6, krylov: int = 2,
                snapshots: bool = True, tol: float = 1e-13,
                scale_ratio: float | None = None) -> ReducedBasis:
    """Build the reduced basis around ``theta0`` (see the module docstring).

    Parameters
    ----------
    mats : :class:`vibid.identify.assembly.PlateMatrices`.
    param : :class:`vibid.identify.materials.Parameterisation`.
    theta0 : (p,) parameters where the modes are computed.
    bounds : dict name -> (lo, hi), the prior box the basis must cover.
    f_max_hz : highest frequency of the AFC.
    margin : modes are kept up to ``margin * f_max * sqrt(stiffness ratio)``.
    max_modes, min_modes : limits on the number of modes per snapshot.
    krylov : number of static-correction vectors ``(K⁻¹M)^k K⁻¹ M 1`` (and the same for
        the probe, the adjoint load), k = 0 .. krylov - 1.
    snapshots : also take modes at :func:`snapshot_points` (the box's faces).
    tol : relative Gram eigenvalue below which directions are dropped.
    scale_ratio : how much softer than ``theta0`` the plate may get (default: from
        ``bounds`` by :func:`stiffness_scale_ratio`).
    """
    theta0 = np.asarray(theta0, float)
    M = mats.inertia_matrix().tocsc()
    f = mats.inertia_load()
    ratio = stiffness_scale_ratio(param, theta0, bounds) if scale_ratio is None else scale_ratio
    f_top = margin * f_max_hz * np.sqrt(ratio)
    points = snapshot_points(param, theta0, bounds) if snapshots else [theta0]

    cols = []
    n_modes, f_reached = 0, 0.0
    for j, th in enumerate(points):
        Dm = np.asarray(param.moduli(th), float)
        K = mats.stiffness_matrix(dict(zip(MODULI, Dm))).tocsc()
        lu = spla.splu(K)
        # frequencies at this point scale like those at theta0 (same cut in mode count)
        Phi, freqs = _modes(K, M, lu, min_modes if j == 0 else n_modes, max_modes,
                            f_top if j == 0 else np.inf)
        if j == 0:
            n_modes, f_reached = Phi.shape[1], float(freqs[-1])
            if f_reached < f_top:
                log.warning("reduced basis: %d modes reach only %.0f Hz of the %.0f Hz wanted",
                            n_modes, f_reached, f_top)
        Phi = Phi[:, :n_modes]
        statics = []
        for rhs in (f, mats.probe):
            v = lu.solve(rhs)
            for _ in range(krylov):
                statics.append(v)
                v = lu.solve(M @ v)
        S = np.column_stack(statics)
        cols += [Phi, S]
        J = _moduli_jacobian(param, th)
        for kk in range(J.shape[1]):
            Kd = mats.stiffness_matrix(dict(zip(MODULI, J[:, kk])))
            cols.append(lu.solve(np.column_stack([Kd @ Phi, Kd @ S[:, :1]])))
    V = np.column_stack(cols)
    n_candidates = V.shape[1]
    D0 = np.asarray(param.moduli(theta0), float)
    energy = mats.stiffness_matrix(dict(zip(MODULI, D0))) + (2 * np.pi * f_max_hz) ** 2 * M
    V = _orthonormal(V, energy, tol)

    def project(a):
        r = V.T @ (a @ V)
        return 0.5 * (r + r.T)

    basis = ReducedBasis(
        V=V, K=np.array([project(mats.stiffness[name]) for name in MODULI]),
        M=project(M), load=V.T @ f, probe=V.T @ mats.probe, probe_rigid=mats.probe_rigid,
        n_modes=n_modes, f_top_hz=f_reached, theta0=theta0, moduli0=D0,
    )
    log.info("reduced basis: %d modes to %.0f Hz at %d points, size %d of %d candidates",
             n_modes, f_reached, len(points), basis.size, n_candidates)
    return basis


#: Reduced bases are padded to a multiple of this size, so that models rebuilt around new
#: estimates (``ForwardModel.refresh``) mostly share one shape and one compilation.
PAD_MULTIPLE = 16


@dataclass(frozen=True)
class ReducedKernel:
    """The reduced forward map's code, apart from its arrays: ``kernel(arrays, theta) -> H``.

    Hashable and static (the parameterisation and the ``post`` map), so that every jitted
    function of the identification takes a model's arrays as arguments and is compiled once
    per kernel and array shape, not once per model (Equinox's split of a module into
    static fields and array leaves).
    """

    param: object
    post: Callable | None = None

    def __call__(self, arrays: dict, theta):
        a = arrays
        theta = jnp.asarray(theta, jnp.float64)
        D = self.param.moduli(theta, jnp)
        w2 = a["w2"]
        if self.param.proportional:
            beta = self.param.losses(theta, jnp)[0]
            mu, weight = self._modal(a, D)
            denom = (1.0 + 1j * beta) - w2[:, None] * mu[None, :]
            H = a["probe_rigid"] + (w2[:, None] * weight[None, :] / denom).sum(axis=1)
        else:
            Dc = D * (1.0 + 1j * self.param.losses(theta, jnp))
            A = jnp.tensordot(Dc, a["K"].astype(jnp.complex128), axes=1) + a["pad"]
            sys = A[None, :, :] - w2[:, None, None] * a["M"][None]
            rhs = (w2[:, None] * a["load"][None, :]).astype(jnp.complex128)
            q = jnp.linalg.solve(sys, rhs[..., None])[..., 0]
            H = a["probe_rigid"] + q @ a["probe"]
        if self.post is not None:
            H = self.post(theta, jnp.sqrt(w2), H)
        return H

    @staticmethod
    def _modal(a: dict, D):
        """``(mu, weight)``: inverse eigenvalues ``mu = 1/λ`` (s²/rad², ascending) of the
        real pencil ``(Σ D_α K_α, M)`` and each mode's weight (probe x load) in H.

        (A - λ M) φ = 0 with A = L Lᵀ  <=>  (L⁻¹ M L⁻ᵀ) z = μ z, μ = 1/λ, φ = L⁻ᵀ z: well
        conditioned whatever the spread of λ (μ is bounded by 1/λ_min)."""
        L = jnp.linalg.cholesky(jnp.tensordot(D, a["K"], axes=1) + a["pad"])
        solve = lambda b: jax.scipy.linalg.solve_triangular(L, b, lower=True)  # noqa: E731
        B = solve(solve(a["M"]).T)
        mu, Z = jnp.linalg.eigh(0.5 * (B + B.T))
        return mu, (Z.T @ solve(a["probe"])) * (Z.T @ solve(a["load"]))

    def modes(self, arrays: dict, theta):
        """Natural frequencies (Hz, ascending) of the reduced model and the height of each
        mode's resonance peak in |H| (``|weight| / (mu beta)``, the modal term at
        resonance); padding modes have zero height. Proportional loss only."""
        theta = jnp.asarray(theta, jnp.float64)
        beta = self.param.losses(theta, jnp)[0]
        mu, weight = self._modal(arrays, self.param.moduli(theta, jnp))
        mu, weight = mu[::-1], weight[::-1]  # largest mu = lowest frequency first
        f_hz = 1.0 / jnp.sqrt(jnp.abs(mu)) / (2 * jnp.pi)
        return f_hz, jnp.abs(weight) / (jnp.abs(mu) * beta)


def padded_arrays(basis: ReducedBasis, omega, multiple: int = PAD_MULTIPLE) -> dict:
    """The kernel's arrays for ``basis`` on angular frequencies ``omega`` (rad/s), the basis
    padded with decoupled dummy unknowns up to a multiple of ``multiple``.

    A dummy unknown has no load and no probe (it adds exactly nothing to H), unit inertia
    and a constant stiffness far above the basis's highest eigenvalue, each a different one
    so that the eigenvalue derivatives stay finite."""
    n = basis.size
    n_pad = (-n) % multiple
    m = n + n_pad
    K = np.zeros((basis.K.shape[0], m, m))
    K[:, :n, :n] = basis.K
    M = np.eye(m)
    M[:n, :n] = basis.M
    pad = np.zeros((m, m))
    if n_pad:
        import scipy.linalg as sla

        D0 = np.zeros(basis.K.shape[0])
        D0[:len(MODULI)] = basis.moduli0
        lam_max = float(abs(sla.eigh(np.tensordot(D0, basis.K, axes=1), basis.M,
                                     eigvals_only=True)).max())
        pad[n:, n:] = np.diag(1e4 * max(lam_max, 1.0) * (1.0 + np.arange(n_pad) / n_pad))
    load = np.zeros(m)
    load[:n] = basis.load
    probe = np.zeros(m)
    probe[:n] = basis.probe
    return {"K": jnp.asarray(K), "M": jnp.asarray(M), "pad": jnp.asarray(pad),
            "load": jnp.asarray(load), "probe": jnp.asarray(probe),
            "probe_rigid": jnp.asarray(float(basis.probe_rigid)),
            "w2": jnp.asarray(np.asarray(omega, float) ** 2)}


@dataclass(frozen=True, eq=False)
class ReducedAFC:
    """The reduced forward map as a pure JAX function of the parameter vector.

    Attributes
    ----------
    basis : the projected matrices.
    param : the parameterisation (names, moduli, losses).
    omega : (nf,) angular frequencies in rad/s.
    post : optional ``post(theta, omega, H) -> H`` applied last (delay, gain, ...).
    kernel, arrays : the same map split into static code and array leaves
        (``self(theta) == self.kernel(self.arrays, theta)``).
    """

    basis: ReducedBasis
    param: object
    omega: np.ndarray
    post: Callable | None = None
    kernel: ReducedKernel = field(init=False, repr=False)
    arrays: dict = field(init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "kernel", ReducedKernel(self.param, self.post))
        object.__setattr__(self, "arrays", padded_arrays(self.basis, self.omega))

    def __call__(self, theta):
        return self.kernel(self.arrays, theta)

    def eigenvalues(self, theta):
        """Reduced eigenvalues ``Λ`` (rad²/s², complex), smallest first (numpy)."""
        import scipy.linalg as sla

        theta = np.asarray(theta, float)
        D = np.asarray(self.param.moduli(theta), float)
        losses = np.asarray(self.param.losses(theta), float)
        if self.param.proportional:
            lam = sla.eigh(np.tensordot(D, self.basis.K, axes=1), self.basis.M, eigvals_only=True)
            return np.sort(lam) * (1.0 + 1j * losses[0])
        A = np.tensordot(D * (1.0 + 1j * losses), self.basis.K, axes=1)
        lam = sla.eigvals(A, self.basis.M)
        return lam[np.argsort(lam.real)]
