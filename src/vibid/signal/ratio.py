"""The AFC point ``H = X_response / X_base`` and its covariance by the delta method.

For a holomorphic ``f(z)``, the real Jacobian of ``(Re f, Im f)`` with respect to
``(Re z, Im z)`` is ``R(f') = [[Re f', -Im f'], [Im f', Re f']]``. With ``H = X_r / X_b``,
``∂H/∂X_r = 1/X_b`` and ``∂H/∂X_b = -H/X_b``, so

    Cov(Re H, Im H) = J Σ Jᵀ,   J = [R(-H/X_b), R(1/X_b)],

``Σ`` the 4×4 covariance of ``(Re X_b, Im X_b, Re X_r, Im X_r)``: both channels' noise, and
the shared frequency's, which correlates them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["phasor_ratio"]


def _real_jacobian(c: np.ndarray) -> np.ndarray:
    """``R(c)`` of shape (..., 2, 2) for complex ``c``."""
    return np.stack([np.stack([c.real, -c.imag], -1), np.stack([c.imag, c.real], -1)], -2)


def phasor_ratio(
    base: np.ndarray, response: np.ndarray, cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``H = response / base`` and the covariance of ``(Re H, Im H)``.

    Parameters
    ----------
    base, response : (S,) complex phasors (any common unit).
    cov : (S, 4, 4) covariance of (Re base, Im base, Re response, Im response).

    Returns
    -------
    h : (S,) complex.
    cov_h : (S, 2, 2).
    """
    base = np.asarray(base, dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        h = np.asarray(response, dtype=complex) / base
        jac = np.concatenate([_real_jacobian(-h / base), _real_jacobian(1.0 / base)], axis=-1)
        return h, jac @ cov @ np.swapaxes(jac, -1, -2)
