"""Weak forms of the Kirchhoff plate, one per physical term.

With the curvature vector ``κ(w) = (w,xx, w,yy, 2 w,xy)`` and the moment law
``M = D κ`` of the session format, the strain energy density is ``½ κᵀ D κ``; its bilinear
form ``κ(u)ᵀ D κ(v)`` splits into one form per modulus::

    a(u, v) = D11 b11 + D12 b12 + D16 b16 + D22 b22 + D26 b26 + D66 b66

    b11 = u,xx v,xx                    b22 = u,yy v,yy
    b12 = u,xx v,yy + u,yy v,xx        b66 = 4 u,xy v,xy
    b16 = 2 (u,xx v,xy + u,xy v,xx)    b26 = 2 (u,yy v,xy + u,xy v,yy)

The kinetic energy of the plate (mass per area ``ρ h``, rotary inertia ``ρ h³ / 12``) gives
``m(u, v) = ∫ ρh (u v + h²/12 ∇u·∇v)`` (paper eq. 4.1.1, with ``e = h / 2``). The forms
below carry no coefficients; :mod:`vibid.identify.model.assembly` scales them.
"""

from skfem import BilinearForm
from skfem.helpers import dd, dot, grad

from vibid.identify.model.terms import MODULI  # noqa: F401  (the names of the six forms, read beside them)


@BilinearForm
def bending_11(u, v, _):
    return dd(u)[0, 0] * dd(v)[0, 0]


@BilinearForm
def bending_12(u, v, _):
    return dd(u)[0, 0] * dd(v)[1, 1] + dd(u)[1, 1] * dd(v)[0, 0]


@BilinearForm
def bending_16(u, v, _):
    return 2.0 * (dd(u)[0, 0] * dd(v)[0, 1] + dd(u)[0, 1] * dd(v)[0, 0])


@BilinearForm
def bending_22(u, v, _):
    return dd(u)[1, 1] * dd(v)[1, 1]


@BilinearForm
def bending_26(u, v, _):
    return 2.0 * (dd(u)[1, 1] * dd(v)[0, 1] + dd(u)[0, 1] * dd(v)[1, 1])


@BilinearForm
def bending_66(u, v, _):
    return 4.0 * dd(u)[0, 1] * dd(v)[0, 1]


@BilinearForm
def translational_inertia(u, v, _):
    return u * v


@BilinearForm
def rotary_inertia(u, v, _):
    return dot(grad(u), grad(v))


@BilinearForm
def edge_rotation(u, v, w):
    """``∂u/∂n ∂v/∂n`` on a boundary (a rotational spring along an edge, per unit length)."""
    return dot(grad(u), w.n) * dot(grad(v), w.n)


BENDING_FORMS = {
    "D11": bending_11,
    "D12": bending_12,
    "D16": bending_16,
    "D22": bending_22,
    "D26": bending_26,
    "D66": bending_66,
}


@BilinearForm
def slope_x(u, v, _):
    """``u,x v,x`` (a transverse-shear correction along x)."""
    return grad(u)[0] * grad(v)[0]


@BilinearForm
def slope_y(u, v, _):
    """``u,y v,y`` (a transverse-shear correction along y)."""
    return grad(u)[1] * grad(v)[1]
