"""Natural frequencies and decay factors: the complex eigenproblem of the full model.

Paper eq. 4.1.13: ``(Σ_k ŝ_k K_k − Λ M) u = 0`` with the clamp's fixed dofs removed; then
``ω_k = Re √Λ_k`` and ``γ_k = Im √Λ_k``, so that free vibrations decay as
``exp((−γ_k + i ω_k) t)``. With one loss factor for all stiffness terms the modes are real
and ``Λ = (1 + iβ) λ`` with ``λ`` from the real problem; otherwise the complex problem is
solved by shift-invert Arnoldi. A loss law ``L(ω)`` (frequency-dependent loss) is applied
at each mode's own frequency.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from vibid.identify.model.machinery import numpy_only


def arpack_start(n: int) -> np.ndarray:
    """ARPACK's start vector: fixed, so that the same model gives the same modes to the
    last bit (left to itself ARPACK starts from a random vector, and the identification
    then differed between runs of the same session by 1e-6 in chi2)."""
    return np.random.default_rng(0).standard_normal(n)


def complex_eigenvalues(mats, moduli, losses, n: int = 6, inertia=None) -> np.ndarray:
    """The ``n`` smallest eigenvalues ``Λ`` (rad²/s², complex) of the plate.

    Parameters
    ----------
    mats : :class:`vibid.identify.model.assembly.PlateMatrices`.
    moduli, losses : storage coefficients (N·m for the moduli) and loss factors of
        ``mats.stiffness``, in its order.
    n : how many.
    inertia : dict name -> coefficient of ``mats.inertia`` (default all 1).
    """
    names = list(mats.stiffness)
    moduli = np.asarray(moduli, float)
    losses = np.asarray(losses, float)
    M = mats.inertia_matrix(inertia)
    n = int(min(n, mats.n_dof - 2))
    if np.allclose(losses, losses[0]):
        K = mats.stiffness_matrix(dict(zip(names, moduli)))
        lam = spla.eigsh(
            K,
            k=n,
            M=M,
            sigma=0.0,
            which="LM",
            return_eigenvectors=False,
            v0=arpack_start(K.shape[0]),
        )
        lam = np.sort(lam) * (1.0 + 1j * losses[0])
    else:
        K = mats.stiffness_matrix(dict(zip(names, moduli * (1.0 + 1j * losses))))
        lam = spla.eigs(
            K,
            k=n,
            M=M.astype(complex),
            sigma=0.0,
            which="LM",
            return_eigenvectors=False,
            v0=arpack_start(K.shape[0]).astype(complex),
        )
        lam = lam[np.argsort(lam.real)]
    return lam


@numpy_only
def model_eigenvalues(mats, model, theta, n: int = 6) -> np.ndarray:
    """``Λ`` of a PlateModel at ``theta`` (its loss law applied at each mode's frequency)."""
    theta = np.asarray(theta, float)
    inertia = dict(zip(model.inertia_names, model.inertia(theta)))
    lam = complex_eigenvalues(mats, model.moduli(theta), model.losses(theta), n, inertia)
    law = model.loss_law(theta, np.sqrt(np.abs(lam.real)), np)
    if law is not None:  # Λ = λ (1 + iβ L(ω)) with λ = Re Λ for proportional loss
        beta = lam.imag / np.where(lam.real != 0, lam.real, 1.0)
        lam = lam.real * (1.0 + 1j * beta * law)
    return lam


#: A mode whose peak in |H| is below this share of the highest mode's is one the sensor
#: does not see (a strip's torsion, its sensor on the centre line: 1e-17; 3 mm off it, 6e-3).
HIDDEN_HEIGHT = 1e-3


def seen(height) -> np.ndarray:
    """Which of the modes of peak heights ``height`` (:func:`mode_heights`) the sensor sees
    (:data:`HIDDEN_HEIGHT`)."""
    height = np.asarray(height, float)
    return height >= HIDDEN_HEIGHT * np.max(height)


@numpy_only
def mode_heights(mats, model, theta, n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """``(frequency_hz, height)`` of the ``n`` lowest real modes of a PlateModel at
    ``theta`` (its storage moduli; loss and any loss law left out): ``height_k = |c φ_k|
    |φ_kᵀ f|`` for the mass-normalised mode ``φ_k``, the probe ``c`` and the base
    translation's load ``f``, which is ``β`` times mode k's resonance peak in |H|. A mode
    of height near zero is one the sensor does not see, or the base does not excite (a
    strip's torsion with its sensor on the centre line)."""
    theta = np.asarray(theta, float)
    inertia = dict(zip(model.inertia_names, model.inertia(theta)))
    probe = dict(zip(model.probe_names, model.probe(theta)))
    M = mats.inertia_matrix(inertia)
    K = mats.stiffness_matrix(dict(zip(mats.stiffness, model.moduli(theta))))
    n = int(min(n, mats.n_dof - 2))
    lam, phi = spla.eigsh(K, k=n, M=M, sigma=0.0, which="LM", v0=arpack_start(K.shape[0]))
    order = np.argsort(lam)
    lam, phi = lam[order], phi[:, order]
    phi = phi / np.sqrt(np.einsum("ik,ik->k", phi, M @ phi))
    c, _ = mats.probe_vector(probe)
    height = np.abs(c @ phi) * np.abs(phi.T @ mats.inertia_load(inertia))
    return np.sqrt(np.abs(lam)) / (2 * np.pi), height


def frequencies_and_decays(lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(f_k in Hz, γ_k in 1/s)`` from eigenvalues ``Λ_k``: ``√Λ = ω + iγ``, ``f = ω/2π``."""
    root = np.sqrt(np.asarray(lam, complex))
    root = np.where(root.real < 0, -root, root)
    return root.real / (2 * np.pi), root.imag
