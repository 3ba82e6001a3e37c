"""Reduced model: a Galerkin projection of the full model on a small parameter-aware basis.

Basis (built once around ``theta0``, from the full matrices of one discretisation and the
model's terms, :class:`~vibid.identify.model.terms.PlateModel`):

* the real modes of ``K0 = Σ s_k(θ0) K_k`` with ``M0``, up to a cut-off frequency chosen so
  that the band ``[0, f_max]`` stays covered, with margin, for the softest parameters in
  the prior box;
* the static correction ``K0⁻¹ M 1`` (the quasi-static response to the base motion, which
  carries the truncated modes' share) and its Krylov successors, and the same for each probe
  (and, for a model whose base rocks, for the rotation's load ``M x``);
* parameter-sensitivity vectors ``K0⁻¹ (∂K/∂θ_j) φ`` (and ``K0⁻¹ (∂M/∂θ_j) φ``) for every
  parameter that moves a stiffness or inertia coefficient, which span the first-order
  changes of the mode shapes;
* with ``snapshots``, the same at the faces of the prior box for every parameter that
  changes the mode shapes (not a pure scale of the stiffness), and at the box's softest
  corner, each point with its own modes up to the cut-off (a face where one modulus is
  soft has more of them; a pure scale, an isotropic ``D``, raises the cut-off instead).

The basis is made orthonormal in an energy norm (directions below a relative tolerance
dropped) and every term's matrix is projected once: ``K_k → Vᵀ K_k V``, ``M_k → Vᵀ M_k V``,
loads ``Vᵀ M_k 1``, probes ``Vᵀ c_k``.

Evaluation (JAX, float64, pure, jit-able, differentiable to any order), by
:class:`ReducedKernel`:

* ``modal`` path, when every stiffness term shares one loss factor β: with ``A = Σ s_k K̃_k``
  and ``M̃ = Σ m_k M̃_k``, ``A = Q Λ Qᵀ`` (generalised ``eigh``),
  ``H(ω) = 1 + Σ_j (cᵀq_j)(q_jᵀ f) ω² / ((1 + iβ L(ω)) λ_j − ω²)``;
* ``direct`` path (one loss per modulus): a dense solve of
  ``(Σ ŝ_k K̃_k − ω² M̃) q = ω² f`` per frequency, one frequency at a time (never a
  batched LAPACK call: :meth:`ReducedKernel._direct`);

and, where a term rocks the base, ``H_translation + θ(ω) H_rotation`` with the rotation's
load in place of the translation's; then the terms' maps on H (delay, gain).
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse.linalg as spla

from vibid.errors import VibidError
from vibid.identify.model.machinery import numpy_only, timed
from vibid.identify.model.modal import arpack_start

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ReducedBasis:
    """An orthonormal basis and the projected matrices.

    Attributes
    ----------
    V : (N, n) basis on the free dofs of the full model, orthonormal in the energy norm
        ``K(θ0) + ω_max² M`` (so that the projected matrices are well conditioned).
    K : (T, n, n) projected stiffness per stiffness term (``PlateModel.stiffness_names``).
    M : (S, n, n) projected inertia per inertia term (``PlateModel.inertia_names``).
    load : (S, n) projected inertia loads ``Vᵀ M_k 1``; probe : (P, n) projected probes
        ``Vᵀ c_k`` (``PlateModel.probe_names``, the declared sensor's first).
    probe_rigid : (P,) value of each probe on the rigid translation (1, then 0s).
    load_rotation : (S, n) and probe_rotation : (P,) the same for the rigid rotation about
        the clamp line (``w = x``, per radian).
    n_modes : how many modes it holds; f_top_hz : the highest of them at ``theta0``.
    theta0 : where it was built; moduli0 : (T,) and inertia0 : (S,) the coefficients there.
    """

    V: np.ndarray
    K: np.ndarray
    M: np.ndarray
    load: np.ndarray
    probe: np.ndarray
    probe_rigid: np.ndarray
    load_rotation: np.ndarray
    probe_rotation: np.ndarray
    n_modes: int
    f_top_hz: float
    theta0: np.ndarray
    moduli0: np.ndarray
    inertia0: np.ndarray

    @property
    def size(self) -> int:
        return self.V.shape[1]


def _coefficients(model, theta):
    return np.asarray(model.moduli(theta), float), np.asarray(model.inertia(theta), float)


def stiffness_scale_ratio(model, theta0, bounds) -> float:
    """How much softer than at ``theta0`` the whole plate may get inside ``bounds`` (>= 1):
    the largest ratio of a parameter that scales every stiffness coefficient (an isotropic
    ``D``) at ``theta0`` to its lower bound. Parameters that soften only part of the plate
    (one orthotropic modulus, a clamp's spring) change the mode shapes instead: the
    snapshots at the box's faces take their own modes (:func:`build_basis`)."""
    ratios = [1.0]
    for i, q in enumerate(model.parameters):
        if (
            q.rule == "positive"
            and q.name in bounds
            and bounds[q.name][0] > 0
            and _pure_scale(model, theta0, i)
        ):
            ratios.append(float(theta0[i]) / bounds[q.name][0])
    return max(ratios)


def moving_parameters(model, theta0) -> list[int]:
    """Indices of the parameters that change a stiffness or inertia coefficient."""
    s0, m0 = _coefficients(model, theta0)
    out = []
    for i in range(len(theta0)):
        t = np.array(theta0, float)
        t[i] = t[i] * 1.1 + (0.01 if t[i] == 0 else 0.0)
        s, m = _coefficients(model, t)
        if not (np.allclose(s, s0, rtol=0, atol=0) and np.allclose(m, m0, rtol=0, atol=0)):
            out.append(i)
    return out


def same_coefficients(model, theta_a, theta_b) -> bool:
    """Whether the stiffness and inertia coefficients at ``theta_a`` and ``theta_b`` are
    equal (then so is every basis built at them)."""
    (sa, ma), (sb, mb) = _coefficients(model, theta_a), _coefficients(model, theta_b)
    return bool(np.array_equal(sa, sb) and np.array_equal(ma, mb))


def _pure_scale(model, theta0, i) -> bool:
    """Whether parameter ``i`` only scales every stiffness coefficient (mode shapes stay)."""
    t = np.array(theta0, float)
    t[i] *= 2.0
    s0, m0 = _coefficients(model, theta0)
    s, m = _coefficients(model, t)
    return bool(np.allclose(s, 2 * s0, rtol=1e-12, atol=0) and np.allclose(m, m0, rtol=0, atol=0))


def snapshot_points(model, theta0, bounds) -> list[np.ndarray]:
    """``theta0``; for each parameter that changes the mode shapes (not the overall
    scale), the two points where it sits at its bounds, the others at ``theta0``; and,
    where two or more positive parameters do, the box's softest corner (all of them at
    their lower bounds), where most modes crowd into the band. Points whose moduli matrix
    is not positive definite are skipped."""
    theta0 = np.asarray(theta0, float)
    pts = [theta0]
    corner, soft = theta0.copy(), 0
    for i in moving_parameters(model, theta0):
        q, n = model.parameters[i], model.names[i]
        if n not in bounds or _pure_scale(model, theta0, i):
            continue
        for v in bounds[n]:
            t = theta0.copy()
            t[i] = v
            if np.isclose(v, theta0[i]) or not _positive_definite(model.moduli(t)):
                continue
            pts.append(t)
        if q.rule == "positive" and bounds[n][0] > 0:
            corner[i], soft = bounds[n][0], soft + 1
    if soft >= 2 and _positive_definite(model.moduli(corner)):
        pts.append(corner)
    return pts


def _positive_definite(m) -> bool:
    d11, d12, d16, d22, d26, d66 = np.asarray(m, float)[:6]
    D = np.array([[d11, d12, d16], [d12, d22, d26], [d16, d26, d66]])
    return bool(np.linalg.eigvalsh(D).min() > 1e-12 * np.abs(D).max())


def _coefficient_jacobians(model, theta0):
    """(T, p) and (S, p) derivatives of the stiffness and inertia coefficients, by complex
    step: ``∂c/∂θ_i = Im c(θ + i h e_i) / h`` is exact to rounding for the analytic
    coefficient laws of the terms (products, quotients, powers of the parameters), and
    costs microseconds where tracing a new model through ``jax.jacfwd`` cost 0.4 s (the
    closed loop builds a basis for every candidate it scores)."""
    th = np.asarray(theta0, float)
    Js, Jm = [], []
    for i in range(th.size):
        h = 1e-200 * max(abs(th[i]), 1.0)  # h² underflows: no O(h²) residue
        t = th.astype(complex)
        t[i] += 1j * h
        Js.append(np.imag(np.asarray(model.moduli(t, np), complex)) / h)
        Jm.append(np.imag(np.asarray(model.inertia(t, np), complex)) / h)
    return np.column_stack(Js), np.column_stack(Jm)


def spd_lu(K):
    """SuperLU's factors of a symmetric positive definite ``K`` in its symmetric mode: a
    minimum-degree ordering of K + Kᵀ and the diagonal as pivots (no pivoting is needed
    for a positive definite matrix). On a strip mesh of 2861 unknowns 7.8 ms and
    0.21 ms a solve, against 12.0 and 0.27 ms for the general ordering; the same
    solutions to 3e-11 (its condition)."""
    return spla.splu(
        K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )


#: The first eigensolve asks for this many modes at least (ARPACK's cost grows with the
#: count: on a strip mesh of 2922 unknowns 8 modes took 14 ms and 16 took 29 ms, the
#: same frequencies to 1e-15). Of a real strip's calibrated run's 218 bases 217 keep 6 or 7
#: modes; the declared fit's wide basis keeps 9 and takes a second solve (43 ms against
#: 29; ``benchmarks/modes.py``).
FIRST_MODES = 8


def _modes(K, M, lu, n_min, n_max, f_top):
    """The lowest modes (shapes, frequencies in Hz) of ``K`` with ``M`` up to the first
    above ``f_top`` (at least ``n_min``, at most ``n_max``), by shift-invert Lanczos on
    ``lu``; where a solve stops short of ``f_top``, the next asks for as many more as a
    plate's mode count, which grows in proportion to the frequency, says it needs (at
    least twice as many): a 150 x 100 x 2 mm plate's 46 modes to 9 kHz in two
    solves (8, then 81), 0.48 s, where doubling took three (16, 32, 64), 0.56-0.60 s."""
    opinv = spla.LinearOperator(K.shape, matvec=lu.solve, dtype=float)
    most = min(n_max, K.shape[0] - 2)
    k = min(max(n_min + 2, FIRST_MODES), most)
    while True:
        lam, Phi = spla.eigsh(
            K, k=k, M=M, sigma=0.0, OPinv=opinv, which="LM", v0=arpack_start(K.shape[0])
        )
        order = np.argsort(lam)
        lam, Phi = lam[order], Phi[:, order]
        freqs = np.sqrt(np.abs(lam)) / (2 * np.pi)
        if freqs[-1] >= f_top or k >= most:
            break
        k = min(max(2 * k, int(np.ceil(1.2 * k * f_top / max(freqs[-1], 1e-300)))), most)
    n_keep = min(k, int(max(n_min, np.searchsorted(freqs, f_top, side="right") + 1)))
    return Phi[:, :n_keep], freqs[:n_keep]


def _orthonormal(V, E, tol):
    """An E-orthonormal basis of span(V), dropping directions below ``tol`` (relative).

    Columns are scaled to unit E-norm, then orthonormalised twice through the Gram matrix
    (the second pass restores the digits the first loses to its squared conditioning).
    ``E`` should be an energy norm (stiffness plus mass): judging rank by the mass alone
    would drop curvature-rich directions that matter to the stiffness."""
    norm2 = np.einsum("ij,ij->j", V, E @ V)
    V = V[:, norm2 > 0] / np.sqrt(norm2[norm2 > 0])  # a zero column (a null sensitivity)
    for k in range(2):
        G = V.T @ (E @ V)
        s, U = np.linalg.eigh(0.5 * (G + G.T))
        keep = s > (tol * s.max() if k == 0 else 0.0)
        V = V @ (U[:, keep] / np.sqrt(s[keep]))
    return V


@numpy_only
@timed("reduced bases")
def build_basis(
    mats,
    model,
    theta0,
    bounds,
    f_max_hz: float,
    *,
    margin: float = 2.0,
    max_modes: int = 96,
    min_modes: int = 6,
    krylov: int = 2,
    snapshots: bool = True,
    tol: float = 1e-13,
    scale_ratio: float | None = None,
) -> ReducedBasis:
    """Build the reduced basis around ``theta0`` (see the module docstring).

    Parameters
    ----------
    mats : :class:`vibid.identify.model.assembly.PlateMatrices` of ``model``'s terms.
    model : :class:`vibid.identify.model.terms.PlateModel`.
    theta0 : (p,) parameters where the modes are computed.
    bounds : dict name -> (lo, hi), the prior box the basis must cover.
    f_max_hz : highest frequency of the AFC.
    margin : modes are kept up to ``margin * f_max * sqrt(stiffness ratio)``.
    max_modes, min_modes : limits on the number of modes per snapshot (a 150 x 100 mm
        plate's local basis, modes to 3.2 kHz, needs 42: a strip's, a dozen).
    krylov : number of static-correction vectors ``(K⁻¹M)^k K⁻¹ M 1`` (and the same for
        the probe, the adjoint load), k = 0 .. krylov - 1.
    snapshots : also take modes at :func:`snapshot_points` (the box's faces).
    tol : relative Gram eigenvalue below which directions are dropped.
    scale_ratio : how much softer than ``theta0`` the plate may get (default: from
        ``bounds`` by :func:`stiffness_scale_ratio`).
    """
    theta0 = np.asarray(theta0, float)
    names, inertia_names = list(mats.stiffness), list(mats.inertia)
    probe_names = list(model.probe_names)
    ratio = stiffness_scale_ratio(model, theta0, bounds) if scale_ratio is None else scale_ratio
    f_top = margin * f_max_hz * np.sqrt(ratio)
    points = snapshot_points(model, theta0, bounds) if snapshots else [theta0]
    moving = moving_parameters(model, theta0)

    cols = []
    n_modes, f_reached = 0, 0.0
    for j, th in enumerate(points):
        found, n, f_last = _point_columns(
            mats, model, th, moving, f_top, f_max_hz, min_modes, max_modes, krylov, first=j == 0
        )
        cols += found
        if j == 0:
            n_modes, f_reached = n, f_last
    V = np.column_stack(cols)
    n_candidates = V.shape[1]
    s0, m0 = _coefficients(model, theta0)
    energy = mats.stiffness_matrix(dict(zip(names, s0))) + (
        2 * np.pi * f_max_hz
    ) ** 2 * mats.inertia_matrix(dict(zip(inertia_names, m0)))
    V = _orthonormal(V, energy, tol)

    def project(a):
        r = V.T @ (a @ V)
        return 0.5 * (r + r.T)

    basis = ReducedBasis(
        V=V,
        K=np.array([project(mats.stiffness[k]) for k in names]),
        M=np.array([project(mats.inertia[k]) for k in inertia_names]),
        load=np.array([V.T @ mats.load[k] for k in inertia_names]),
        probe=np.array([V.T @ mats.probes[k] for k in probe_names]),
        probe_rigid=np.array([mats.probes_rigid[k] for k in probe_names]),
        load_rotation=np.array([V.T @ mats.load_rotation[k] for k in inertia_names]),
        probe_rotation=np.array([mats.probes_rotation[k] for k in probe_names]),
        n_modes=n_modes,
        f_top_hz=f_reached,
        theta0=theta0,
        moduli0=s0,
        inertia0=m0,
    )
    log.info(
        "reduced basis: %d modes to %.0f Hz at %d points, size %d of %d candidates",
        n_modes,
        f_reached,
        len(points),
        basis.size,
        n_candidates,
    )
    return basis


def _point_columns(
    mats, model, th, moving, f_top, f_max_hz, min_modes, max_modes, krylov, *, first: bool
) -> tuple[list, int, float]:
    """One snapshot point's candidate columns of :func:`build_basis` (its modes up to
    ``f_top``, the static and Krylov corrections of each load and probe, the sensitivities
    of the modes to the ``moving`` parameters), the number of its modes and the highest one
    (Hz). At the ``first`` point (``theta0``) modes that stop below the band are an error."""
    names, inertia_names = list(mats.stiffness), list(mats.inertia)
    s, m = _coefficients(model, th)
    K = mats.stiffness_matrix(dict(zip(names, s))).tocsc()
    M = mats.inertia_matrix(dict(zip(inertia_names, m))).tocsc()
    f = mats.inertia_load(dict(zip(inertia_names, m)))
    loads = [f] + (
        [mats.inertia_load(dict(zip(inertia_names, m)), rotation=True)]
        if model.rotates_base
        else []
    )
    lu = spd_lu(K)
    # every point its own modes up to f_top: a face where one modulus is soft has more
    Phi, freqs = _modes(K, M, lu, min_modes, max_modes, f_top)
    if first and freqs[-1] < f_max_hz:
        # modes inside the band would be missing: the model is wrong there, and a fit
        # on a basis this wide only crawls (a point at 126 kHz: 190 unknowns, a run
        # that never ended)
        raise VibidError(
            f"the plate model's {Phi.shape[1]} lowest modes reach only "
            f"{freqs[-1]:.0f} Hz, below the AFC's highest frequency {f_max_hz:.0f} Hz: "
            f"a band this wide holds more than {max_modes} modes; fit a narrower band"
        )
    if freqs[-1] < f_top:
        log.warning(
            "reduced basis: %d modes reach only %.0f Hz of the %.0f Hz wanted%s",
            Phi.shape[1],
            freqs[-1],
            f_top,
            "" if first else " at a face",
        )
    statics = []
    for rhs in loads + [mats.probes[k] for k in model.probe_names]:
        v = lu.solve(rhs)
        for _ in range(krylov):
            statics.append(v)
            v = lu.solve(M @ v)
    S = np.column_stack(statics)
    cols = [Phi, S]
    Js, Jm = _coefficient_jacobians(model, th)
    for i in moving:
        if np.any(Js[:, i] != 0):
            Kd = mats.stiffness_matrix(dict(zip(names, Js[:, i])))
            cols.append(lu.solve(np.column_stack([Kd @ Phi, Kd @ S[:, :1]])))
        if np.any(Jm[:, i] != 0):
            Md = mats.inertia_matrix(dict(zip(inertia_names, Jm[:, i])))
            cols.append(lu.solve(np.column_stack([Md @ Phi, Md @ S[:, :1]])))
    return cols, Phi.shape[1], float(freqs[-1])


#: How many reduced bases are kept (each a few MB on the paper's strip).
MAX_BASES = 12
_BASES: OrderedDict[tuple, ReducedBasis] = OrderedDict()
_BASES_LOCK = threading.Lock()  # a loop round's refits on threads, a batch's sessions


def basis_key(mats, model, theta0, bounds, f_max_hz: float, options: dict) -> tuple:
    """What a basis built by :func:`build_basis` depends on: the matrices, the model's
    matrix and probe names, the stiffness and inertia coefficients and their nonzero
    parameter derivatives at every snapshot point, the modes' cut-off and the options.
    Parameters that move no matrix (a delay, a gain, a loss law) do not appear: a candidate
    that only changes H reuses the basis of the model it extends."""
    theta0 = np.asarray(theta0, float)
    ratio = options.get("scale_ratio")
    ratio = stiffness_scale_ratio(model, theta0, bounds) if ratio is None else ratio
    points = snapshot_points(model, theta0, bounds) if options.get("snapshots", True) else [theta0]
    moving = moving_parameters(model, theta0)
    at = []
    for th in points:
        s, m = _coefficients(model, th)
        Js, Jm = _coefficient_jacobians(model, th)
        directions = sorted(Js[:, i].tobytes() + Jm[:, i].tobytes() for i in moving)
        at.append((s.tobytes(), m.tobytes(), tuple(directions)))
    return (
        (
            mats.geometry,
            mats.discretisation,
            tuple(mats.stiffness),
            tuple(mats.inertia),
            tuple(mats.probes),
            mats.n_dof,
        ),
        model.stiffness_names,
        model.inertia_names,
        model.probe_names,
        model.rotates_base,
        float(ratio),
        float(f_max_hz),
        tuple(at),
        tuple(sorted((k, v) for k, v in options.items() if k != "scale_ratio")),
    )


def cached_basis(mats, model, theta0, bounds, f_max_hz: float, **options) -> ReducedBasis:
    """:func:`build_basis`, or the basis already built for the same key
    (:func:`basis_key`), with ``theta0`` this model's."""
    key = basis_key(mats, model, theta0, bounds, f_max_hz, options)
    with _BASES_LOCK:
        basis = _BASES.get(key)
        if basis is not None:
            _BASES.move_to_end(key)
    if basis is None:  # built outside the lock: two threads may build one basis twice
        basis = build_basis(mats, model, theta0, bounds, f_max_hz, **options)
        with _BASES_LOCK:
            _BASES[key] = basis
            while len(_BASES) > MAX_BASES:
                _BASES.popitem(last=False)
    else:
        log.info("reduced basis: reused (size %d)", basis.size)
    return replace(basis, theta0=np.asarray(theta0, float))


#: Reduced bases are padded to one of these sizes (then to multiples of the last), so that
#: the models of a loop (rebuilt around new estimates, extended by candidates) share a few
#: shapes and so a few compilations: 16, 32, 64, 96, 128, 160, then steps of 1.2-1.5. (A
#: size's eigensolve costs its cube: a simulated orthotropic plate's wide basis of 131
#: padded to 192 cost 3.6 ms a member in the peak search, 2.3 ms at 160. A strip's basis of
#: 15 unknowns padded to 16 instead of 32 made a measured strip AFC's exact Hessian 1.8 ms
#: instead of 5.3 ms, the same to 1e-14; a size 24, and 48, cost the loop more compilations
#: than they saved: BENCHMARKS.md.)
PAD_SIZES = (16, 32, 64, 96, 128, 160, 192, 256, 384, 512)


def padded_size(n: int, sizes: tuple | None = None) -> int:
    """The size ``n`` unknowns are padded to: the first of ``sizes`` (default
    :data:`PAD_SIZES`) that holds them, then multiples of the last."""
    sizes = PAD_SIZES if sizes is None else sizes
    for m in sizes:
        if n <= m:
            return m
    return -(-n // sizes[-1]) * sizes[-1]


@dataclass(frozen=True)
class ReducedKernel:
    """The reduced forward map's code, apart from its arrays: ``kernel(arrays, theta) -> H``.

    Hashable and static (the model's terms), so that every jitted function of the
    identification takes a model's arrays as arguments and is compiled once per kernel and
    array shape, not once per model (Equinox's split of a module into static fields and
    array leaves).
    """

    model: object  # PlateModel: the structure (:mod:`vibid.identify.model.structure`)

    def __call__(self, arrays: dict, theta):
        """H (nf,) at the structure's parameter vector ``theta`` (:func:`embed`)."""
        return self._afc(arrays, theta)[0]

    def _afc(self, a: dict, theta):
        """``(H, modal)``: H (nf,) and, for proportional loss, the ``(mu, weights)`` of
        :meth:`_modal` it was summed from (else None)."""
        import jax.numpy as jnp

        model = self.model
        theta = jnp.asarray(theta, jnp.float64)
        s = model.moduli(theta, jnp)
        Mr, probe, loads = self._sides(a, theta)
        w2 = a["w2"]
        omega = jnp.sqrt(w2)
        law = model.loss_law(theta, omega, jnp)
        modal = None
        if model.proportional:
            beta = model.common_loss(theta, jnp)
            mu, weights = modal = self._modal(a, s, Mr, [f for f, _ in loads], probe)
            loss = 1.0 + 1j * beta * (1.0 if law is None else law)
            denom = loss[..., None] * jnp.ones((w2.shape[0], 1)) - w2[:, None] * mu[None, :]
            Hs = [
                r + (w2[:, None] * wt[None, :] / denom).sum(axis=1)
                for (_, r), wt in zip(loads, weights)
            ]
        else:
            b = model.losses(theta, jnp)
            c = s[None, :] * (1.0 + 1j * b[None, :] * (1.0 if law is None else law[:, None]))
            c = c * jnp.ones((w2.shape[0], 1))
            q = self._direct(a, c, w2, Mr, [f for f, _ in loads])  # (nf, m, loads)
            Hs = [r + q[..., j] @ probe for j, (_, r) in enumerate(loads)]
        H = Hs[0]
        if model.rotates_base:
            H = H + model.base_rotation(theta, omega, jnp) * Hs[1]
        return model.afc_map(theta, omega, H, jnp), modal

    def _sides(self, a: dict, theta):
        """``(M, probe, loads)`` at ``theta``: the reduced inertia (m, m), the probe vector
        (m,), and ``(load (m,), the probe's rigid value)`` for the base's translation and,
        where a term rocks the base, for its rotation about the clamp line."""
        import jax.numpy as jnp

        m, c = self.model.inertia(theta, jnp), self.model.probe(theta, jnp)
        loads = [(m @ a["load"], c @ a["probe_rigid"])]
        if self.model.rotates_base:
            loads.append((m @ a["load_rotation"], c @ a["probe_rotation"]))
        return jnp.tensordot(m, a["M"], axes=1) + a["M_pad"], c @ a["probe"], loads

    @staticmethod
    def _direct(a: dict, c, w2, Mr, loads):
        """``q`` (nf, m, loads): ``(Σ c_fk K_k − ω_f² M) q_f = ω_f² [loads]`` solved one
        frequency at a time.

        The system is complex symmetric, not Hermitian (no Cholesky), so each frequency is
        an LU solve: LAPACK's ``zgetrf`` and two ``ztrsm``. Solved as one batch over the
        frequencies (``jnp.linalg.solve`` on (nf, m, m)), jaxlib 0.10's LAPACK kernels split
        the batch over XLA's intra-op thread pool and block until it is done
        (``jax::ParallelBatchMap`` → ``absl::BlockingCounter::Wait``); when XLA runs two such
        calls side by side on a two-thread pool (the Hessian's value and tangent solves),
        each pool thread waits for chunks queued behind the other and the process hangs
        for good: 3 loop runs in about 25 on a lab PC's two cores, either thread setting.
        jaxlib runs a call whose batch is one matrix inline, on the calling thread
        (``chunk_size >= batch_count``), so here ``jax.lax.map`` loops over the
        frequencies and every LAPACK call sees one matrix; the derivatives keep it so
        (the tangents of a solve with an unbatched matrix become extra right-hand-side
        columns, ``_triangular_solve_batching_rule``), and
        ``tests/test_no_batched_lapack.py`` checks every compiled function of the fit for a
        LAPACK call with a batch. No jaxlib the registry serves (0.10.2 is the newest)
        compiles that parallel path out. Costs nothing measurable: the loop's step is
        microseconds against an LU of tens of unknowns."""
        import jax
        import jax.numpy as jnp

        K = a["K"].astype(jnp.complex128)
        f = jnp.stack(loads, axis=-1).astype(jnp.complex128)  # (m, loads)

        def one(cw):
            c_f, w2_f = cw
            sys = jnp.tensordot(c_f, K, axes=1) + a["pad"] - w2_f * Mr
            return jnp.linalg.solve(sys, w2_f * f)

        return jax.lax.map(one, (c, w2))

    @staticmethod
    def _modal(a: dict, s, Mr, loads, probe):
        """``(mu, weights)``: inverse eigenvalues ``mu = 1/λ`` (s²/rad², ascending) of the
        real pencil ``(Σ s_k K_k, M)`` and, for each of ``loads``, each mode's weight
        (probe x load) in H.

        (A - λ M) φ = 0 with A = L Lᵀ  <=>  (L⁻¹ M L⁻ᵀ) z = μ z, μ = 1/λ, φ = L⁻ᵀ z: well
        conditioned whatever the spread of λ (μ is bounded by 1/λ_min)."""
        import jax
        import jax.numpy as jnp

        L = jnp.linalg.cholesky(jnp.tensordot(s, a["K"], axes=1) + a["pad"])
        solve = lambda b: jax.scipy.linalg.solve_triangular(L, b, lower=True)  # noqa: E731
        B = solve(solve(Mr).T)
        mu, Z = jnp.linalg.eigh(0.5 * (B + B.T))
        zp = Z.T @ solve(probe)
        return mu, [zp * (Z.T @ solve(f)) for f in loads]

    def modes(self, arrays: dict, theta):
        """Natural frequencies (Hz, ascending) of the reduced model and the height of each
        mode's resonance peak in |H| (``|weight| / (mu beta)``, the modal term at
        resonance); padding modes have zero height. Proportional loss only."""
        import jax.numpy as jnp

        theta = jnp.asarray(theta, jnp.float64)
        Mr, probe, loads = self._sides(arrays, theta)
        modal = self._modal(arrays, self.model.moduli(theta, jnp), Mr, [loads[0][0]], probe)
        return self._peaks(theta, modal)

    def modes_and_afc(self, arrays: dict, theta):
        """``(f_hz, height, H)``: :meth:`modes` and H from one modal decomposition (the
        peak search's score with chi2 as its tie-break pays for one, not two)."""
        import jax.numpy as jnp

        theta = jnp.asarray(theta, jnp.float64)
        H, modal = self._afc(arrays, theta)
        return (*self._peaks(theta, modal), H)

    def _peaks(self, theta, modal):
        """Each mode's frequency (Hz, ascending) and resonance peak height from ``modal``
        (:meth:`_modal`; the first load's weights: the base's translation)."""
        import jax.numpy as jnp

        mu, (weight, *_) = modal
        beta = self.model.common_loss(theta, jnp)
        mu, weight = mu[::-1], weight[::-1]  # largest mu = lowest frequency first
        f_hz = 1.0 / jnp.sqrt(jnp.abs(mu)) / (2 * jnp.pi)
        return f_hz, jnp.abs(weight) / (jnp.abs(mu) * beta)


def largest_eigenvalue(K, M) -> float:
    """The largest finite |λ| of the pencil ``(K, M)`` (rad²/s²). A reduced mass that
    rounding left a hair indefinite (a basis direction with almost no mass: the clamp's
    slope at an extreme spring stiffness) has no Cholesky factor, which ``eigh`` needs;
    the QZ algorithm does not."""
    try:
        lam = sla.eigh(K, M, eigvals_only=True)
    except np.linalg.LinAlgError:
        lam = sla.eigvals(K, M)
    lam = np.abs(lam[np.isfinite(lam)])
    return float(lam.max()) if lam.size else 1.0


def padded_arrays(basis: ReducedBasis, omega, model, structure) -> dict:
    """The kernel's arrays for ``basis`` (of PlateModel ``model``) on angular frequencies
    ``omega`` (rad/s), laid out for ``structure``'s code
    (:mod:`vibid.identify.model.structure`): the terms ``model`` lacks get zero matrices,
    loads and probes. The basis is padded with decoupled dummy unknowns up to
    :func:`padded_size`.

    A dummy unknown has no load and no probe (it adds exactly nothing to H), unit inertia
    and a constant stiffness far above the basis's highest eigenvalue, each a different one
    so that the eigenvalue derivatives stay finite."""
    import jax

    from vibid.identify.model.structure import slots

    n = basis.size
    m = padded_size(n)
    n_pad = m - n

    def laid_out(own, names_of_model, names_of_structure, shape):
        out = np.zeros((len(names_of_structure),) + shape)
        for k, i in enumerate(slots(names_of_model, names_of_structure)):
            if i is not None:
                out[(k,) + tuple(slice(0, n) for _ in shape)] = own[i]
        return out

    K = laid_out(basis.K, model.stiffness_names, structure.stiffness_names, (m, m))
    M = laid_out(basis.M, model.inertia_names, structure.inertia_names, (m, m))
    load = laid_out(basis.load, model.inertia_names, structure.inertia_names, (m,))
    probe = laid_out(basis.probe, model.probe_names, structure.probe_names, (m,))
    load_rotation = laid_out(
        basis.load_rotation, model.inertia_names, structure.inertia_names, (m,)
    )
    rigid = np.zeros(len(structure.probe_names))
    rotation = np.zeros(len(structure.probe_names))
    for k, i in enumerate(slots(model.probe_names, structure.probe_names)):
        if i is not None:
            rigid[k] = basis.probe_rigid[i]
            rotation[k] = basis.probe_rotation[i]
    M_pad = np.zeros((m, m))
    M_pad[n:, n:] = np.eye(n_pad)
    pad = np.zeros((m, m))
    if n_pad:
        lam_max = largest_eigenvalue(
            np.tensordot(basis.moduli0, basis.K, axes=1),
            np.tensordot(basis.inertia0, basis.M, axes=1),
        )
        pad[n:, n:] = np.diag(1e4 * max(lam_max, 1.0) * (1.0 + np.arange(n_pad) / n_pad))
    # device_put, not jnp.asarray: no compiled conversion per array shape
    arrays = {
        "K": K,
        "M": M,
        "M_pad": M_pad,
        "pad": pad,
        "load": load,
        "probe": probe,
        "probe_rigid": rigid,
        "w2": np.asarray(omega, float) ** 2,
    }
    if structure.rotates_base:
        arrays |= {"load_rotation": load_rotation, "probe_rotation": rotation}
    return jax.device_put(arrays)


@dataclass(frozen=True, eq=False)
class ReducedAFC:
    """The reduced forward map as a pure JAX function of the parameter vector.

    Attributes
    ----------
    basis : the projected matrices.
    model : the PlateModel (names, coefficients, maps).
    omega : (nf,) angular frequencies in rad/s.
    kernel, arrays : the same map split into static code and array leaves
        (``self(theta) == self.kernel(self.arrays, theta)``).
    """

    basis: ReducedBasis
    model: object
    omega: np.ndarray
    kernel: ReducedKernel = field(init=False, repr=False)
    arrays: dict = field(init=False, repr=False)

    def __post_init__(self):
        from vibid.identify.model.structure import structure_of

        structure = structure_of(self.model)
        object.__setattr__(self, "kernel", ReducedKernel(structure))
        object.__setattr__(
            self, "arrays", padded_arrays(self.basis, self.omega, self.model, structure)
        )

    def __call__(self, theta):
        from vibid.identify.model.structure import embed, embedding

        return self.kernel(self.arrays, embed(embedding(self.model, self.kernel.model), theta))

    def eigenvalues(self, theta):
        """Reduced eigenvalues ``Λ`` (rad²/s², complex), smallest first (numpy)."""
        theta = np.asarray(theta, float)
        s, m = _coefficients(self.model, theta)
        losses = np.asarray(self.model.losses(theta), float)
        K = np.tensordot(s, self.basis.K, axes=1)
        M = np.tensordot(m, self.basis.M, axes=1)
        if self.model.proportional:
            return np.sort(sla.eigh(K, M, eigvals_only=True)) * (1.0 + 1j * losses[0])
        lam = sla.eigvals(np.tensordot(s * (1.0 + 1j * losses), self.basis.K, axes=1), M)
        return lam[np.argsort(lam.real)]
