"""The accelerometer's footprint: exact quadrature over a disc cut by a triangle mesh.

The sensor is a disc of radius ``r`` centred at ``c``; its mass is spread uniformly over the
disc, so the mass and rotary-inertia matrices gain ``∫_disc φ_i φ_j`` and
``∫_disc ∇φ_i · ∇φ_j`` terms. Marking whole cells would tie the sensor's mass to the mesh;
here each cell's intersection with the disc is integrated in polar coordinates about ``c``::

    ∫_{T ∩ disc} f dA = ∫ dθ ∫_{t_lo(θ)}^{t_hi(θ)} f(c + t (cos θ, sin θ)) t dt

where ``[t_lo, t_hi]`` is the part of the ray inside the triangle (three half-planes) and
inside the disc (``t ≤ r``). Between the angles of the triangle's vertices, of its edge
directions and of the circle's crossings with its edges, each limit is one curve: the
circle (a sector: Gauss–Legendre in θ and t, smooth) or one edge (a triangle with a vertex
at the centre: an exact triangle rule). Each cell's share is thus integrated to round-off,
even when the centre lies on or next to an edge: the disc's area comes out right to about
1e-12 on any mesh.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from skfem.quadrature import get_quadrature
from skfem.refdom import RefTri

#: Gauss points per angular piece of a circular sector (its integrand is a trigonometric
#: polynomial of degree <= 12 in the angle) and along each radius (a polynomial of degree
#: ``2 * 5 + 1`` for products of quintics, times ``t``).
N_ANGLE = 16
N_RADIAL = 7
#: Triangle rule exact for degree 12 (products of quintics have degree 10).
_TRI_RULE = get_quadrature(RefTri, 12)


def _edge_data(tri: np.ndarray):
    """Outward unit normals and offsets of a triangle's edges, ``n_k · x <= d_k`` inside."""
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    ccw = e1[0] * e2[1] - e1[1] * e2[0] > 0
    if not ccw:
        tri = tri[[0, 2, 1]]
    a, b = tri, np.roll(tri, -1, axis=0)
    e = b - a
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = (n * a).sum(axis=1)
    return tri, a, e, n, d


def _breakpoints(tri, a, e, centre, radius):
    """Angles at which the ray limits of one triangle may have a kink."""
    angles = []
    for p in tri:
        v = p - centre
        if np.hypot(*v) > 1e-14 * radius:
            angles.append(np.arctan2(v[1], v[0]))
    for ak, ek in zip(a, e):
        angles += [np.arctan2(ek[1], ek[0]), np.arctan2(-ek[1], -ek[0])]
        # circle crossings: |ak + s ek - c| = r, s in [0, 1]
        f = ak - centre
        A, B, C = ek @ ek, 2 * f @ ek, f @ f - radius**2
        disc = B * B - 4 * A * C
        if disc > -1e-9 * B * B:  # crossings, and tangency (a double root) as well
            root = np.sqrt(max(disc, 0.0))
            for s in ((-B - root) / (2 * A), (-B + root) / (2 * A)):
                if 0.0 <= s <= 1.0:
                    q = f + s * ek
                    angles.append(np.arctan2(q[1], q[0]))
    angles = np.mod(np.asarray(angles), 2 * np.pi)
    angles = np.unique(np.concatenate([[0.0], angles, [2 * np.pi]]))
    return angles


def _triangle_rule(p0, p1, p2):
    """Points (2, q) and signed-free weights (q,) of a degree-12 rule on a triangle."""
    X, W = _TRI_RULE
    J = np.column_stack([p1 - p0, p2 - p0])
    area2 = abs(np.linalg.det(J))
    return p0[:, None] + J @ X, W * area2


