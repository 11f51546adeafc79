"""Element integration (9.17–9.19) with the optional consistency correction.

Each non-tetrahedral element gets one sample per vertex at ``0.8 x_i + 0.2 c`` and
one per boundary triangle at ``0.9 c_f + 0.1 c`` (``c`` the vertex centroid),
weighted by the volume fractions μ_i (9.17) and ν_f (9.18) times the element
volume and halved, so the weights of an element sum to its volume (the reading
of (9.19) in the reading notes). Tetrahedra use their centroid with weight V and
exact linear gradients.

Consistency correction (beyond the thesis; Talischi et al. 2015 for polygons):
the heuristic quadrature does not integrate ∇φ_i exactly, so a linear field is
not reproduced (the patch test fails). The divergence theorem gives the exact
integral ``∫_E ∇φ_i = ∮ φ_i n dA = Σ_{T∋i} A_T n_T / 3`` (φ_i is linear on each
boundary triangle). Adding ``(exact_i - Σ_q w_q ∇φ_i(p_q)) / V`` to every sampled
gradient makes the quadrature exact for ∇φ_i and keeps Σ_i x_i ∇φ_iᵀ = I at every
sample, so constant strains are represented exactly and the patch test passes.

Other rules (beyond the thesis; :class:`IntegrationRule`, study in
docs/fem_cantilever_study.md): ``subtet`` integrates the same mean value basis with Gauss
points in the centroid cones of the boundary triangles (converging to the exact integral);
``trilinear`` and ``incompatible`` give hexahedral cells the trilinear brick (the latter with
Wilson–Taylor incompatible modes, :mod:`unmesh.fem.hexcells`), which removes most of the
bending over-stiffness of mean value cubes (a basis effect, not a quadrature one).

Example
-------
>>> from unmesh.fem import voronoi_foam
>>> integ = integrate_elements(voronoi_foam(5, seed=2))
>>> bool(abs(integ.volumes.sum() - 1.0) < 1e-12)
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unmesh.errors import InputError
from unmesh.fem import _fe_kernels as FK
from unmesh.fem.mesh import PolyMesh

__all__ = ["ElementIntegration", "IntegrationRule", "gather_csr", "integrate_elements", "merge_csr"]

RULES = ("thesis", "subtet", "trilinear", "incompatible")


@dataclass(frozen=True)
class IntegrationRule:
    """Which quadrature (and, for hexahedral cells, which element) the non-tetrahedral elements get.

    Attributes
    ----------
    kind : str
        ``"thesis"`` (default): mean value basis, the vertex and face samples of (9.19),
        ``n + m`` samples.
        ``"subtet"``: mean value basis; the element is split into the cones from its vertex
        centroid to its boundary triangles and each cone gets a Gauss (Stroud conical
        product) rule with ``order³`` points, exact for polynomials of degree
        ``2·order - 1`` on the cone. Converges to the exactly integrated mean value
        stiffness (see docs/fem_cantilever_study.md).
        ``"trilinear"``: hexahedral cells (:func:`unmesh.fem.hexcells.hex_cells`) get the
        trilinear basis at 2×2×2 Gauss points (no consistency correction: it passes the
        patch test by itself); other cells the thesis rule.
        ``"incompatible"``: a stiffness option, not a quadrature: hexahedral cells get the
        condensed Wilson–Taylor incompatible-mode stiffness
        (:func:`unmesh.fem.hexcells.incompatible_stiffness`), other cells the thesis rule.
        Accepted by :func:`~unmesh.fem.assembly.element_stiffness`,
        :func:`~unmesh.fem.assembly.stiffness_matrix` and
        :func:`~unmesh.fem.assembly.solve_static` given a mesh; :func:`integrate_elements`
        gives the ``trilinear`` samples for it (the compatible part).
    order : int
        Gauss points per direction of the ``subtet`` rule (1–8; ignored by the others).

    Tetrahedra always get their exact one-point rule (their basis is linear). The volumes
    and volume fractions μ (9.17, lumped masses 9.21) are the thesis ones under every rule.

    Example
    -------
    >>> IntegrationRule("subtet", 2).points_per_cone
    8
    """

    kind: str = "thesis"
    order: int = 2

    def __post_init__(self) -> None:
        if self.kind not in RULES:
            raise InputError(f"integration: expected one of {', '.join(RULES)}, got {self.kind!r}")
        if isinstance(self.order, bool) or not isinstance(self.order, int | np.integer) or not 1 <= self.order <= 8:
            raise InputError(f"integration order: expected an integer in [1, 8], got {self.order!r}")

    @property
    def points_per_cone(self) -> int:
        """Samples per boundary-triangle cone of the ``subtet`` rule (``order³``)."""
        return int(self.order) ** 3

    @classmethod
    def parse(cls, value: IntegrationRule | str | None) -> IntegrationRule:
        """A rule from a rule, ``None`` (thesis) or a string ``"thesis"``, ``"subtet"``, ``"subtet:3"``.

        Example
        -------
        >>> IntegrationRule.parse("subtet:3")
        IntegrationRule(kind='subtet', order=3)
        """
        if value is None:
            return cls()
        if isinstance(value, IntegrationRule):
            return value
        if not isinstance(value, str):
            raise InputError(f"integration: expected an IntegrationRule or a string, got {type(value).__name__}")
        kind, _, order = value.partition(":")
        if not order:
            return cls(kind)
        try:
            return cls(kind, int(order))
        except ValueError:
            raise InputError(f"integration: expected 'kind' or 'kind:order' with an integer order, got {value!r}") \
                from None


def cone_rule(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Stroud conical-product Gauss rule on the unit tetrahedron: barycentric points (k, 4), weights (k,).

    ``k = order³``; the weights sum to 1 (fractions of the tetrahedron's volume) and the rule
    integrates polynomials of degree ``2·order - 1`` exactly. The first barycentric coordinate
    belongs to the apex.

    Example
    -------
    >>> lam, w = cone_rule(2)
    >>> lam.shape, round(float(w.sum()), 12)
    ((8, 4), 1.0)
    """
    from scipy.special import roots_jacobi

    def jacobi01(alpha: int) -> tuple[np.ndarray, np.ndarray]:
        x, w = roots_jacobi(order, alpha, 0)
        return (x + 1) / 2, w / 2 ** (alpha + 1)

    a, wa = jacobi01(2)
    b, wb = jacobi01(1)
    c, wc = jacobi01(0)
    A, B, Cc = (g.ravel() for g in np.meshgrid(a, b, c, indexing="ij"))
    W = (wa[:, None, None] * wb[None, :, None] * wc[None, None, :]).ravel() * 6.0
    x = A
    y = (1 - A) * B
    z = (1 - A) * (1 - B) * Cc
    return np.c_[1 - x - y - z, x, y, z], W


