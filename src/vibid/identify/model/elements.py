"""C1 plate elements whose basis is built in element-local coordinates.

scikit-fem's :class:`skfem.ElementTriArgyris` (an :class:`skfem.ElementGlobal`) builds each
element's quintic basis by inverting the matrix of its 21 degrees of freedom applied to the
monomials ``x**i * y**j`` in *global* coordinates. On an element of size ``h`` at distance
``X`` from the origin that matrix has a condition number of order ``(X / h)**5``, so small
elements far from the origin lose digits (a mesh refined near the sensor gave a first
frequency of 220 Hz instead of 74.9 Hz).

:class:`ElementTriArgyrisLocal` spans the same space with the same degrees of freedom, but
its monomials are in the scaled local coordinates ``((x - xc) / s, (y - yc) / s)`` of each
element (``xc`` the centroid, ``s`` the element diameter), where they are well conditioned
on any mesh. Derivatives pick up the factors ``1 / s**k`` by the chain rule.
"""

from __future__ import annotations

import itertools
import threading

import numpy as np
from skfem import ElementTriArgyris
from skfem.element.discrete_field import DiscreteField

#: An element keeps state on its instance between calls (the monomials at the last points,
#: the parent's functionals swapped out while the basis is built), and one instance serves
#: every model of a mesh; threads build models at once (a loop round's refits,
#: :mod:`vibid.identify.engine.threads`, assemble with the JAX turn lent; a batch's sessions on
#: Prefect's thread runner), so its basis is evaluated under this lock.
#: (Without it, two threads' monomials met in one ``einsum``: a closed-loop candidate's
#: score failed with "operands could not be broadcast together".)
_STATE = threading.Lock()


class ElementTriArgyrisLocal(ElementTriArgyris):
    """The Argyris triangle (quintic, C1) with its basis built in element-local coordinates.

    Same degrees of freedom as :class:`skfem.ElementTriArgyris` (``u, u_x, u_y, u_xx, u_xy,
    u_yy`` at the vertices, ``u_n`` at the edge midpoints), so the two span the same finite
    element space; only the round-off differs. Use one instance per mesh (the basis inverse
    is cached on the instance, as in scikit-fem).
    """

    def _frame(self, mesh):
        p = mesh.p[:, mesh.t]  # (2, 3, nt)
        centre = p.mean(axis=1)  # (2, nt)
        edges = p - np.roll(p, 1, axis=1)
        scale = np.sqrt((edges**2).sum(axis=0)).max(axis=0)  # (nt,)
        return centre, scale

    def _local(self, F, centre, scale):
        """The monomials of ``F`` re-expressed as functions of global points."""
        out = {}
        for diff, f in F.items():
            k = len(diff)
            out[diff] = (
                lambda f_, k_: (
                    lambda x, y: f_((x - centre[0]) / scale, (y - centre[1]) / scale) / scale**k_
                )
            )(f, k)
        return out

    def _eval_dofs(self, mesh, tind=None):  # called from gbasis alone: under its lock
        self._centre, self._scale = self._frame(mesh)
        if tind is not None:
            raise NotImplementedError("ElementTriArgyrisLocal builds the basis of every cell")
        # the parent evaluates the functionals on ``self._pbasis``; swap in local monomials
        original = self._pbasis
        try:
            self._pbasis = {
                diff: [self._local({diff: f}, self._centre, self._scale)[diff] for f in fs]
                for diff, fs in original.items()
            }
            return super()._eval_dofs(mesh)
        finally:
            self._pbasis = original

    def gbasis(self, mapping, X, i, tind=None):
        with _STATE:
            return self._gbasis(mapping, X, i, tind)

    def _gbasis(self, mapping, X, i, tind):
        if tind is None:
            tind = np.arange(mapping.mesh.t.shape[1])
        if self.V is None:
            self._pbasis_init(self.maxdeg, self.dim, self.derivatives, self.tensorial_basis)
            self.V = np.linalg.inv(self._eval_dofs(mapping.mesh))
        V = self.V[tind]
        x = mapping.F(X, tind=tind)
        c = self._centre[:, tind]
        s = self._scale[tind]
        c, s = c[:, :, None], s[:, None]  # x is (2, cells, points)
        xl = ((x[0] - c[0]) / s, (x[1] - c[1]) / s)
        key = (x.shape, xl[0].tobytes(), xl[1].tobytes())
        if getattr(self, "_mono_key", None) != key:
            # monomials at the points, shared by the 21 basis functions of one call sequence
            self._mono_key = key
            self._mono = {
                diff: np.array([np.broadcast_to(f(*xl), x[0].shape) for f in fs])
                for diff, fs in self._pbasis.items()
            }
        U = [np.zeros((self.dim,) * k + x[0].shape) for k in range(self.derivatives + 1)]
        coef = V[:, :, i]  # (nt, N)
        for k in range(self.derivatives + 1):
            for diff in itertools.product(*((list(range(self.dim)),) * k)):
                U[k][diff] = np.einsum("tn,nt...->t...", coef, self._mono[diff]) / s**k
        return (DiscreteField(value=U[0], grad=U[1], hess=U[2]),)
