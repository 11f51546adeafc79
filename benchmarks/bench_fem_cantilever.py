"""Cantilever accuracy study (issue 22, item 3): tip deflection per mesh, element and integration rule.

The 10×1×1 beam (E = 1000, ν = 0.3) clamped at x = 0 (all nodes of the face fixed) with a
unit tip load (consistent nodal weights on the end face), on nx × nx/10 × nx/10 cube cells
and on the same grid split into 5 or 6 linear tetrahedra per cube. Prints one row per case:
the mean tip deflection, its error against Euler–Bernoulli (4) and Timoshenko
(4 + PL/(κGA) = 4.0306, κ = 10(1+ν)/(12+11ν)), the stiffness assembly time per element
and the total ``solve_static`` time. Optional: scikit-fem's trilinear hexahedra (the
same load as a traction, the tip deflection as the face mean) as an outside reference.

Run::

    python benchmarks/bench_fem_cantilever.py              # 30 and 60 cells along the beam
    python benchmarks/bench_fem_cantilever.py --sizes 30 60 120 --skfem

Timings are wall-clock on whatever machine runs it (two shared cores in the study of
docs/fem_cantilever_study.md: read them as rough ratios only).
"""

from __future__ import annotations

import argparse
import time
from itertools import permutations

import numpy as np

from unmesh.fem import hex_grid, solve_static, stiffness_matrix, tet_mesh
from unmesh.fem.mesh import PolyMesh

E, NU = 1e3, 0.3
EB = 4.0
TIMOSHENKO = EB + 10.0 / (10 * (1 + NU) / (12 + 11 * NU) * E / (2 * (1 + NU)))
CUBE_RULES = ("thesis", "subtet:1", "subtet:2", "subtet:3", "trilinear", "incompatible")


def beam(nx: int, cells: str = "cube") -> PolyMesh:
    """The beam on nx × nx/10 × nx/10 cubes (``cells="cube"``) or their 5- or 6-tetrahedra splits."""
    ny = nx // 10
    g = hex_grid((nx, ny, ny), size=(10, 1, 1))
    if cells == "cube":
        return g
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(ny), indexing="ij"))

    def nid(a, b, c):
        return a + (nx + 1) * (b + (ny + 1) * c)

    corner = np.stack([nid(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)) for c in range(8)], 1)
    if cells == "tet6":  # Kuhn: six tetrahedra around the main diagonal (conforming on the grid)
        local = [[0, 1 << p[0], (1 << p[0]) | (1 << p[1]), 7] for p in permutations(range(3))]
        tets = corner[:, np.array(local)].reshape(-1, 4)
    elif cells == "tet5":  # four corner tetrahedra and a central one, mirrored on alternate cubes
        even = np.array([[0, 1, 2, 4], [3, 1, 2, 7], [5, 1, 4, 7], [6, 2, 4, 7], [1, 2, 4, 7]])
        odd = np.array([[1, 0, 3, 5], [2, 0, 3, 6], [4, 0, 5, 6], [7, 3, 5, 6], [0, 3, 5, 6]])
        tets = np.where(((i + j + k) % 2 == 0)[:, None, None], corner[:, even], corner[:, odd]).reshape(-1, 4)
    else:
        raise ValueError(cells)
    return tet_mesh(g.points, tets)