def cell_disc_quadrature(tri: np.ndarray, centre: np.ndarray, radius: float):
    """Quadrature points ``(2, n)`` and weights ``(n,)`` for ``T ∩ disc``.

    Each angular piece between breakpoints is a star-shaped region ``t_lo(θ) <= t <=
    t_hi(θ)`` about the centre; ``t_hi`` is either the circle (a circular sector,
    integrated in polar coordinates, smooth in θ) or one edge line (a triangle with a vertex
    at the centre, integrated by an exact triangle rule); the part below ``t_lo > 0`` (an
    edge line again) is subtracted the same way, with negative weights. Polynomials of
    degree <= 12 are integrated to round-off, whatever the position of the centre.

    Parameters
    ----------
    tri : (3, 2) array, the triangle's vertices in metres.
    centre : (2,) array, the disc's centre in metres.
    radius : float, the disc's radius in metres.

    Returns
    -------
    points : (2, n) array of points in metres (empty if the two do not overlap).
    weights : (n,) array in m² summing to the area of ``T ∩ disc``.
    """
    centre = np.asarray(centre, float)
    tri, a, e, n, d = _edge_data(np.asarray(tri, float))
    brk = _breakpoints(tri, a, e, centre, radius)
    room = d - n @ centre  # inside: t (n·dir) <= room
    ga, wa = np.polynomial.legendre.leggauss(N_ANGLE)
    gr, wr = np.polynomial.legendre.leggauss(N_RADIAL)

    def limits(theta):
        dirs = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        nd = dirs @ n.T
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = room / nd
        up = np.where(nd > 1e-15, bound, np.inf)
        low = np.where(nd < -1e-15, bound, -np.inf)
        blocked = ((np.abs(nd) <= 1e-15) & (room < 0)).any(axis=-1)
        return up, low, blocked

    pts, wts = [], []
    for lo, hi in zip(brk[:-1], brk[1:]):
        if hi - lo < 1e-14:
            continue
        mid = 0.5 * (lo + hi)
        up, low, blocked = limits(np.array([mid]))
        t_hi_m = min(up[0].min(), radius)
        t_lo_m = max(low[0].max(), 0.0)
        if blocked[0] or t_hi_m <= t_lo_m:
            continue
        for sign, which in ((1.0, "hi"), (-1.0, "lo")):
            if which == "hi":
                k = int(np.argmin(up[0]))
                on_circle = radius <= up[0][k]
            else:
                if t_lo_m <= 0.0:
                    continue
                k = int(np.argmax(low[0]))
                on_circle = False
            if on_circle:
                theta = 0.5 * (hi - lo) * (ga + 1) + lo
                t = 0.5 * radius * (gr + 1)
                x = centre[:, None, None] + np.stack([np.cos(theta), np.sin(theta)])[:, :, None] * t
                w = (0.5 * (hi - lo) * wa)[:, None] * (0.5 * radius * wr * t)[None, :]
                pts.append(x.reshape(2, -1))
                wts.append(sign * w.ravel())
            else:
                if abs(room[k]) <= 1e-12 * radius:
                    continue  # the centre lies on this edge: a region of zero area
                ends = []
                for th in (lo, hi):
                    # within the piece t <= r; clip the round-off at its ends
                    dvec = np.array([np.cos(th), np.sin(th)])
                    with np.errstate(divide="ignore"):
                        t_end = room[k] / (dvec @ n[k])
                    ends.append(centre + dvec * float(np.clip(t_end, 0.0, radius)))
                x, w = _triangle_rule(centre, ends[0], ends[1])
                pts.append(x)
                wts.append(sign * w)
    if not pts:
        return np.zeros((2, 0)), np.zeros(0)
    return np.concatenate(pts, axis=1), np.concatenate(wts)


def disc_cells(mesh, centre: np.ndarray, radius: float) -> np.ndarray:
    """Indices of the cells whose bounding box meets the disc's bounding box."""
    p = mesh.p[:, mesh.t]  # (2, 3, nt)
    lo, hi = p.min(axis=1), p.max(axis=1)
    hit = np.all((lo <= centre[:, None] + radius) & (hi >= centre[:, None] - radius), axis=0)
    return np.nonzero(hit)[0]


def disc_quadrature(mesh, centre, radius: float):
    """Per-cell quadrature over the disc for the cells it touches.

    Returns
    -------
    cells : (nc,) int array of cell indices.
    points : (2, nc, nq) array of points in metres (padding points carry zero weight).
    weights : (nc, nq) array of weights in m²; ``weights.sum()`` is the disc's area.
    """
    centre = np.asarray(centre, float)
    cells, pts, wts = [], [], []
    for c in disc_cells(mesh, centre, radius):
        x, w = cell_disc_quadrature(mesh.p[:, mesh.t[:, c]].T, centre, radius)
        if w.size and w.sum() > 0:
            cells.append(c)
            pts.append(x)
            wts.append(w)
    nq = max(w.size for w in wts)
    P = np.zeros((2, len(cells), nq))
    W = np.zeros((len(cells), nq))
    for k, (x, w) in enumerate(zip(pts, wts)):
        centroid = mesh.p[:, mesh.t[:, cells[k]]].mean(axis=1)
        P[:, k, :] = centroid[:, None]
        P[:, k, : w.size] = x
        W[k, : w.size] = w
    return np.asarray(cells), P, W