def gather_csr(offsets: np.ndarray, data: np.ndarray, idx: np.ndarray, *,
               fast: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``idx`` of a CSR array: ``(new_offsets, new_data)``.

    ``offsets`` (R+1,) int, ``data`` (offsets[-1], ...) any dtype, ``idx`` (k,) int.
    ``fast`` copies the row ranges with a numba kernel (no (Σ len,) index arrays; the
    re-integration after a cut gathers ~10⁷ stiffness entries); ``fast=False`` is the
    vectorised numpy reference.

    Example
    -------
    >>> gather_csr(np.array([0, 2, 3]), np.array([5, 6, 7]), np.array([1, 0]))[1].tolist()
    [7, 5, 6]
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    idx = np.asarray(idx, dtype=np.int64)
    lens = offsets[idx + 1] - offsets[idx]
    new_off = np.r_[0, np.cumsum(lens)].astype(np.int64)
    if fast and new_off[-1] > 0 and data.size and data.flags.c_contiguous:
        from unmesh.fem._kernels import gather_rows

        out = np.empty((int(new_off[-1]), *data.shape[1:]), dtype=data.dtype)
        gather_rows(offsets, data.reshape(len(data), -1), idx, new_off, out.reshape(len(out), -1))
        return new_off, out
    pos = np.repeat(offsets[idx] - new_off[:-1], lens) + np.arange(new_off[-1])
    return new_off, data[pos]


def merge_csr(off_a: np.ndarray, data_a: np.ndarray, off_b: np.ndarray, data_b: np.ndarray, from_b: np.ndarray,
              idx: np.ndarray, *, fast: bool = True, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rows picked from two CSR arrays: row i is row ``idx[i]`` of b if ``from_b[i]``, else of a.

    ``off_a`` (Ra+1,), ``off_b`` (Rb+1,) int; ``data_a``, ``data_b`` of equal dtype and
    trailing shape; ``from_b`` (k,) bool; ``idx`` (k,) int. Returns ``(new_offsets (k+1,),
    new_data)``. One copy of the rows (the re-integration after a cut merges the kept
    elements' data with the re-integrated ones); ``fast=False`` is the numpy reference.
    ``out``: a buffer (rows of the same dtype and trailing shape, neither input) whose
    first rows receive the data when it is long enough; the returned data is then a view
    of it. (Writing into memory the process already uses avoids the first-touch page
    faults of a fresh ~100 MB array: measured on the bunny-slicing benchmark's virtual
    machine, up to 10 ms per MB for memory the host had reclaimed.)

    Example
    -------
    >>> import numpy as np
    >>> merge_csr(np.array([0, 2]), np.array([5, 6]), np.array([0, 1]), np.array([7]),
    ...           np.array([True, False]), np.array([0, 0]))[1].tolist()
    [7, 5, 6]
    """
    off_a = np.asarray(off_a, dtype=np.int64)
    off_b = np.asarray(off_b, dtype=np.int64)
    from_b = np.asarray(from_b, dtype=bool)
    idx = np.asarray(idx, dtype=np.int64)
    lens = np.where(from_b, off_b[np.where(from_b, idx, 0) + 1] - off_b[np.where(from_b, idx, 0)],
                    off_a[np.where(from_b, 0, idx) + 1] - off_a[np.where(from_b, 0, idx)])
    new_off = np.r_[0, np.cumsum(lens)].astype(np.int64)
    if (fast and new_off[-1] > 0 and data_a.size and data_b.size and data_a.flags.c_contiguous
            and data_b.flags.c_contiguous):
        size = int(new_off[-1])
        if (out is None or len(out) < size or out.shape[1:] != data_a.shape[1:] or out.dtype != data_a.dtype
                or not out.flags.c_contiguous):
            out = np.empty((size, *data_a.shape[1:]), dtype=data_a.dtype)
        out = out[:size]
        FK.merge_rows(off_a, data_a.reshape(len(data_a), -1), off_b, data_b.reshape(len(data_b), -1), from_b, idx,
                      new_off, out.reshape(len(out), -1))
        return new_off, out
    both = np.concatenate([data_a, data_b])
    start = np.where(from_b, off_b[np.where(from_b, idx, 0)] + len(data_a), off_a[np.where(from_b, 0, idx)])
    pos = np.repeat(start - new_off[:-1], lens) + np.arange(new_off[-1])
    return new_off, both[pos]


def _local_triangles(mesh: PolyMesh, elements: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Node CSR and boundary triangles in local node numbers of ``elements`` (default all)."""
    noff, nodes = mesh.element_nodes()
    if elements is None:
        toff, tris = mesh.element_triangles()
    else:
        noff, nodes = gather_csr(noff, nodes, elements)
        toff, tris = mesh.triangles_of(elements)
    ne = len(noff) - 1
    n1 = np.int64(mesh.n_nodes + 1)
    eid_n = np.repeat(np.arange(ne, dtype=np.int64), np.diff(noff))
    keys = eid_n * n1 + nodes
    eid_t = np.repeat(np.arange(ne, dtype=np.int64), np.diff(toff))
    loc = np.searchsorted(keys, eid_t[:, None] * n1 + tris) - noff[eid_t][:, None]
    return noff, nodes, toff, np.ascontiguousarray(loc.astype(np.int64))


@dataclass(frozen=True, eq=False)
class ElementIntegration:
    """Quadrature data of every element (flat CSR arrays).

    Attributes
    ----------
    node_offsets : (E+1,) int64
    nodes : (Σn,) int64
        Each element's nodes, sorted (the local numbering).
    volumes : (E,) float64
    mu : (Σn,) float64
        Volume fractions μ_i^e (9.17), summing to 1 per element; lumped masses (9.21).
    sample_offsets : (E+1,) int64
    weights : (Σq,) float64
        Quadrature weights (sum V_e per element).
    samples : (Σq, 3) float64
        Sample positions.
    grad_offsets : (E+1,) int64
    grads : (Σ n·q, 3) float64
        ∇φ_i at sample q of element e at row ``grad_offsets[e] + q·n_e + i``.
    corrected : bool
        Whether the consistency correction was applied.

    Example
    -------
    >>> from unmesh.fem import hex_grid, integrate_elements
    >>> integrate_elements(hex_grid((2, 1, 1))).n_elements
    2
    """

    node_offsets: np.ndarray
    nodes: np.ndarray
    volumes: np.ndarray
    mu: np.ndarray
    sample_offsets: np.ndarray
    weights: np.ndarray
    samples: np.ndarray
    grad_offsets: np.ndarray
    grads: np.ndarray
    corrected: bool

    @property
    def n_elements(self) -> int:
        """Number of elements."""
        return len(self.volumes)

    def take(self, idx: np.ndarray) -> ElementIntegration:
        """The data of elements ``idx`` (in that order)."""
        idx = np.asarray(idx, dtype=np.int64)
        noff, nodes = gather_csr(self.node_offsets, self.nodes, idx)
        _, mu = gather_csr(self.node_offsets, self.mu, idx)
        soff, w = gather_csr(self.sample_offsets, self.weights, idx)
        _, s = gather_csr(self.sample_offsets, self.samples, idx)
        goff, g = gather_csr(self.grad_offsets, self.grads, idx)
        return ElementIntegration(noff, nodes, self.volumes[idx], mu, soff, w, s, goff, g, self.corrected)


def concat(parts: list[ElementIntegration], order: np.ndarray) -> ElementIntegration:
    """Concatenate integrations, then reorder elements by ``order`` (indices into the concatenation)."""
    def cat_csr(off_name: str, data_name: str) -> tuple[np.ndarray, np.ndarray]:
        offs, datas, shift = [np.zeros(1, np.int64)], [], 0
        for p in parts:
            o = getattr(p, off_name)
            offs.append(o[1:] + shift)
            shift += int(o[-1])
            datas.append(getattr(p, data_name))
        return np.concatenate(offs), np.concatenate(datas)

    noff, nodes = cat_csr("node_offsets", "nodes")
    _, mu = cat_csr("node_offsets", "mu")
    soff, w = cat_csr("sample_offsets", "weights")
    _, s = cat_csr("sample_offsets", "samples")
    goff, g = cat_csr("grad_offsets", "grads")
    vols = np.concatenate([p.volumes for p in parts])
    full = ElementIntegration(noff, nodes, vols, mu, soff, w, s, goff, g, parts[0].corrected)
    return full.take(order)


def _cone_data(mesh: PolyMesh, noff: np.ndarray, nodes: np.ndarray, toff: np.ndarray, tris: np.ndarray
               ) -> tuple[np.ndarray, ...]:
    """Centroids, triangle corners and normals, cone volumes, V, μ (9.17) and ∮ φ_i n dA per local node."""
    ne = len(noff) - 1
    n = np.diff(noff)
    eid_t = np.repeat(np.arange(ne), np.diff(toff))
    pts = mesh.points[nodes]
    c = np.add.reduceat(pts, noff[:-1], axis=0) / n[:, None] if ne else np.zeros((0, 3))
    corner = pts[noff[eid_t][:, None] + tris]                     # (Σm, 3, 3)
    cr = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
    tv = np.einsum("ij,ij->i", corner[:, 0] - c[eid_t], cr) / 6.0  # cone volumes (9.17)-(9.18)
    vols = np.bincount(eid_t, weights=tv, minlength=ne)
    local = noff[eid_t][:, None] + tris
    mu = np.bincount(local.ravel(), weights=np.repeat(tv / (3.0 * vols[eid_t]), 3), minlength=len(nodes))
    exact = np.zeros((len(nodes), 3))
    for r in range(3):
        np.add.at(exact, local[:, r], cr / 6.0)
    return c, corner, cr, tv, vols, mu, exact


def _integrate_subtet(mesh: PolyMesh, noff: np.ndarray, nodes: np.ndarray, toff: np.ndarray, tris: np.ndarray,
                      correction: bool, order: int) -> tuple[np.ndarray, ...]:
    """The ``subtet`` rule: Gauss points in the centroid cones of the boundary triangles (numpy + MVC kernel)."""
    from unmesh.fem._mvc_kernels import mvc_elements

    ne = len(noff) - 1
    n = np.diff(noff)
    m = np.diff(toff)
    eid_n = np.repeat(np.arange(ne), n)
    eid_t = np.repeat(np.arange(ne), m)
    c, corner, cr, tv, vols, mu, exact = _cone_data(mesh, noff, nodes, toff, tris)
    tet = (n == 4) & (m == 4)
    lam, cw = cone_rule(order)
    k = len(cw)
    counts = np.where(tet, 1, m * k)
    soff = np.r_[0, np.cumsum(counts)].astype(np.int64)
    # samples: tetrahedra their centroid, other elements k points per cone, cone by cone
    is_cone_t = ~tet[eid_t]
    samples = np.empty((int(soff[-1]), 3))
    weights = np.empty(int(soff[-1]))
    samples[soff[:-1][tet]] = c[tet]
    weights[soff[:-1][tet]] = vols[tet]
    ct = np.flatnonzero(is_cone_t)
    first_t = toff[eid_t[ct]]
    pos = soff[eid_t[ct]][:, None] + (ct - first_t)[:, None] * k + np.arange(k)
    cone_pts = lam[None, :, 0, None] * c[eid_t[ct]][:, None, :] + np.einsum("qr,trj->tqj", lam[:, 1:], corner[ct])
    samples[pos.ravel()] = cone_pts.reshape(-1, 3)
    weights[pos.ravel()] = (tv[ct][:, None] * cw[None, :]).ravel()
    _, grads, goff = mvc_elements(mesh.points, noff, nodes, toff, tris, soff, samples)
    # tetrahedra: exact constant gradients (the MVC of a tetrahedron is barycentric; use the closed form)
    te = np.flatnonzero(tet)
    if len(te):
        tt = np.flatnonzero(tet[eid_t])
        opp = 6 - tris[tt].sum(axis=1)
        grads[goff[eid_t[tt]] + opp] = -cr[tt] / (6.0 * vols[eid_t[tt]])[:, None]
    if correction and len(ct):
        ce = np.flatnonzero(~tet)
        q = counts[ce]
        # Σ_q w_q ∇φ_i(p_q) per local node i of the corrected elements
        acc = np.zeros((len(nodes), 3))
        row_e = np.repeat(ce, q * n[ce])
        start = np.repeat(goff[ce], q * n[ce])
        rel = np.arange(len(row_e)) - np.repeat(np.r_[0, np.cumsum(q * n[ce])][:-1], q * n[ce])
        i_loc = rel % n[row_e]
        s_loc = rel // n[row_e]
        rows = start + rel
        node_row = noff[row_e] + i_loc
        np.add.at(acc, node_row, weights[soff[row_e] + s_loc][:, None] * grads[rows])
        fix = (exact - acc) / vols[eid_n][:, None]
        grads[rows] += fix[node_row]
    return vols, mu, weights, samples, grads, soff, goff


def _interface_fix(mesh: PolyMesh, is_hex: np.ndarray, hexes: np.ndarray, noff8: np.ndarray, nodes8: np.ndarray,
                   vols: np.ndarray) -> np.ndarray | None:
    """Consistency correction of hexahedra on faces shared with non-hexahedral cells: (k, 8, 3) or None.

    A linear field's nodal forces are ``σ·∫∇N_i = σ·∮ N_i n``; across a face both cells must
    use the same trace. On faces to other hexahedra the bilinear one (nothing to do); on
    faces to mean value cells the piecewise-linear one of the face's triangles. The
    difference ``∫_f (φ_i - N_i) n dA`` over those faces, divided by V, is added to every
    sample's ∇N_i (it keeps Σ_i x_i ∇N_iᵀ = I), so the patch test passes on mixed meshes.
    """
    fe = mesh.face_elements()
    pos = np.full(mesh.n_elements, -1, np.int64)
    pos[hexes] = np.arange(len(hexes))
    # (hex position, face) pairs with a non-hexahedral neighbour across the face
    eid = np.repeat(np.arange(mesh.n_elements), np.diff(mesh.elem_offsets))
    mine = pos[eid] >= 0
    f_all = mesh.elem_faces[mine]
    hpos = pos[eid[mine]]
    nb = np.where(fe[f_all, 0] == eid[mine], fe[f_all, 1], fe[f_all, 0])
    mixed = (nb >= 0) & ~is_hex[np.maximum(nb, 0)]
    if not mixed.any():
        return None
    f, hp = f_all[mixed], hpos[mixed]
    c = mesh.points[nodes8.reshape(-1, 8)[hp]].mean(axis=1)                 # cell centroids
    quad = mesh.face_nodes[mesh.face_offsets[f][:, None] + np.arange(4)]     # (P, 4) cyclic
    q = mesh.points[quad]
    out = np.zeros((len(hexes), 8, 3))

    def add(nodes_glob: np.ndarray, pairs: np.ndarray, vec: np.ndarray) -> None:
        rows = nodes8.reshape(-1, 8)[pairs]
        li = (rows < nodes_glob[:, None]).sum(axis=1)
        np.add.at(out, (pairs, li), vec)

    sign = np.sign(np.einsum("pj,pj->p", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), q.mean(axis=1) - c))
    # bilinear trace: ∫ N_k n dA by 2×2 Gauss on the face (exact for planar quadrilaterals)
    g = np.array([-1.0, 1.0]) / np.sqrt(3.0)
    sk = np.array([-1.0, 1.0, 1.0, -1.0])
    tk = np.array([-1.0, -1.0, 1.0, 1.0])
    for s in g:
        for t in g:
            N = (1 + sk * s) * (1 + tk * t) / 4
            dXs = np.einsum("k,pkj->pj", sk * (1 + tk * t) / 4, q)
            dXt = np.einsum("k,pkj->pj", tk * (1 + sk * s) / 4, q)
            nA = np.cross(dXs, dXt) * sign[:, None]
            for kk in range(4):
                add(quad[:, kk], hp, -N[kk] * nA)
    # piecewise-linear trace on the face's triangles: A_T n_T / 3 per corner
    toff, tris = mesh.triangles()
    nt = toff[f + 1] - toff[f]
    tp = np.repeat(np.arange(len(f)), nt)
    tr = tris[np.repeat(toff[f], nt) + (np.arange(nt.sum()) - np.repeat(np.cumsum(nt) - nt, nt))]
    p = mesh.points[tr]
    cr = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) * sign[tp][:, None] / 6.0
    for r in range(3):
        add(tr[:, r], hp[tp], cr)
    return out / vols[:, None, None]


def _integrate_trilinear(mesh: PolyMesh, correction: bool, elements: np.ndarray | None) -> ElementIntegration:
    """Hexahedra: 2×2×2 trilinear samples (V and μ of 9.17 as in the thesis); other cells: the thesis rule."""
    from unmesh.fem.hexcells import GAUSS_2, REFERENCE_CORNERS, hex_cells, trilinear_gradients

    is_hex, corners = hex_cells(mesh)
    sel = np.arange(mesh.n_elements) if elements is None else np.asarray(elements, dtype=np.int64)
    h = np.flatnonzero(is_hex[sel])                      # positions in the integration that are hexahedra
    if not len(h):
        return integrate_elements(mesh, correction, elements)
    slot = np.full(mesh.n_elements, -1, np.int64)
    slot[is_hex] = np.arange(int(is_hex.sum()))
    cor = corners[slot[sel[h]]]                          # (k, 8) local node per reference corner
    noff8, nodes8, toff8, tris8 = _local_triangles(mesh, sel[h])
    vols, mu = _cone_data(mesh, noff8, nodes8, toff8, tris8)[4:6]
    k = len(h)
    x = mesh.points[nodes8[noff8[:-1, None] + cor]]
    g, det = trilinear_gradients(x)                      # (k, 8q, 8 corners, 3)
    grads = np.empty_like(g)
    grads[np.arange(k)[:, None, None], np.arange(8)[None, :, None], cor[:, None, :]] = g  # local order
    ref = np.einsum("qa,hak->hqk", 0.125 * np.prod(1 + GAUSS_2[:, None, :] * REFERENCE_CORNERS[None], axis=2), x)
    soff8 = np.arange(0, 8 * k + 1, 8, dtype=np.int64)
    goff8 = np.arange(0, 64 * k + 1, 64, dtype=np.int64)
    grads = grads.reshape(k, 8, 8, 3)
    if correction:
        fix = _interface_fix(mesh, is_hex, sel[h], noff8, nodes8, vols)
        if fix is not None:
            grads += fix[:, None, :, :]
    hexes = ElementIntegration(noff8, nodes8, vols, mu, soff8, det.ravel(), ref.reshape(-1, 3), goff8,
                               grads.reshape(-1, 3), bool(correction))
    rest = np.flatnonzero(~is_hex[sel])
    if not len(rest):
        return hexes
    order = np.empty(len(sel), np.int64)
    order[rest] = np.arange(len(rest))
    order[h] = len(rest) + np.arange(k)
    return concat([integrate_elements(mesh, correction, sel[rest]), hexes], order)


def integrate_elements(mesh: PolyMesh, correction: bool = True, elements: np.ndarray | None = None,
                       rule: IntegrationRule | str | None = None) -> ElementIntegration:
    """Samples, weights and shape-function gradients of the elements (9.17–9.19).

    Parameters
    ----------
    mesh : PolyMesh
        Rest configuration (convex elements).
    correction : bool
        Apply the consistency correction (default True; see the module docstring).
    elements : (k,) int array, optional
        Integrate only these elements (in this order).
    rule : IntegrationRule or str, optional
        The quadrature (default the thesis rule (9.19); ``"subtet"`` or ``"subtet:ORDER"``
        the Gauss rule on the centroid cones, see :class:`IntegrationRule`).

    Returns
    -------
    ElementIntegration

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> integ = integrate_elements(hex_grid((1, 1, 1)))
    >>> integ.sample_offsets.tolist()  # 8 vertex + 12 triangle samples
    [0, 20]
    >>> integrate_elements(hex_grid((1, 1, 1)), rule="subtet:2").sample_offsets.tolist()  # 12 cones x 2³
    [0, 96]
    """
    rule = IntegrationRule.parse(rule)
    if rule.kind in ("trilinear", "incompatible"):
        return _integrate_trilinear(mesh, correction, elements)
    idx = None if elements is None else np.asarray(elements, dtype=np.int64)
    noff, nodes, toff, tris = _local_triangles(mesh, idx)
    if rule.kind == "subtet":
        vols, mu, w, s, g, soff, goff = _integrate_subtet(mesh, noff, nodes, toff, tris, bool(correction),
                                                          int(rule.order))
        return ElementIntegration(noff, nodes, vols, mu, soff, w, s, goff, g, bool(correction))
    counts = FK.sample_counts(noff, toff)
    soff = np.r_[0, np.cumsum(counts)].astype(np.int64)
    goff = np.r_[0, np.cumsum(counts * np.diff(noff))].astype(np.int64)
    vols, mu, w, s, g = FK.integrate(mesh.points, noff, nodes, toff, tris, soff, goff, bool(correction))
    return ElementIntegration(noff, nodes, vols, mu, soff, w, s, goff, g, bool(correction))
