"""Helpers shared by the SPH tests: lattices, neighbour lists and a direct call of the lattice pass."""

from __future__ import annotations

import numpy as np

from unmesh.kernels import poly6
from unmesh.spatial import radius_neighbors
from unmesh.sph import _elastic_kernels as EK
from unmesh.sph import _slot_kernels as SK
from unmesh.sph.elastic import ElasticParams, assign_slots, neighbourhood_forces
from unmesh.sph.materials import Material, material_table
from unmesh.sph.sampling import closest_packing, lattice_basis, lattice_frame, lattice_slots


def neighbour_table(x: np.ndarray, h: float, dim: int, cap: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """Ascending neighbour lists (self excluded) in the fixed-capacity layout of the kernels."""
    off, ind = radius_neighbors(x[:, :dim], h)
    n = len(x)
    nbr = np.full((n, cap), -1, np.int32)
    nn = np.zeros(n, np.int64)
    for i in range(n):
        js = ind[off[i]:off[i + 1]]
        js = np.sort(js[js != i])
        nbr[i, :len(js)] = js
        nn[i] = len(js)
    return nbr, nn


class LatticeState:
    """Particles of one elastic object and the outputs of one call of ``lattice_update``.

    ``solid`` (N,) bool: the solid particles (default all); the others are fluid (no neighbourhood of
    their own, never members of one).
    """

    def __init__(self, x: np.ndarray, dim: int, spacing: float, material: Material, masses: np.ndarray,
                 a_prev: np.ndarray | None = None, solid: np.ndarray | None = None,
                 pmat: np.ndarray | None = None) -> None:
        self.x = np.ascontiguousarray(x)
        self.dim = dim
        self.d = spacing
        self.h = 2.0 * spacing
        self.n = len(x)
        self.m = np.ascontiguousarray(masses, dtype=np.float64)
        self.mat = material
        self.mats = material_table([material])
        self.vecs, self.coords, self.table = lattice_slots(dim, 2.0)
        self.tmat = SK.d3_transform(lattice_basis(dim)) if dim == 3 else np.eye(3)
        frame = lattice_frame(dim)
        self.amat = np.repeat(frame[None], self.n, 0) if a_prev is None else np.ascontiguousarray(a_prev)
        self.ainv = np.ascontiguousarray(np.linalg.inv(self.amat))
        self.nbr, self.nn = neighbour_table(self.x, self.h, dim)
        self.solid = np.ones(self.n, bool) if solid is None else np.asarray(solid, bool)
        # stored plastic deformations (rest offsets P l); none: no plasticity (an empty table)
        self.pmat = np.zeros((0, 3, 3)) if pmat is None else np.ascontiguousarray(pmat, dtype=np.float64)

    def run(self) -> None:
        n, q = self.n, len(self.vecs)
        self.occ = np.full((n, q), -1, np.int32)
        self.docked = np.zeros((n, q), np.uint8)
        self.lam = np.full((n, q), np.inf)
        self.out = {
            "amat": np.zeros((n, 3, 3)), "ainv": np.zeros((n, 3, 3)), "gmat": np.zeros((n, 3, 3)),
            "fown": np.zeros((n, 3)), "valid": np.zeros(n, np.uint8), "fel": np.full((n, 3), np.nan),
            "pmat": np.full(self.pmat.shape, np.nan),
        }
        o = self.out
        EK.lattice_update(self.x, self.m, self.solid.astype(np.int8), np.zeros(n, np.int32), np.zeros(n, np.int32),
                          np.arange(n, dtype=np.int64), self.mats, self.nbr, self.nn, self.h, self.dim, self.d,
                          self.vecs, self.tmat, self.table, np.arange(n, dtype=np.int64), self.amat, self.ainv,
                          self.occ, self.docked, self.lam, 0, 0, 1e-4, 1, o["amat"], o["ainv"], self.occ, self.docked,
                          o["gmat"], o["fown"], o["valid"], o["fel"], self.pmat, o["pmat"])

    def forces(self) -> np.ndarray:
        """Total elastic force on every particle, as the force pass adds it (own share + member forces)."""
        self.run()
        return self.out["fown"] + self.out["fel"]

    def reference_forces(self) -> np.ndarray:
        """The same forces from the numpy reference (:mod:`unmesh.sph.elastic`)."""
        mu, lam = self.mat.lame
        par = ElasticParams(self.dim, self.mat.elastic_stiffness, self.mat.goal_deformation, mu, lam,
                            self.mat.density, self.mat.plastic_yield, self.mat.plastic_creep,
                            self.mat.freeze_rate > 0.0)
        w0 = float(poly6(0.0, self.h, self.dim))
        f = np.zeros((self.n, 3))
        for i in np.flatnonzero(self.solid):
            js = self.nbr[i, :self.nn[i]].astype(np.int64)
            js = js[self.solid[js]]
            r = self.x[js] - self.x[i]
            slot = assign_slots(r, self.ainv[i], self.coords, self.d, self.dim)
            keep = slot >= 0
            js, r, slot = js[keep], r[keep], slot[keep]
            w = np.asarray(poly6(np.linalg.norm(r, axis=1), self.h, self.dim))
            plastic = self.pmat[i] if len(self.pmat) else None
            fi, fj = neighbourhood_forces(self.x[i], r, self.vecs[slot] * self.d, w, w0, self.m[i], self.m[js], par,
                                          plastic)
            f[i] += fi
            np.add.at(f, js, fj)
        return f


def lattice_block(dim: int, spacing: float = 0.1, size: float = 0.6) -> np.ndarray:
    """A block of closest-packed particles around the origin."""
    half = size / 2.0
    return closest_packing([-half, -half, -half], [half, half, half], spacing, dim)