def load(m: PolyMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clamped nodes, tip nodes and the unit tip load (bilinear-consistent nodal weights)."""
    left = np.flatnonzero(np.isclose(m.points[:, 0], 0))
    right = np.flatnonzero(np.isclose(m.points[:, 0], 10))
    y, z = m.points[right, 1], m.points[right, 2]
    wy = np.where(np.isclose(y, 0) | np.isclose(y, 1), 0.5, 1.0)
    wz = np.where(np.isclose(z, 0) | np.isclose(z, 1), 0.5, 1.0)
    f = np.zeros((m.n_nodes, 3))
    f[right, 1] = -(wy * wz) / (wy * wz).sum()
    return left, right, f


def case(m: PolyMesh, rule: str) -> tuple[float, float, float]:
    """(tip deflection, assembly µs per element, total solve seconds).

    The mesh's cached topology (element nodes, face triangles, face neighbours) is built
    before the clock starts, so every rule is timed on the same footing.
    """
    m.element_nodes(), m.element_triangles(), m.face_elements()
    left, right, f = load(m)
    t0 = time.perf_counter()
    stiffness_matrix(m, E, NU, rule=rule)
    t_asm = time.perf_counter() - t0
    t0 = time.perf_counter()
    u = solve_static(m, E, NU, left, f, rule=rule)
    t_solve = time.perf_counter() - t0
    return float(-u[right, 1].mean()), 1e6 * t_asm / m.n_elements, t_solve


def skfem_case(nx: int) -> tuple[float, float, float]:
    """scikit-fem trilinear hexahedra (ElementHex1, default quadrature) on the same grid."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    ny = nx // 10
    m = skfem.MeshHex.init_tensor(np.linspace(0, 10, nx + 1), np.linspace(0, 1, ny + 1), np.linspace(0, 1, ny + 1))
    e = skfem.ElementVector(skfem.ElementHex1())
    t0 = time.perf_counter()
    ib = skfem.Basis(m, e)
    K = skfem.asm(linear_elasticity(*lame_parameters(E, NU)), ib)
    t_asm = time.perf_counter() - t0
    fb = skfem.FacetBasis(m, e, facets=m.facets_satisfying(lambda x: np.isclose(x[0], 10)))
    f = skfem.asm(skfem.LinearForm(lambda v, w: -v.value[1]), fb)
    u = skfem.solve(*skfem.condense(K, f, D=ib.get_dofs(lambda x: np.isclose(x[0], 0)).all()))
    t_all = time.perf_counter() - t0
    d = -skfem.asm(skfem.Functional(lambda w: w["u"].value[1]), fb, u=fb.interpolate(u))
    return float(d), 1e6 * t_asm / m.nelements, t_all


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[30, 60], help="cells along the beam (multiples of 10)")
    ap.add_argument("--rules", nargs="+", default=list(CUBE_RULES), help="rules on the cube cells")
    ap.add_argument("--skip-subtet-above", type=int, default=60,
                    help="run subtet:3 only up to this size (it costs ~10x the thesis rule)")
    ap.add_argument("--skfem", action="store_true", help="add scikit-fem's trilinear hexahedra")
    a = ap.parse_args()
    case(beam(10), "thesis")  # compile the kernels
    case(beam(10, "tet5"), "thesis")
    print(f"Euler–Bernoulli {EB:.4f}, Timoshenko {TIMOSHENKO:.4f}")
    print(f"{'mesh':>10} {'cells':>7} {'element':>26} {'rule':>12} {'tip':>7} {'vs EB':>8} {'vs Tim.':>8} "
          f"{'asm µs/el':>10} {'solve s':>8}")

    def row(nx, cells, ne, element, rule, res):
        d, asm, tot = res
        print(f"{nx}×{nx // 10}×{nx // 10}".rjust(10), f"{ne:>7}", f"{element:>26}", f"{rule:>12}", f"{d:7.4f}",
              f"{100 * (d / EB - 1):+7.2f}%", f"{100 * (d / TIMOSHENKO - 1):+7.2f}%", f"{asm:10.1f}", f"{tot:8.2f}",
              flush=True)

    for nx in a.sizes:
        m = beam(nx)
        for rule in a.rules:
            if rule == "subtet:3" and nx > a.skip_subtet_above:
                continue
            element = {"trilinear": "trilinear hexahedron", "incompatible": "hexahedron + incomp. modes"}.get(
                rule, "mean value cube")
            row(nx, "cube", m.n_elements, element, rule, case(m, rule))
        for cells in ("tet5", "tet6"):
            mt = beam(nx, cells)
            row(nx, cells, mt.n_elements, f"linear tet ({cells[-1]} per cube)", "exact", case(mt, "thesis"))
        if a.skfem:
            row(nx, "cube", m.n_elements, "scikit-fem Hex1", "2×2×2 Gauss", skfem_case(nx))


if __name__ == "__main__":
    main()
