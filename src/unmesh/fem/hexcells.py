"""Hexahedral cells as isoparametric elements: the trilinear basis and Wilson–Taylor incompatible modes.

Beyond the thesis (which integrates mean value shape functions, 9.8–9.10 and 9.19, on every
cell). The cantilever study (docs/fem_cantilever_study.md) shows that on cube cells the
mean value basis, not the quadrature, makes bending too stiff: its trace on a face is
linear on each triangle of the face, so the cell cannot bend without parasitic shear.
These alternatives apply to *hexahedral cells* (8 nodes, 6 quadrilateral faces, three
faces at every corner, e.g. every cell of :func:`unmesh.fem.hex_grid`); every other cell
keeps the mean value element.

* ``trilinear``: the standard 8-node brick (Q1), 2×2×2 Gauss points. Still locks in
  bending, less than the mean value cell.
* ``incompatible``: Q1 plus the three internal bubble modes ``1 - ξ_k²`` per displacement
  component (Wilson, Taylor, Doherty & Ghaboussi 1973), with Taylor's gradient taken at the
  cell centre (``J₀``) and scaled by ``det J₀ / det J`` so the constant-strain patch test
  passes on distorted cells; the 9 internal unknowns are condensed out per cell. The element
  reproduces pure bending of a box exactly.

Example
-------
>>> from unmesh.fem import hex_grid
>>> is_hex, corners = hex_cells(hex_grid((2, 1, 1)))
>>> is_hex.tolist(), corners.shape
([True, True], (2, 8))
"""

from __future__ import annotations

import numpy as np

from unmesh.fem.mesh import PolyMesh

__all__ = ["REFERENCE_CORNERS", "hex_cells", "incompatible_stiffness", "trilinear_gradients"]

#: Reference coordinates (ξ, η, ζ) ∈ {-1, 1}³ of the corners, in the order of :func:`hex_cells`.
REFERENCE_CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [-1, 1, -1], [1, 1, -1],
                              [-1, -1, 1], [1, -1, 1], [-1, 1, 1], [1, 1, 1]], dtype=np.float64)

_G = 1.0 / np.sqrt(3.0)
GAUSS_2 = REFERENCE_CORNERS * _G  # 2×2×2 Gauss points (weights 1)


