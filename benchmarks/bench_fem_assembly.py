"""Assembly and solve of linear tetrahedral elasticity: unmesh vs scikit-fem on the same mesh.

Mesh: scikit-fem's tensor tetrahedral mesh of the unit cube (21^3 nodes = 27,783 DOFs, 48,000
tets), clamped at x = 0, loaded at x = 1. Prints:

- global stiffness assembly: scikit-fem ``asm(linear_elasticity)`` vs ``unmesh.fem.stiffness_matrix``
  (after JIT warm-up), and that both matrices agree;
- static solve: scikit-fem ``spsolve`` (SuperLU, default COLAMD ordering) vs unmesh
  ``solve_static`` (SuperLU with minimum-degree ordering of A+Aᵀ);
- an implicit Euler step (Δt = 0.01, ρ = 1) with stiffness warping, per solver: ``auto``
  (block-Jacobi PCG, falling back to ``lu-pcg`` when too stiff), ``cg`` (block-Jacobi PCG
  warm-started from the last velocity), ``lu-pcg`` (PCG with a lagged LU preconditioner; its
  setup, one factorisation, is printed separately) and ``direct`` (a factorisation per step).

Usage: ``python benchmarks/bench_fem_assembly.py [--n 20]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def timed(fn, repeat: int = 1):
    best = np.inf
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return out, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20, help="cells per axis of the tensor mesh (default 20)")
    args = ap.parse_args()
    import scipy.sparse.linalg as spla
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    from unmesh.fem import solve_static, stiffness_matrix, tet_mesh
    from unmesh.fem.dynamics import Dynamics, Prescribed

    Y, nu = 1e3, 0.3
    m = skfem.MeshTet.init_tensor(*[np.linspace(0, 1, args.n + 1)] * 3)
    mesh = tet_mesh(m.p.T, m.t.T)
    print(f"mesh: {mesh.n_elements} tets, {mesh.n_nodes} nodes, {3 * mesh.n_nodes} DOFs")

    basis = skfem.Basis(m, skfem.ElementVector(skfem.ElementTetP1()))
    Ks, t_sk = timed(lambda: skfem.asm(linear_elasticity(*lame_parameters(Y, nu)), basis).tocsr())
    stiffness_matrix(mesh, Y, nu)  # JIT compilation (cached on disk after the first run)
    K, t_um = timed(lambda: stiffness_matrix(mesh, Y, nu), repeat=3)
    print(f"assembly: scikit-fem {t_sk:.2f} s, unmesh {t_um:.2f} s  ({t_sk / t_um:.1f}x faster); "
          f"max |K - K_skfem| / max |K| = {abs(K - Ks).max() / abs(Ks).max():.1e}")

    left = np.flatnonzero(mesh.points[:, 0] < 1e-9)
    right = np.flatnonzero(mesh.points[:, 0] > 1 - 1e-9)
    f = np.zeros((mesh.n_nodes, 3))
    f[right, 1] = -1.0 / len(right)
    fixed_dofs = np.repeat(3 * left, 3) + np.tile([0, 1, 2], len(left))
    free = np.setdiff1d(np.arange(3 * mesh.n_nodes), fixed_dofs)
    Kff = Ks[free][:, free].tocsc()
    x_sk, t_solve_sk = timed(lambda: spla.spsolve(Kff, f.ravel()[free]))
    u, t_solve_um = timed(lambda: solve_static(mesh, Y, nu, left, f))
    err = abs(u.ravel()[free] - x_sk).max() / abs(x_sk).max()
    print(f"static solve: scikit-fem spsolve {t_solve_sk:.2f} s, unmesh solve_static (incl. assembly) "
          f"{t_solve_um:.2f} s ({t_solve_sk / t_solve_um:.1f}x); relative difference {err:.1e}")

    dt = 0.01
    step_times = {}
    for solver in ("auto", "cg", "lu-pcg", "direct"):
        sim = Dynamics(mesh, Y, nu, 1.0, prescribed=[Prescribed(left)], solver=solver, gravity=(0, -9.81, 0))
        sim.step(dt)  # JIT and (for lu-pcg) the first factorisation
        t0 = time.perf_counter()
        info = sim.step(dt)
        first = time.perf_counter() - t0
        times, its = [], []
        for _ in range(3):
            t0 = time.perf_counter()
            info = sim.step(dt)
            times.append(time.perf_counter() - t0)
            its.append(info.iterations)
        step_times[solver] = float(np.median(times))
        print(f"implicit Euler step, solver {solver:7s}: {step_times[solver]:.2f} s per step "
              f"({np.median(its):.0f} iterations; second step {first:.2f} s)")
    sim = Dynamics(mesh, Y, nu, 1.0, prescribed=[Prescribed(left)], solver="lu-pcg")
    t0 = time.perf_counter()
    sim.step(dt)
    print(f"lu-pcg preconditioner setup (first step incl. factorisation): {time.perf_counter() - t0:.2f} s")
    for solver in ("auto", "cg", "lu-pcg"):
        print(f"warm-started preconditioned solve ({solver} step) vs scikit-fem spsolve: "
              f"{t_solve_sk / step_times[solver]:.1f}x faster")


if __name__ == "__main__":
    main()
