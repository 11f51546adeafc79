"""Constitutive law, element stiffness (9.19), sparse global assembly, lumped masses (9.21),
and static solves.

Degrees of freedom are interleaved per node: ``(x0, y0, z0, x1, ...)``.

Example
-------
>>> from unmesh.fem import tet_mesh
>>> K = stiffness_matrix(tet_mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]]), 1.0, 0.25)
>>> K.shape
(12, 12)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from unmesh._validate import as_array, as_indices, scalar
from unmesh.errors import InputError
from unmesh.fem import _fe_kernels as FK
from unmesh.fem import _pattern_kernels as PK
from unmesh.fem.integration import ElementIntegration, IntegrationRule, integrate_elements
from unmesh.fem.mesh import PolyMesh

__all__ = [
    "BlockPattern",
    "ElementStiffness",
    "constitutive_matrix",
    "element_stiffness",
    "lame_parameters",
    "lumped_masses",
    "solve_static",
    "stiffness_matrix",
]


def lame_parameters(young: Any, poisson: Any) -> tuple[np.ndarray, np.ndarray]:
    """Lamé parameters ``λ = Yν/((1+ν)(1-2ν))``, ``μ = Y/(2(1+ν))`` (scalars or arrays).

    Example
    -------
    >>> [round(float(v), 6) for v in lame_parameters(1.0, 0.25)]
    [0.4, 0.4]
    """
    y = np.asarray(young, dtype=np.float64)
    nu = np.asarray(poisson, dtype=np.float64)
    if np.any(~(y > 0)) or not np.all(np.isfinite(y)):
        raise InputError(f"young: expected a positive Young's modulus, got {young}")
    if np.any(~(nu > -1.0)) or np.any(~(nu < 0.5)):
        raise InputError(f"poisson: expected a Poisson ratio in (-1, 0.5), got {poisson}")
    return y * nu / ((1 + nu) * (1 - 2 * nu)), y / (2 * (1 + nu))


def constitutive_matrix(young: float, poisson: float) -> np.ndarray:
    """Isotropic 6×6 matrix C of (9.4) for the strain order of (9.3).

    Strain ``ε = (ε_xx, ε_yy, ε_zz, γ_xy, γ_xz, γ_yz)`` with engineering shears
    ``γ_xy = ∂u_x/∂y + ∂u_y/∂x`` etc.; stress in the same order.

    Example
    -------
    >>> C = constitutive_matrix(1.0, 0.25)
    >>> [round(float(C[0, 0]), 6), round(float(C[0, 1]), 6), round(float(C[3, 3]), 6)]
    [1.2, 0.4, 0.4]
    """
    lam, mu = (float(v) for v in lame_parameters(scalar(young, "young"), scalar(poisson, "poisson")))
    C = np.zeros((6, 6))
    C[:3, :3] = lam
    C[np.arange(3), np.arange(3)] += 2 * mu
    C[np.arange(3, 6), np.arange(3, 6)] = mu
    return C


def _per_element(value: Any, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    return as_array(arr, name, (n,))


@dataclass(frozen=True, eq=False)
class ElementStiffness:
    """Element stiffness matrices K_e as (n_e, n_e, 3, 3) blocks, flat.

    Attributes
    ----------
    node_offsets, nodes : CSR of each element's (sorted) nodes.
    offsets : (E+1,) int64
        Element e's blocks are ``data[offsets[e]:offsets[e+1]]`` reshaped (n, n, 3, 3).
    data : (Σ 9 n²,) float64

    Example
    -------
    >>> from unmesh.fem import hex_grid, element_stiffness
    >>> element_stiffness(hex_grid((1, 1, 1)), 1.0, 0.3).data.shape
    (576,)
    """

    node_offsets: np.ndarray
    nodes: np.ndarray
    offsets: np.ndarray
    data: np.ndarray

    def matrix(self, e: int) -> np.ndarray:
        """Dense K_e (3n, 3n) of element ``e`` with interleaved local DOFs."""
        n = int(self.node_offsets[e + 1] - self.node_offsets[e])
        blk = self.data[self.offsets[e]:self.offsets[e + 1]].reshape(n, n, 3, 3)
        return blk.transpose(0, 2, 1, 3).reshape(3 * n, 3 * n)


def element_stiffness(mesh: PolyMesh | ElementIntegration, young: Any, poisson: Any,
                      correction: bool = True, rule: IntegrationRule | str | None = None, *,
                      of_mesh: PolyMesh | None = None, elements: np.ndarray | None = None) -> ElementStiffness:
    """Element stiffness matrices (9.19 with the volume factor).

    Parameters
    ----------
    mesh : PolyMesh or ElementIntegration
        The mesh (integrated here) or its integration data.
    young, poisson : float or (E,) arrays
        Young's modulus Y and Poisson ratio ν per element.
    correction : bool
        Consistency correction of the sampled gradients (when integrating here).
    rule : IntegrationRule or str, optional
        Quadrature when integrating here (default the thesis rule (9.19); see
        :class:`unmesh.fem.integration.IntegrationRule`).
    of_mesh : PolyMesh, optional
        The mesh ``mesh``'s integration data belong to, when given data: the
        ``incompatible`` rule builds its hexahedra's stiffness from the geometry.
    elements : (k,) int array, optional
        The mesh's elements the stiffness is for, in this order (the integration data
        then hold these elements only; with a mesh, only these are integrated).

    Returns
    -------
    ElementStiffness

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> ks = element_stiffness(hex_grid((1, 1, 1)), 1.0, 0.3)
    >>> ks.matrix(0).shape
    (24, 24)
    """
    rule = IntegrationRule.parse(rule)
    if isinstance(mesh, PolyMesh):
        geometry, integ = mesh, integrate_elements(mesh, correction, elements, rule)
    else:
        geometry, integ = of_mesh, mesh
    ne = integ.n_elements
    lam, mu = lame_parameters(_per_element(young, ne, "young"), _per_element(poisson, ne, "poisson"))
    n = np.diff(integ.node_offsets)
    koff = np.r_[0, np.cumsum(9 * n * n)].astype(np.int64)
    data = FK.element_stiffness(integ.node_offsets, integ.sample_offsets, integ.grad_offsets, integ.weights,
                                integ.grads, lam, mu, koff)
    if rule.kind == "incompatible":
        if geometry is None:
            raise InputError("rule: the 'incompatible' stiffness needs the mesh, got an ElementIntegration "
                             "without of_mesh")
        from unmesh.fem.hexcells import hex_cells, incompatible_stiffness, trilinear_gradients

        is_hex, corners = hex_cells(geometry)
        sel = np.arange(geometry.n_elements) if elements is None else np.asarray(elements, dtype=np.int64)
        if len(sel) != ne:
            raise InputError(f"elements: expected {ne} element indices (one per integrated element), got {len(sel)}")
        slot = np.full(geometry.n_elements, -1, np.int64)
        slot[is_hex] = np.arange(int(is_hex.sum()))
        h = np.flatnonzero(is_hex[sel])                 # positions in the integration that are hexahedra
        corners = corners[slot[sel[h]]]
        if len(h):
            loc = integ.nodes[integ.node_offsets[h][:, None] + corners]
            x = geometry.points[loc]
            # the integration's trilinear gradients carry the interface correction: pass it on
            g0 = integ.grads[(integ.grad_offsets[h][:, None] + np.arange(8)).ravel()].reshape(len(h), 8, 3)
            shift = g0[np.arange(len(h))[:, None], corners] - trilinear_gradients(x)[0][:, 0]
            kb = incompatible_stiffness(x, lam[h], mu[h], shift)                # corner order
            local = np.empty_like(kb)
            r = np.arange(len(h))[:, None, None]
            local[r, corners[:, :, None], corners[:, None, :]] = kb
            data[(koff[h][:, None] + np.arange(576)).ravel()] = local.reshape(-1)
    return ElementStiffness(integ.node_offsets, integ.nodes, koff, data)


@dataclass(frozen=True, eq=False)
class BlockPattern:
    """Sparsity of the global matrix in 3×3 blocks and the element-block -> global-block map.

    Example
    -------
    >>> p = BlockPattern.build(np.array([0, 2]), np.array([0, 1]), 2)
    >>> p.indptr.tolist(), p.indices.tolist()
    ([0, 2, 4], [0, 1, 0, 1])
    """

    n_nodes: int
    indptr: np.ndarray
    indices: np.ndarray
    block_map: np.ndarray
    diag: np.ndarray
    inc_offsets: np.ndarray
    inc_elements: np.ndarray
    inc_local: np.ndarray

    @classmethod
    def build(cls, node_offsets: np.ndarray, nodes: np.ndarray, n_nodes: int, *, fast: bool = True) -> BlockPattern:
        """Pattern of the element node lists (CSR), and the node -> (element, local index) incidence.

        ``fast`` builds it with numba kernels (:func:`unmesh.fem._pattern_kernels.block_pattern`,
        no global sort, rows in parallel: it is rebuilt after every cut); ``fast=False`` is
        the numpy reference. The incidence (``inc_offsets`` (n+1,), ``inc_elements``,
        ``inc_local``: node i is local node ``inc_local[t]`` of element ``inc_elements[t]``,
        elements ascending) drives the row-parallel warped assembly.
        """
        if fast and len(nodes):
            return cls(int(n_nodes), *PK.block_pattern(np.ascontiguousarray(node_offsets, dtype=np.int64),
                                                       np.ascontiguousarray(nodes, dtype=np.int64), int(n_nodes)))
        n = np.diff(node_offsets)
        e = np.repeat(np.arange(len(n)), n * n)
        start = np.repeat(node_offsets[:-1], n * n)
        k = np.arange(e.size) - np.repeat(np.r_[0, np.cumsum(n * n)][:-1], n * n)
        ne = n[e]
        rows = nodes[start + k // ne]
        cols = nodes[start + k % ne]
        key = rows * np.int64(n_nodes) + cols
        uniq, inv = np.unique(key, return_inverse=True)
        r = uniq // n_nodes
        indptr = np.searchsorted(r, np.arange(n_nodes + 1)).astype(np.int64)
        indices = (uniq % n_nodes).astype(np.int64)
        diag = np.searchsorted(uniq, np.arange(n_nodes, dtype=np.int64) * (n_nodes + 1))
        order = np.argsort(nodes, kind="stable")
        inc_off = np.searchsorted(np.asarray(nodes)[order], np.arange(n_nodes + 1)).astype(np.int64)
        inc_e = np.repeat(np.arange(len(n), dtype=np.int64), n)[order]
        inc_a = (np.arange(len(nodes)) - np.repeat(node_offsets[:-1], n))[order].astype(np.int64)
        return cls(int(n_nodes), indptr, indices, inv.astype(np.int64).ravel(), diag.astype(np.int64), inc_off, inc_e,
                   inc_a)

    def assemble(self, blocks: np.ndarray) -> sp.bsr_array:
        """Global BSR matrix from element blocks (Σn², 9) in element order."""
        data = FK.scatter_blocks(self.block_map, blocks.reshape(-1, 9), len(self.indices))
        n3 = 3 * self.n_nodes
        return sp.bsr_array((data.reshape(-1, 3, 3), self.indices, self.indptr), shape=(n3, n3))


def stiffness_matrix(mesh: PolyMesh, young: Any, poisson: Any, correction: bool = True,
                     rule: IntegrationRule | str | None = None) -> sp.csr_array:
    """Global stiffness matrix K (9.16) of a polyhedral mesh.

    Parameters
    ----------
    mesh : PolyMesh
    young, poisson : float or (E,) arrays
        Young's modulus Y and Poisson ratio ν.
    correction : bool
        Consistency correction of the quadrature (default True).
    rule : IntegrationRule or str, optional
        Quadrature (default the thesis rule (9.19); ``"subtet"``, ``"subtet:ORDER"``).

    Returns
    -------
    scipy.sparse.csr_array, shape (3n, 3n)
        Symmetric positive semi-definite, DOFs interleaved per node.

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> K = stiffness_matrix(hex_grid((2, 2, 2)), 1e3, 0.3)
    >>> import numpy as np; bool(abs(K @ np.tile([1.0, 0, 0], 27)).max() < 1e-9)
    True
    """
    ks = element_stiffness(mesh, young, poisson, correction, rule)
    pattern = BlockPattern.build(ks.node_offsets, ks.nodes, mesh.n_nodes)
    return pattern.assemble(ks.data).tocsr()


def lumped_masses(mesh: PolyMesh | ElementIntegration, density: Any = 1.0, n_nodes: int | None = None) -> np.ndarray:
    """Lumped nodal masses ``m_i = Σ_e μ_i^e V_e ρ_e`` (9.21).

    Parameters
    ----------
    mesh : PolyMesh or ElementIntegration
    density : float or (E,) array
    n_nodes : int, optional
        Needed with an ElementIntegration.

    Returns
    -------
    (n,) float64

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> float(lumped_masses(hex_grid((2, 2, 2)), 2.0).sum())
    2.0
    """
    if isinstance(mesh, PolyMesh):
        n_nodes = mesh.n_nodes
        integ = integrate_elements(mesh, correction=False)
    else:
        integ = mesh
        if n_nodes is None:
            raise InputError("n_nodes: required with an ElementIntegration")
    rho = _per_element(density, integ.n_elements, "density")
    if np.any(~(rho > 0)):
        raise InputError("density: expected positive values")
    per = np.repeat(integ.volumes * rho, np.diff(integ.node_offsets)) * integ.mu
    return np.bincount(integ.nodes, weights=per, minlength=n_nodes)


def _components(mesh: PolyMesh) -> np.ndarray:
    """Connected component label of every node (through shared elements)."""
    noff, nodes = mesh.element_nodes()
    e = np.repeat(np.arange(mesh.n_elements), np.diff(noff))
    g = sp.coo_array((np.ones(len(nodes)), (nodes, e)), shape=(mesh.n_nodes, mesh.n_elements)).tocsr()
    adj = g @ g.T
    return sp.csgraph.connected_components(adj, directed=False)[1]


def check_supported(mesh: PolyMesh, fixed: np.ndarray) -> None:
    """Raise if some connected part has fewer than three non-collinear fixed nodes (singular K)."""
    labels = _components(mesh)
    used = np.zeros(mesh.n_nodes, bool)
    used[mesh.element_nodes()[1]] = True
    for c in np.unique(labels[used]):
        f = fixed[labels[fixed] == c]
        ok = False
        if len(f) >= 3:
            p = mesh.points[f] - mesh.points[f].mean(axis=0)
            sv = np.linalg.svd(p, compute_uv=False)
            ok = sv[1] > 1e-9 * max(sv[0], 1e-300)
        if not ok:
            raise InputError(f"fixed: the system is singular: a connected part of the mesh ({int((labels == c).sum())} "
                             f"nodes) has {len(f)} fixed node(s); it needs at least three non-collinear fixed nodes "
                             "(or use dynamics with masses)")


def solve_static(mesh: PolyMesh, young: Any, poisson: Any, fixed: Any, forces: Any, *,
                 displacements: Any | None = None, correction: bool = True,
                 rule: IntegrationRule | str | None = None) -> np.ndarray:
    """Static displacements: solve ``K u = f`` with fixed (prescribed) nodes.

    Parameters
    ----------
    mesh : PolyMesh
    young, poisson : float or (E,) arrays
    fixed : (k,) int array
        Indices of nodes with prescribed displacement (zero unless ``displacements``).
    forces : (n, 3) array
        Nodal forces.
    displacements : (n, 3) array, optional
        Prescribed displacements (only the rows of ``fixed`` are used).
    correction : bool
        Consistency correction of the quadrature (default True).
    rule : IntegrationRule or str, optional
        Quadrature (default the thesis rule (9.19); ``"subtet"``, ``"subtet:ORDER"``; see
        docs/fem_cantilever_study.md).

    Returns
    -------
    (n, 3) float64 displacements.

    Raises
    ------
    InputError
        If the system is singular (a part of the mesh without enough fixed nodes).

    Example
    -------
    >>> from unmesh.fem import hex_grid
    >>> m = hex_grid((2, 1, 1), size=(2, 1, 1))
    >>> stretch = np.c_[0.1 * m.points[:, 0], np.zeros((m.n_nodes, 2))]
    >>> f = (stiffness_matrix(m, 1.0, 0.0) @ stretch.ravel()).reshape(-1, 3)
    >>> u = solve_static(m, 1.0, 0.0, np.flatnonzero(m.points[:, 0] == 0), f)
    >>> round(float(u[m.points[:, 0] == 2, 0].mean()), 9)
    0.2
    """
    from scipy.sparse.linalg import spsolve

    n = mesh.n_nodes
    fix = np.unique(as_indices(fixed, "fixed", (None,), upper=n))
    f = as_array(forces, "forces", (n, 3))
    u = np.zeros((n, 3)) if displacements is None else as_array(displacements, "displacements", (n, 3)).copy()
    check_supported(mesh, fix)
    K = stiffness_matrix(mesh, young, poisson, correction, rule)
    mask = np.ones(n, bool)
    mask[fix] = False
    used = np.zeros(n, bool)
    used[mesh.element_nodes()[1]] = True
    mask &= used
    free = np.flatnonzero(np.repeat(mask, 3))
    pres = np.flatnonzero(~np.repeat(mask, 3))
    uf = u.ravel()
    rhs = f.ravel()[free] - K[free][:, pres] @ uf[pres]
    Kff = K[free][:, free].tocsc()
    uf[free] = spsolve(Kff, rhs, permc_spec="MMD_AT_PLUS_A")
    if not np.all(np.isfinite(uf)):
        raise InputError("the static system is singular (check the fixed nodes and the mesh)")
    return uf.reshape(n, 3)
