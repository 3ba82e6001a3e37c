"""The full (sparse) FE model of the base-excited plate: the reference for the reduced one.

Base excitation (paper section 3.1, spec: the clamp moves as a rigid unit translation with
zero slope). Write the plate's displacement amplitude as ``u = 1 + u_rel``: the rigid unit
translation ``1`` has no curvature, so ``K 1 = 0``, and ``u_rel`` vanishes with its slope on
the clamp. With the convention ``exp(+iωt)`` the discrete problem on the free dofs is::

    (K(θ) − ω² M) u_rel = ω² M 1,        K(θ) = Σ_α D_α (1 + i β_α) K_α,

where ``M`` holds the plate's and the sensor's translational and rotary inertia (``∇1 = 0``
so only the translational part loads), and the AFC at the sensor centre is
``H(ω) = c·1 + c·u_rel`` with ``c·1 = 1``. A positive loss factor makes ``H`` lag past a
resonance (``H ≈ −i × real`` at the peak).

:func:`afc_full` solves this with a sparse LU per frequency (numpy in, numpy out);
:func:`make_full_afc_jax` wraps it as a JAX function of the six complex moduli with an
exact first derivative (adjoint), for verifying the reduced model's gradients.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse.linalg as spla

from vibid.identify.forms import MODULI



def _solve_all(mats, complex_moduli, frequencies_hz, sensitivities: bool = False):
    K = mats.stiffness_matrix(dict(zip(MODULI, np.asarray(complex_moduli, complex))))
    M = mats.inertia_matrix()
    f = mats.inertia_load()
    c = mats.probe
    omega = 2 * np.pi * np.asarray(frequencies_hz, float)
    H = np.empty(omega.size, complex)
    S = np.empty((omega.size, len(MODULI)), complex) if sensitivities else None
    for k, w in enumerate(omega):
        lu = spla.splu((K - w**2 * M).tocsc())
        u = lu.solve((w**2 * f).astype(complex))
        H[k] = mats.probe_rigid + c @ u
        if sensitivities:
            z = lu.solve(c.astype(complex), trans="T")  # adjoint: A^T z = c
            S[k] = [-(z @ (mats.stiffness[name] @ u)) for name in MODULI]
    return H, S


def afc_full(mats, complex_moduli, frequencies_hz) -> np.ndarray:
    """The AFC ``H(f)`` of the full model.

    Parameters
    ----------
    mats : :class:`vibid.identify.assembly.PlateMatrices`.
    complex_moduli : (6,) complex ``D_α (1 + i β_α)`` in N·m, :data:`MODULI` order.
    frequencies_hz : (nf,) excitation frequencies in Hz.

    Returns
    -------
    (nf,) complex128: sensor displacement over base displacement.
    """
    return _solve_all(mats, complex_moduli, frequencies_hz)[0]


def afc_full_with_sensitivities(mats, complex_moduli, frequencies_hz):
    """``H`` (nf,) and ``∂H/∂D̂_α`` (nf, 6) by the adjoint method (``A`` is complex
    symmetric, so ``∂H/∂D̂_α = −zᵀ K_α u`` with ``Aᵀ z = c``)."""
    return _solve_all(mats, complex_moduli, frequencies_hz, sensitivities=True)


def make_full_afc_jax(mats, frequencies_hz):
    """A JAX function ``complex_moduli (6,) -> H (nf,)`` backed by the sparse solver.

    Differentiable once (forward or reverse mode) through an exact adjoint JVP; the sparse
    solves run on the host via :func:`jax.pure_callback`. For verification, not speed.
    """
    freqs = np.asarray(frequencies_hz, float)
    nf = freqs.size
    out_h = jax.ShapeDtypeStruct((nf,), jnp.complex128)
    out_s = jax.ShapeDtypeStruct((nf, len(MODULI)), jnp.complex128)

    def host(dc):
        h, s = afc_full_with_sensitivities(mats, np.asarray(dc), freqs)
        return h.astype(np.complex128), s.astype(np.complex128)

    @jax.custom_jvp
    def full(dc):
        return jax.pure_callback(lambda d: host(d)[0], out_h, dc)

    @full.defjvp
    def _full_jvp(primals, tangents):
        (dc,), (tdc,) = primals, tangents
        h, s = jax.pure_callback(host, (out_h, out_s), dc)
        return h, s @ tdc

    return full