def hex_cells(mesh: PolyMesh) -> tuple[np.ndarray, np.ndarray]:
    """Which elements are hexahedra, and their local nodes ordered as :data:`REFERENCE_CORNERS`.

    Parameters
    ----------
    mesh : PolyMesh

    Returns
    -------
    is_hex : (E,) bool
        8 nodes, 6 planar four-node faces (within 1e-9 of the cell diagonal), every node on
        exactly three edges of the element.
    corners : (H, 8) int64
        For the hexahedra in element order: the *local* node index (into the element's
        sorted node list, :meth:`PolyMesh.element_nodes`) of each reference corner, with a
        positive Jacobian at the cell centre.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> hex_cells(hex_grid((1, 1, 1)))[1].tolist()
    [[0, 1, 2, 3, 4, 5, 6, 7]]
    """
    noff, nodes = mesh.element_nodes()
    nf = np.diff(mesh.elem_offsets)
    flen = np.diff(mesh.face_offsets)
    quads_only = np.zeros(mesh.n_elements, bool)
    if mesh.n_elements:
        eid_f = np.repeat(np.arange(mesh.n_elements), nf)
        bad = np.bincount(eid_f, weights=(flen[mesh.elem_faces] != 4), minlength=mesh.n_elements)
        quads_only = bad == 0
    cand = np.flatnonzero((np.diff(noff) == 8) & (nf == 6) & quads_only)
    if not len(cand):
        return np.zeros(mesh.n_elements, bool), np.zeros((0, 8), np.int64)
    # the 24 face edges of every candidate in local node numbers -> adjacency (H, 8, 8)
    fstart = mesh.elem_offsets[cand]
    faces = mesh.elem_faces[fstart[:, None] + np.arange(6)]                # (H, 6)
    quad = mesh.face_nodes[mesh.face_offsets[faces][..., None] + np.arange(4)]  # (H, 6, 4) global
    enodes = nodes[noff[cand][:, None] + np.arange(8)]                     # (H, 8) sorted
    loc = np.empty_like(quad)
    for h in range(4):  # searchsorted per row, vectorised over the cells
        loc[..., h] = (enodes[:, None, :] < quad[..., h, None]).sum(axis=2)
    adj = np.zeros((len(cand), 8, 8), bool)
    rows = np.repeat(np.arange(len(cand)), 24)
    a = loc.reshape(-1, 4)
    b = np.roll(a, -1, axis=1)
    adj[rows, a.ravel(), b.ravel()] = True
    adj[rows, b.ravel(), a.ravel()] = True
    ok = np.all(adj.sum(axis=2) == 3, axis=1) & ~adj[:, np.arange(8), np.arange(8)].any(axis=1)
    # planar faces (Newell normal; within 1e-9 of the cell's diagonal): else the bilinear face
    # of the trilinear map is not the polyhedron's face
    qp = mesh.points[quad]                                                 # (H, 6, 4, 3)
    nrm = np.cross(qp, np.roll(qp, -1, axis=2)).sum(axis=2)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=-1, keepdims=True), 1e-300)
    off = np.einsum("hfkj,hfj->hfk", qp - qp.mean(axis=2, keepdims=True), nrm)
    diag = np.linalg.norm(np.ptp(mesh.points[enodes], axis=1), axis=1)
    ok &= np.abs(off).max(axis=(1, 2)) <= 1e-9 * diag
    # corner 0 = local node 0; its three neighbours are corners 1, 2, 4; the common neighbours
    # of two of them (other than node 0) are corners 3, 5, 6; the node left is corner 7
    H = len(cand)
    r = np.arange(H)
    nb = np.argsort(~adj[:, 0], axis=1, kind="stable")[:, :3]                # (H, 3) ascending local ids
    corners = np.zeros((H, 8), np.int64)
    corners[:, 1], corners[:, 2], corners[:, 4] = nb[:, 0], nb[:, 1], nb[:, 2]
    for c, (p, q) in ((3, (1, 2)), (5, (1, 4)), (6, (2, 4))):
        common = adj[r, corners[:, p]] & adj[r, corners[:, q]]
        common[:, 0] = False
        ok &= common.sum(axis=1) == 1
        corners[:, c] = np.argmax(common, axis=1)
    used = np.zeros((H, 8), bool)
    used[r[:, None], corners[:, :7]] = True
    ok &= used[:, :7].sum(axis=1) == 7
    corners[:, 7] = np.argmin(used, axis=1)
    ok &= adj[r, corners[:, 7], corners[:, 3]] & adj[r, corners[:, 7], corners[:, 5]] & adj[r, corners[:, 7],
                                                                                          corners[:, 6]]
    # orientation: swap η and ζ where the Jacobian at the centre is negative
    x = mesh.points[enodes[r[:, None], corners]]                           # (H, 8, 3)
    J0 = np.einsum("hak,aj->hkj", x, REFERENCE_CORNERS) / 8.0              # ∂x_k/∂ξ_j at ξ = 0
    flip = np.linalg.det(J0) < 0
    corners[flip] = corners[flip][:, [0, 1, 4, 5, 2, 3, 6, 7]]
    is_hex = np.zeros(mesh.n_elements, bool)
    is_hex[cand[ok]] = True
    return is_hex, corners[ok]


def _shape_derivatives(xi: np.ndarray) -> np.ndarray:
    """∂N_a/∂ξ_j of the trilinear shape functions at points ``xi`` (P, 3): (P, 8, 3)."""
    s = REFERENCE_CORNERS
    f = 1.0 + xi[:, None, :] * s[None]                                     # (P, 8, 3) factors (1 + ξ_j s_aj)
    d = np.empty_like(f)
    for j in range(3):
        o = [k for k in range(3) if k != j]
        d[..., j] = s[None, :, j] * f[..., o[0]] * f[..., o[1]]
    return d / 8.0


