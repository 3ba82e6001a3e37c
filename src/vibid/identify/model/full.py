"""The full (sparse) FE model of the base-excited plate: the reference for the reduced one.

Base excitation (paper section 3.1, spec: the clamp moves as a rigid unit translation with
zero slope). Write the plate's displacement amplitude as ``u = 1 + u_rel``: the rigid unit
translation ``1`` has no curvature and no slope, so ``K 1 = 0``, and ``u_rel`` vanishes
with its slope on the clamp. With the convention ``exp(+iωt)`` the discrete problem on the
free dofs is::

    (K(θ, ω) − ω² M(θ)) u_rel = ω² M(θ) 1,    K = Σ_k s_k (1 + i β_k L(ω)) K_k,

and, where a term rocks the base about the clamp line by ``θ(ω)`` per unit translation
(a stand resonance), the rigid rotation ``x`` joins the translation: the load becomes
``ω² M (1 + θ x)`` and ``H = c·(1 + θ x) + c·u_rel``; with the stiffness terms ``k`` and
inertia terms of the model
(:class:`~vibid.identify.model.terms.PlateModel`: the six moduli, then the effects'), ``L``
its loss law (1 unless a term gives one), and the AFC at the sensor centre
``H(ω) = c·1 + c·u_rel`` (``c·1 = 1``), then each term's map (delay, gain). A positive
loss factor makes ``H`` lag past a resonance (``H ≈ −i × real`` at the peak).

:func:`afc_full` solves this with a sparse LU per frequency for given complex stiffness
coefficients; :func:`model_afc_full` evaluates a model at ``theta``;
:func:`make_full_afc_jax` wraps it as a JAX function of ``theta`` with an exact first
derivative (adjoint), for verifying the reduced model's gradients.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from vibid.identify.model.machinery import numpy_only, timed


def _solve_all(
    mats,
    coefficients,
    frequencies_hz,
    inertia=None,
    sensitivities=False,
    probe=None,
    rotation=False,
):
    """``coefficients``: (T,) complex, or (nf, T) per frequency, over ``mats.stiffness``;
    ``inertia`` and ``probe``: dicts of coefficients by name (default: the declared ones).
    With ``rotation`` the response to the rigid unit rotation about the clamp line instead
    of the translation (m per rad)."""
    names = list(mats.stiffness)
    omega = 2 * np.pi * np.asarray(frequencies_hz, float)
    C = np.broadcast_to(np.asarray(coefficients, complex), (omega.size, len(names)))
    f = mats.inertia_load(inertia, rotation=rotation)
    c, c_rigid = mats.probe_vector(probe)
    if rotation:
        c_rigid = mats.probe_rotation(probe)
    H = np.empty(omega.size, complex)
    S = np.empty((omega.size, len(names)), complex) if sensitivities else None
    # K - w^2 M on the matrices' shared pattern (assembly.SharedPattern), M's values summed
    # once and K's again only where its coefficients change
    pattern = mats.pattern
    M = pattern.data("M", inertia or {k: 1.0 for k in mats.inertia})
    K = None
    for k, w in enumerate(omega):
        if K is None or not np.array_equal(C[k], C[k - 1]):
            K = pattern.data("K", dict(zip(names, C[k])))
        lu = spla.splu(pattern.matrix(K - w**2 * M))
        u = lu.solve((w**2 * f).astype(complex))
        H[k] = c_rigid + c @ u
        if sensitivities:
            z = lu.solve(c.astype(complex), trans="T")  # adjoint: A^T z = c
            S[k] = [-(z @ (mats.stiffness[name] @ u)) for name in names]
    return H, S


def afc_full(
    mats, complex_moduli, frequencies_hz, inertia=None, probe=None, *, rotation: bool = False
) -> np.ndarray:
    """The plate's AFC ``H(f)`` of the full model (before any term's map on H).

    Parameters
    ----------
    mats : :class:`vibid.identify.model.assembly.PlateMatrices`.
    complex_moduli : (T,) complex coefficients ``s_k (1 + i β_k)`` of ``mats.stiffness``
        in its order (the six moduli in N·m first), or (nf, T) one row per frequency.
    frequencies_hz : (nf,) excitation frequencies in Hz.
    inertia : dict name -> coefficient of ``mats.inertia`` (default: all 1).
    probe : dict name -> coefficient of ``mats.probes`` (default: the declared sensor's).
    rotation : the response to the base's rigid unit rotation about the clamp line instead.

    Returns
    -------
    (nf,) complex128: sensor displacement over base displacement (or, with ``rotation``,
    over the base's rotation, m/rad).
    """
    return _solve_all(
        mats, complex_moduli, frequencies_hz, inertia, probe=probe, rotation=rotation
    )[0]


def afc_full_with_sensitivities(
    mats, complex_moduli, frequencies_hz, inertia=None, probe=None, *, rotation: bool = False
):
    """``H`` (nf,) and ``∂H/∂c_k`` (nf, T) by the adjoint method (``A`` is complex
    symmetric, so ``∂H/∂c_k = −zᵀ K_k u`` with ``Aᵀ z = c``)."""
    return _solve_all(
        mats,
        complex_moduli,
        frequencies_hz,
        inertia,
        sensitivities=True,
        probe=probe,
        rotation=rotation,
    )


def stiffness_coefficients(model, theta, omega, xp=np):
    """(nf, T) complex stiffness coefficients ``s_k (1 + i β_k L(ω))`` of ``model``."""
    s, b = model.moduli(theta, xp), model.losses(theta, xp)
    law = model.loss_law(theta, omega, xp)
    if law is None:
        return xp.broadcast_to(s * (1.0 + 1j * b), (omega.shape[0], s.shape[0]))
    return s[None, :] * (1.0 + 1j * b[None, :] * law[:, None])


@numpy_only
@timed("full-model checks")
def model_afc_full(mats, model, theta, frequencies_hz) -> np.ndarray:
    """(nf,) the observed AFC of ``model`` (a PlateModel) at ``theta``, full FE model."""
    theta = np.asarray(theta, float)
    omega = 2 * np.pi * np.asarray(frequencies_hz, float)
    inertia = dict(zip(model.inertia_names, model.inertia(theta)))
    probe = dict(zip(model.probe_names, model.probe(theta)))
    C = stiffness_coefficients(model, theta, omega)
    H = afc_full(mats, C, frequencies_hz, inertia, probe)
    if model.rotates_base:
        H = H + model.base_rotation(theta, omega, np) * afc_full(
            mats, C, frequencies_hz, inertia, probe, rotation=True
        )
    return model.afc_map(theta, omega, H, np)


def make_full_afc_jax(mats, model, frequencies_hz):
    """A JAX function ``theta -> H (nf,)`` of ``model`` backed by the sparse solver.

    Differentiable once (forward or reverse mode) through an exact adjoint JVP with
    respect to the stiffness coefficients (inertia and probe parameters are held); the
    sparse solves run on the host via :func:`jax.pure_callback`. For verification, not speed.
    """
    import jax
    import jax.numpy as jnp

    freqs = np.asarray(frequencies_hz, float)
    omega = 2 * np.pi * freqs
    nf, T = freqs.size, len(mats.stiffness)
    out_h = jax.ShapeDtypeStruct((nf,), jnp.complex128)
    out_s = jax.ShapeDtypeStruct((nf, T), jnp.complex128)

    def responses(rotation):
        def host(C, m, c):
            inertia = dict(zip(model.inertia_names, np.asarray(m)))
            probe = dict(zip(model.probe_names, np.asarray(c)))
            h, s = afc_full_with_sensitivities(
                mats, np.asarray(C), freqs, inertia, probe, rotation=rotation
            )
            return h.astype(np.complex128), s.astype(np.complex128)

        @jax.custom_jvp
        def plate(C, m, c):
            return jax.pure_callback(lambda c_, m_, p_: host(c_, m_, p_)[0], out_h, C, m, c)

        @plate.defjvp
        def _plate_jvp(primals, tangents):
            (C, m, c), (tC, _, _) = primals, tangents
            h, s = jax.pure_callback(host, (out_h, out_s), C, m, c)
            return h, jnp.sum(s * tC, axis=1)

        return plate

    translation, rotation = responses(False), responses(True)

    def fn(theta):
        theta = jnp.asarray(theta, jnp.float64)
        w = jnp.asarray(omega)
        C = stiffness_coefficients(model, theta, w, jnp)
        m = jax.lax.stop_gradient(model.inertia(theta, jnp))
        c = jax.lax.stop_gradient(model.probe(theta, jnp))
        H = translation(C, m, c)
        if model.rotates_base:
            H = H + model.base_rotation(theta, w, jnp) * rotation(C, m, c)
        return model.afc_map(theta, w, H, jnp)

    return fn
