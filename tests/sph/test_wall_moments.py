"""Hydrostatic wall pressure on analytic walls (Adami et al. 2012): the half-space and quarter-space
moments of the kernel gradient against brute-force sums, and the column it holds up."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.kernels import spiky_derivative
from unmesh.sph.boundary import corner_moment_tables, wall_moment_tables


def _cells(dim: int, h: float, step: float) -> tuple[np.ndarray, float]:
    """Cell centres of a grid covering [-1.5h, 1.5h]^dim with cell faces on the coordinate planes."""
    k = int(np.ceil(1.5 * h / step))
    ax = (np.arange(-k, k) + 0.5) * step
    mesh = np.meshgrid(*([ax] * dim), indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1), step**dim


def _moment(s: np.ndarray, h: float, dim: int, dv: float) -> np.ndarray:
    r = np.linalg.norm(s, axis=1)
    ok = (r > 0) & (r < h)
    s, r = s[ok], r[ok]
    g = np.asarray(spiky_derivative(r, h, dim)) / r
    return np.einsum("pi,pj,p->ij", s, s, g) * dv


@pytest.mark.parametrize("dim", [2, 3])
def test_wall_moment_tables_match_half_space_sums(dim):
    """M(d) = ∫_wall s sᵀ ŵ'(r)/r: −I/2 on the wall, −I deep behind it, 0 beyond h, and equal to a
    brute-force cell sum, diagonal in the wall frame."""
    h = 1.0
    tab = wall_moment_tables(h, dim)
    z = np.linspace(-h, h, tab.shape[1])
    assert np.allclose(tab[:, tab.shape[1] // 2], -0.5, atol=1e-6)
    assert np.allclose(tab[:, 0], -1.0, atol=1e-4) and np.all(tab[:, -1] == 0.0)
    pts, dv = _cells(dim, h, 0.01 if dim == 2 else 0.025)
    wall = pts[pts[:, -1] < 0.0]  # the wall plane is the last axis = 0, normal +e_last
    for dist in (-0.3, 0.0, 0.25, 0.6):
        s = -wall.copy()
        s[:, -1] += dist
        m = _moment(s, h, dim, dv)
        mt, mn = np.interp(dist, z, tab[0]), np.interp(dist, z, tab[1])
        assert np.allclose(m, np.diag([mt] * (dim - 1) + [mn]), rtol=0, atol=1.5e-2 * max(abs(mn), 0.05))


@pytest.mark.parametrize("dim", [2, 3])
def test_corner_moment_tables_match_quarter_space_sums(dim):
    """∫_Q s sᵀ ŵ'(r)/r over the region behind two perpendicular walls (normals e0, e1) against a
    brute-force cell sum, with Q11, Q22 = Q11ᵀ, Q12 and the edge component Qee."""
    h = 1.0
    size = 65
    q = corner_moment_tables(h, dim, size=size, fine=300)
    d = np.linspace(-h, h, size)
    pts, dv = _cells(dim, h, 0.01 if dim == 2 else 0.025)
    quarter = pts[(pts[:, 0] < 0.0) & (pts[:, 1] < 0.0)]
    for d1, d2 in ((0.0, 0.0), (0.25, -0.125), (-0.375, 0.5)):
        x = np.zeros(dim)
        x[0], x[1] = d1, d2
        m = _moment(x - quarter, h, dim, dv)
        i, j = int(np.argmin(np.abs(d - d1))), int(np.argmin(np.abs(d - d2)))
        want = np.zeros((dim, dim))
        want[0, 0], want[1, 1], want[0, 1] = q[0, i, j], q[0, j, i], q[1, i, j]
        want[1, 0] = want[0, 1]
        if dim == 3:
            want[2, 2] = q[2, i, j]
        assert np.allclose(m, want, rtol=0, atol=1.5e-2 * max(abs(want[0, 0]), 0.05)), (d1, d2, m, want)
    assert np.all(q[2] == 0.0) if dim == 2 else np.allclose(q[2, 0, 0], -1.0, atol=1e-3)