def trilinear_gradients(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Physical gradients of the trilinear basis at the 2×2×2 Gauss points of hexahedra.

    Parameters
    ----------
    x : (H, 8, 3) float64
        Corner positions in the order of :data:`REFERENCE_CORNERS`.

    Returns
    -------
    grads : (H, 8, 8, 3)
        ∇N_a at Gauss point q: ``grads[h, q, a]``.
    weights : (H, 8)
        ``det J`` at the Gauss points (the Gauss weights are 1).

    Example
    -------
    >>> g, w = trilinear_gradients(REFERENCE_CORNERS[None] * 0.5)  # the unit cube
    >>> round(float(w.sum()), 12), bool(abs(g.sum(axis=2)).max() < 1e-12)
    (1.0, True)
    """
    dN = _shape_derivatives(GAUSS_2)                                        # (8q, 8a, 3j)
    J = np.einsum("hak,qaj->hqkj", x, dN)                                  # ∂x_k/∂ξ_j
    det = np.linalg.det(J)
    grads = np.einsum("qaj,hqjk->hqak", dN, np.linalg.inv(J))              # ∂N/∂x_k = ∂N/∂ξ_j ∂ξ_j/∂x_k
    return grads, det


def _lame_blocks(ga: np.ndarray, gb: np.ndarray, w: np.ndarray, lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Σ_q w (λ g_a,i g_b,j + μ g_a,j g_b,i + μ δ_ij g_a·g_b): blocks (H, A, B, 3, 3)."""
    t1 = np.einsum("hq,hqai,hqbj->habij", w, ga, gb)
    dot = np.einsum("hq,hqak,hqbk->hab", w, ga, gb)
    return (lam[:, None, None, None, None] * t1 + mu[:, None, None, None, None] * t1.transpose(0, 1, 2, 4, 3)
            + mu[:, None, None, None, None] * dot[..., None, None] * np.eye(3))


def incompatible_stiffness(x: np.ndarray, lam: np.ndarray, mu: np.ndarray,
                           shift: np.ndarray | None = None) -> np.ndarray:
    """Condensed stiffness of Wilson–Taylor incompatible-mode hexahedra: blocks (H, 8, 8, 3, 3).

    Parameters
    ----------
    x : (H, 8, 3) float64
        Corner positions in the order of :data:`REFERENCE_CORNERS`.
    lam, mu : (H,) float64
        Lamé parameters.
    shift : (H, 8, 3) float64, optional
        Constant added to the trilinear gradients at every Gauss point (the interface
        consistency correction of :func:`unmesh.fem.integration.integrate_elements`).

    Returns
    -------
    (H, 8, 8, 3, 3) float64
        Block (a, b) couples corners a and b; ``K = K_uu - K_ua K_aa⁻¹ K_au`` with the
        internal modes ``1 - ξ_k²`` (gradients at J₀ scaled by det J₀/det J).

    Example
    -------
    >>> K = incompatible_stiffness(REFERENCE_CORNERS[None] * 0.5, np.array([1.0]), np.array([1.0]))
    >>> K.shape, bool(abs(K.sum(axis=(1, 2))).max() < 1e-12)  # rigid translations: no force
    ((1, 8, 8, 3, 3), True)
    """
    H = len(x)
    gu, det = trilinear_gradients(x)
    if shift is not None:
        gu = gu + shift[:, None]
    J0 = np.einsum("hak,aj->hkj", x, REFERENCE_CORNERS) / 8.0
    det0 = np.linalg.det(J0)
    inv0 = np.linalg.inv(J0)                                               # ∂ξ_j/∂x_k at the centre
    dB = np.zeros((8, 3, 3))                                               # ∂(1-ξ_m²)/∂ξ_j at the Gauss points
    for m in range(3):
        dB[:, m, m] = -2.0 * GAUSS_2[:, m]
    ga = np.einsum("qmj,hjk->hqmk", dB, inv0) * (det0[:, None] / det)[..., None, None]
    g = np.concatenate([gu, ga], axis=2)                                   # (H, 8q, 11, 3)
    blocks = _lame_blocks(g, g, det, lam, mu)                              # (H, 11, 11, 3, 3)
    full = blocks.transpose(0, 1, 3, 2, 4).reshape(H, 33, 33)
    kuu, kua, kaa = full[:, :24, :24], full[:, :24, 24:], full[:, 24:, 24:]
    cond = kuu - kua @ np.linalg.solve(kaa, kua.transpose(0, 2, 1))
    cond = 0.5 * (cond + cond.transpose(0, 2, 1))
    return cond.reshape(H, 8, 3, 8, 3).transpose(0, 1, 3, 2, 4)