def assemble_disc(basis, centre, radius: float):
    """``∫_disc φ_i φ_j`` and ``∫_disc ∇φ_i · ∇φ_j`` as sparse (N, N) matrices.

    Parameters
    ----------
    basis : a scalar skfem ``CellBasis`` on a triangle mesh.
    centre : (2,) disc centre in metres; radius : disc radius in metres.

    Returns
    -------
    (mass, grad) : scipy sparse matrices in m² and 1 (dimensionless), and the integrated
    area in m² (a check: it equals ``pi * radius**2`` to round-off).
    """
    mesh, mapping, elem = basis.mesh, basis.mapping, basis.elem
    cells, P, W = disc_quadrature(mesh, centre, radius)
    X = mapping.invF(P, tind=cells)
    fields = [elem.gbasis(mapping, X, i, tind=cells)[0] for i in range(basis.Nbfun)]
    val = np.array([f.value for f in fields])  # (nb, nc, nq)
    grd = np.array([f.grad for f in fields])  # (nb, 2, nc, nq)
    m_loc = np.einsum("icq,jcq,cq->cij", val, val, W)
    g_loc = np.einsum("idcq,jdcq,cq->cij", grd, grd, W)
    dofs = basis.element_dofs[:, cells]  # (nb, nc)
    rows = np.broadcast_to(dofs.T[:, :, None], m_loc.shape).ravel()
    cols = np.broadcast_to(dofs.T[:, None, :], m_loc.shape).ravel()
    shape = (basis.N, basis.N)
    mass = coo_matrix((m_loc.ravel(), (rows, cols)), shape=shape).tocsr()
    grad = coo_matrix((g_loc.ravel(), (rows, cols)), shape=shape).tocsr()
    return mass, grad, float(W.sum())


def _fields_at(basis, points: np.ndarray):
    """Values and gradients of every basis function at ``points`` (2, n), as sparse
    (n, N) matrices ``(value, d/dx, d/dy)``."""
    from scipy.sparse import csr_matrix

    mesh, mapping, elem = basis.mesh, basis.mapping, basis.elem
    cells = mesh.element_finder(mapping=mapping)(*points)
    X = mapping.invF(points[:, :, None], tind=cells)
    fields = [elem.gbasis(mapping, X, i, tind=cells)[0] for i in range(basis.Nbfun)]
    rows = np.tile(np.arange(points.shape[1]), basis.Nbfun)
    cols = basis.element_dofs[:, cells].ravel()
    shape = (points.shape[1], basis.N)

    def mat(parts):
        return csr_matrix((np.array(parts).ravel(), (rows, cols)), shape=shape)

    return (
        mat([f.value[:, 0] for f in fields]),
        mat([f.grad[0][:, 0] for f in fields]),
        mat([f.grad[1][:, 0] for f in fields]),
    )


def polynomial_through(f0, others, places) -> list:
    """``[c_1, ..., c_n]`` of ``f(t) = f0 + Σ_k c_k t^k`` through ``(0, f0)`` and
    ``(places[i], others[i])`` (n places, none of them 0; arrays or sparse matrices)."""
    t = np.asarray(places, float)
    n = t.size
    inv = np.linalg.inv(t[:, None] ** np.arange(1, n + 1)[None, :])
    diffs = [f - f0 for f in others]
    return [sum(inv[k, i] * diffs[i] for i in range(n)) for k in range(n)]


def shifted_disc(basis, centre, radius: float, direction, places, shifts=None) -> dict:
    """The disc's ``∫ φ_i φ_j`` and ``∫ ∇φ_i · ∇φ_j`` when it moves by ``s`` along the unit
    vector ``direction`` (m), as polynomials in ``s``.

    At each of the disc's quadrature points ``p`` the basis functions are interpolated by
    the polynomial through ``s = 0`` and the n ``places`` (m): ``a(s) = φ(p) + Σ s^k c_k``;
    then ``∫ a aᵀ = Σ_k s^k M_k`` (k = 0..2n; a Gram matrix, so positive for every ``s``,
    and exact wherever the field is a polynomial of degree n along ``direction``).

    With ``shifts`` the disc lies ``shifts[i]`` (m) away where the polynomial's variable is
    ``places[i]`` (a parameter that moves the disc, not the distance itself).

    Returns ``{k: (uv_k, grad_k)}`` for k = 1..2n, sparse (N, N) in m²/m^k and 1/m^k
    (``M_0`` is :func:`assemble_disc`'s).
    """
    from scipy.sparse import diags

    cells, P, W = disc_quadrature(basis.mesh, centre, radius)
    keep = W.ravel() != 0
    pts = P.reshape(2, -1)[:, keep]
    w = diags(W.ravel()[keep])
    e = np.asarray(direction, float)[:, None]
    here = _fields_at(basis, pts)
    there = [_fields_at(basis, pts + t * e) for t in (places if shifts is None else shifts)]
    n = len(places)
    out = {k: [0.0, 0.0] for k in range(1, 2 * n + 1)}
    for comp in range(3):  # value, d/dx, d/dy
        a = [here[comp]] + polynomial_through(here[comp], [f[comp] for f in there], places)
        for i in range(n + 1):
            for j in range(n + 1):
                if i + j:
                    out[i + j][0 if comp == 0 else 1] += a[i].T @ w @ a[j]
    return {k: (uv.tocsr(), grad.tocsr()) for k, (uv, grad) in out.items()}
