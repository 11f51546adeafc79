"""Numba kernels of element integration (9.17–9.19), element stiffness and assembly.

Numpy references of each kernel are in the tests (``tests/fem/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from unmesh.fem._mvc_kernels import mvc_point


@njit(cache=True)
def _tri_cross(points, a, b, c):
    e1 = points[b] - points[a]
    e2 = points[c] - points[a]
    return np.array((e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]))


@njit(cache=True)
def sample_counts(node_off, tri_off):
    """Samples per element: 1 for tetrahedra, else one per vertex plus one per triangle."""
    ne = node_off.shape[0] - 1
    out = np.empty(ne, dtype=np.int64)
    for e in range(ne):
        n = node_off[e + 1] - node_off[e]
        m = tri_off[e + 1] - tri_off[e]
        out[e] = 1 if (n == 4 and m == 4) else n + m
    return out


@njit(cache=True)
def _zeros_integration(ne, n_nodes, n_samples, n_grads):
    """Zeroed outputs of :func:`integrate` (allocated outside the parallel function: no parfors)."""
    return (np.zeros(ne), np.zeros(n_nodes), np.zeros(n_samples), np.zeros((n_samples, 3)),
            np.zeros((n_grads, 3)))


@njit(cache=True)
def _integrate_element(e, points, node_off, nodes, tri_off, tris_local, sample_off, grad_off, correction,
                       vols, mu, weights, samples, grads):
    """Quadrature of element ``e`` (9.17–9.19) into the outputs of :func:`integrate`."""
    n = node_off[e + 1] - node_off[e]
    n0 = node_off[e]
    t0 = tri_off[e]
    m = tri_off[e + 1] - t0
    verts = np.empty((n, 3))
    for k in range(n):
        verts[k] = points[nodes[n0 + k]]
    c = np.zeros(3)
    for k in range(n):
        c += verts[k]
    c /= n
    tris = tris_local[t0:t0 + m]
    # cone volumes of the triangles to the centre (9.17)-(9.18) and exact boundary integrals
    tv = np.empty(m)
    exact = np.zeros((n, 3))
    V = 0.0
    for t in range(m):
        a = tris[t, 0]
        b = tris[t, 1]
        cc = tris[t, 2]
        cr = _tri_cross(verts, a, b, cc)
        tv[t] = ((verts[a] - c) * cr).sum() / 6.0
        V += tv[t]
        for r in range(3):
            exact[tris[t, r]] += cr / 6.0
    vols[e] = V
    for t in range(m):
        for r in range(3):
            mu[n0 + tris[t, r]] += tv[t] / (3.0 * V)
    s0 = sample_off[e]
    g0 = grad_off[e]
    if n == 4 and m == 4:
        # linear tetrahedron: one sample, constant barycentric gradients
        weights[s0] = V
        samples[s0] = c
        for t in range(m):
            opp = 6 - tris[t, 0] - tris[t, 1] - tris[t, 2]
            cr = _tri_cross(verts, tris[t, 0], tris[t, 1], tris[t, 2])
            grads[g0 + opp] = -cr / (6.0 * V)
        return
    lo = np.empty(3)
    hi = np.empty(3)
    for k in range(3):
        lo[k] = verts[:, k].min()
        hi[k] = verts[:, k].max()
    scale = np.sqrt(((hi - lo) ** 2).sum())
    phi = np.empty(n)
    for i in range(n):
        samples[s0 + i] = 0.8 * verts[i] + 0.2 * c
        weights[s0 + i] = V * mu[n0 + i] / 2.0
    for t in range(m):
        cf = (verts[tris[t, 0]] + verts[tris[t, 1]] + verts[tris[t, 2]]) / 3.0
        samples[s0 + n + t] = 0.9 * cf + 0.1 * c
        weights[s0 + n + t] = tv[t] / 2.0
    q = n + m
    # a run-time bool (always true here), not the literal True: one compiled mvc_point serves
    # this caller and mvc_many's run-time want_grad alike
    want_grad = q > 0
    for k in range(q):
        base = g0 + k * n
        mvc_point(verts, tris, samples[s0 + k], scale, phi, grads[base:base + n], want_grad)
    if correction:
        for i in range(n):
            acc = np.zeros(3)
            for k in range(q):
                acc += weights[s0 + k] * grads[g0 + k * n + i]
            fix = (exact[i] - acc) / V
            for k in range(q):
                grads[g0 + k * n + i] += fix


@njit(cache=True, parallel=True)
def integrate(points, node_off, nodes, tri_off, tris_local, sample_off, grad_off, correction):
    """Quadrature of every element (9.17–9.19) with MVC gradients at the samples.

    Returns
    -------
    volumes (E,), mu (Σn,) volume fractions (9.17), weights (Σq,) = V μ/2 and V ν/2
    (sum V per element), samples (Σq,3), grads (Σ n·q, 3): gradient of local
    shape function i at sample q of element e at ``grad_off[e] + q·n + i``.
    With ``correction``, grads get the consistency correction so that
    Σ_q w_q ∇φ_i(p_q) = ∮ φ_i n dA exactly.
    """
    # A thin prange loop over a serial element body: array expressions in a parallel
    # function become parfors of their own, which multiplied its compile time.
    ne = node_off.shape[0] - 1
    vols, mu, weights, samples, grads = _zeros_integration(ne, nodes.shape[0], sample_off[ne], grad_off[ne])
    for e in prange(ne):
        # np.int64: the parfor's own index is unsigned, a second signature of the body otherwise
        _integrate_element(np.int64(e), points, node_off, nodes, tri_off, tris_local, sample_off, grad_off, correction,
                           vols, mu, weights, samples, grads)
    return vols, mu, weights, samples, grads


@njit(cache=True, parallel=True)
def element_stiffness(node_off, sample_off, grad_off, weights, grads, lam, mu, k_off):
    """Element stiffness K_e = Σ_q w_q Bᵀ C B (9.19) in Lamé form, as (n,n,3,3) blocks.

    Block (a, b), entry (i, j) = Σ_q w_q (λ g_a,i g_b,j + μ g_a,j g_b,i + μ δ_ij g_a·g_b).
    ``lam``, ``mu`` are per element.
    """
    ne = node_off.shape[0] - 1
    out = np.empty(k_off[ne])  # zeroed per element below (np.zeros here would be a parfor)
    for e in prange(ne):
        n = node_off[e + 1] - node_off[e]
        base = k_off[e]
        for k in range(base, k_off[e + 1]):
            out[k] = 0.0
        la = lam[e]
        mm = mu[e]
        for q in range(sample_off[e], sample_off[e + 1]):
            w = weights[q]
            g = grads[grad_off[e] + (q - sample_off[e]) * n: grad_off[e] + (q - sample_off[e] + 1) * n]
            for a in range(n):
                for b in range(n):
                    dot = g[a, 0] * g[b, 0] + g[a, 1] * g[b, 1] + g[a, 2] * g[b, 2]
                    o = base + (a * n + b) * 9
                    for i in range(3):
                        for j in range(3):
                            v = la * g[a, i] * g[b, j] + mm * g[a, j] * g[b, i]
                            if i == j:
                                v += mm * dot
                            out[o + i * 3 + j] += w * v
    return out


@njit(cache=True)
def scatter_blocks(block_map, blocks, nblocks):
    """Sum element blocks (K,9) into global blocks (nblocks,9) by ``block_map`` (K,)."""
    out = np.zeros((nblocks, 9))
    for k in range(block_map.shape[0]):
        b = block_map[k]
        for j in range(9):
            out[b, j] += blocks[k, j]
    return out


@njit(cache=True, inline="always")
def _rotation_entries(R, scale):
    """The entries of the rotation ``R`` (3, 3) and of ``scale·R``, row by row (18 floats)."""
    r00, r01, r02 = R[0, 0], R[0, 1], R[0, 2]
    r10, r11, r12 = R[1, 0], R[1, 1], R[1, 2]
    r20, r21, r22 = R[2, 0], R[2, 1], R[2, 2]
    return (r00, r01, r02, r10, r11, r12, r20, r21, r22,
            r00 * scale, r01 * scale, r02 * scale, r10 * scale, r11 * scale, r12 * scale,
            r20 * scale, r21 * scale, r22 * scale)


@njit(cache=True, nogil=True)
def warped_global_blocks(node_off, k_off, ke, rots, block_map, nblocks, scale):
    """Global blocks (nblocks, 9) of the scaled warped stiffness ``scale · Σ_e R_e K_e R_eᵀ`` in one pass.

    Serial, a scatter over the elements (the global sums would race; the parallel version is
    :func:`warped_global_rows`, with the same sums in the same order); the reference is
    :func:`rotated_blocks` followed by :func:`scatter_blocks` (times scale), which write and
    read all element blocks once more. (Rotating only the blocks a ≤ b and adding the
    transposes was measured no faster.)
    """
    ne = node_off.shape[0] - 1
    out = np.zeros((nblocks, 9))
    T = np.empty((3, 3))
    for e in range(ne):
        n = node_off[e + 1] - node_off[e]
        (r00, r01, r02, r10, r11, r12, r20, r21, r22,
         s00, s01, s02, s10, s11, s12, s20, s21, s22) = _rotation_entries(rots[e], scale)
        for ab in range(n * n):
            o = k_off[e] + ab * 9
            for j in range(3):
                k0 = ke[o + j]
                k1 = ke[o + 3 + j]
                k2 = ke[o + 6 + j]
                T[0, j] = s00 * k0 + s01 * k1 + s02 * k2
                T[1, j] = s10 * k0 + s11 * k1 + s12 * k2
                T[2, j] = s20 * k0 + s21 * k1 + s22 * k2
            b = block_map[o // 9]
            for i in range(3):
                t0 = T[i, 0]
                t1 = T[i, 1]
                t2 = T[i, 2]
                out[b, i * 3] += t0 * r00 + t1 * r01 + t2 * r02
                out[b, i * 3 + 1] += t0 * r10 + t1 * r11 + t2 * r12
                out[b, i * 3 + 2] += t0 * r20 + t1 * r21 + t2 * r22
    return out


@njit(cache=True, nogil=True, parallel=True)
def warped_global_rows(node_off, k_off, ke, rots, inc_off, inc_e, inc_a, block_map, nblocks, scale):
    """:func:`warped_global_blocks` in parallel over the rows (nodes), bit for bit the same.

    Row i gathers the rotated block rows of its elements (the incidence ``inc_off, inc_e,
    inc_a`` of :func:`unmesh.fem._pattern_kernels.node_incidence`), elements ascending, so
    every global block sums its terms in the order of the serial scatter over the elements,
    on any number of threads. It reads the element blocks in the nodes' order instead of
    streaming them: measured on the bunny benchmark (25k nodes, 82k elements, load ~1),
    105 ms on one thread against the scatter's 70 ms, 77 ms on two.
    """
    n = inc_off.shape[0] - 1
    out = np.zeros((nblocks, 9))
    for i in prange(n):
        for t in range(inc_off[i], inc_off[i + 1]):
            e = inc_e[t]
            m = node_off[e + 1] - node_off[e]
            (r00, r01, r02, r10, r11, r12, r20, r21, r22,
             s00, s01, s02, s10, s11, s12, s20, s21, s22) = _rotation_entries(rots[e], scale)
            o = k_off[e] + inc_a[t] * m * 9
            for _ in range(m):
                b = block_map[o // 9]
                k00, k01, k02 = ke[o], ke[o + 1], ke[o + 2]
                k10, k11, k12 = ke[o + 3], ke[o + 4], ke[o + 5]
                k20, k21, k22 = ke[o + 6], ke[o + 7], ke[o + 8]
                t00 = s00 * k00 + s01 * k10 + s02 * k20
                t01 = s00 * k01 + s01 * k11 + s02 * k21
                t02 = s00 * k02 + s01 * k12 + s02 * k22
                t10 = s10 * k00 + s11 * k10 + s12 * k20
                t11 = s10 * k01 + s11 * k11 + s12 * k21
                t12 = s10 * k02 + s11 * k12 + s12 * k22
                t20 = s20 * k00 + s21 * k10 + s22 * k20
                t21 = s20 * k01 + s21 * k11 + s22 * k21
                t22 = s20 * k02 + s21 * k12 + s22 * k22
                out[b, 0] += t00 * r00 + t01 * r01 + t02 * r02
                out[b, 1] += t00 * r10 + t01 * r11 + t02 * r12
                out[b, 2] += t00 * r20 + t01 * r21 + t02 * r22
                out[b, 3] += t10 * r00 + t11 * r01 + t12 * r02
                out[b, 4] += t10 * r10 + t11 * r11 + t12 * r12
                out[b, 5] += t10 * r20 + t11 * r21 + t12 * r22
                out[b, 6] += t20 * r00 + t21 * r01 + t22 * r02
                out[b, 7] += t20 * r10 + t21 * r11 + t22 * r12
                out[b, 8] += t20 * r20 + t21 * r21 + t22 * r22
                o += 9
    return out


@njit(cache=True, parallel=True)
def rotated_blocks(node_off, k_off, ke, rots):
    """Rotated element blocks R K_ab Rᵀ (stiffness warping, 9.1.4) as (Σn², 9)."""
    ne = node_off.shape[0] - 1
    out = np.empty((k_off[ne] // 9, 9))
    for e in prange(ne):
        n = node_off[e + 1] - node_off[e]
        R = rots[e]
        T = np.empty((3, 3))
        for ab in range(n * n):
            o = k_off[e] + ab * 9
            for i in range(3):
                for j in range(3):
                    T[i, j] = R[i, 0] * ke[o + j] + R[i, 1] * ke[o + 3 + j] + R[i, 2] * ke[o + 6 + j]
            r = o // 9
            for i in range(3):
                for j in range(3):
                    out[r, i * 3 + j] = T[i, 0] * R[j, 0] + T[i, 1] * R[j, 1] + T[i, 2] * R[j, 2]
    return out


@njit(cache=True, nogil=True)
def _warped_element(e, points_rest, x, node_off, nodes, k_off, ke, rots, fe, energy):
    """Warped force rows and energy of element ``e`` (body of :func:`warped_forces`)."""
    n = node_off[e + 1] - node_off[e]
    n0 = node_off[e]
    R = rots[e]
    dl = np.empty((n, 3))
    for a in range(n):
        p = nodes[n0 + a]
        for i in range(3):
            dl[a, i] = R[0, i] * x[p, 0] + R[1, i] * x[p, 1] + R[2, i] * x[p, 2] - points_rest[p, i]
    # remove the mean so round-off of large translations does not enter
    mean = np.zeros(3)
    for a in range(n):
        mean += dl[a]
    mean /= n
    for a in range(n):
        dl[a] -= mean
    en = 0.0
    for a in range(n):
        fa = np.zeros(3)
        for b in range(n):
            o = k_off[e] + (a * n + b) * 9
            for i in range(3):
                fa[i] += ke[o + i * 3] * dl[b, 0] + ke[o + i * 3 + 1] * dl[b, 1] + ke[o + i * 3 + 2] * dl[b, 2]
        en += 0.5 * (fa[0] * dl[a, 0] + fa[1] * dl[a, 1] + fa[2] * dl[a, 2])
        for i in range(3):
            fe[n0 + a, i] = -(R[i, 0] * fa[0] + R[i, 1] * fa[1] + R[i, 2] * fa[2])
    energy[e] = en


@njit(cache=True, nogil=True, parallel=True)
def warped_forces(points_rest, x, node_off, nodes, k_off, ke, rots, n_nodes):
    """Per-element warped elastic forces f_e = -R K_e (Rᵀ x_e - X_e) and energies.

    Returns (element forces (Σn,3), element energies (E,)). Summing the
    element forces per node gives the global elastic force.
    """
    # a thin prange loop over a serial body (array expressions here would be parfors)
    ne = node_off.shape[0] - 1
    fe = np.empty((nodes.shape[0], 3))  # every row is written by its element
    energy = np.empty(ne)
    for e in prange(ne):
        _warped_element(np.int64(e), points_rest, x, node_off, nodes, k_off, ke, rots, fe, energy)
    return fe, energy


@njit(cache=True)
def merge_rows(off_a, data_a, off_b, data_b, from_b, idx, new_off, out):
    """Row i of ``out`` (2-D views) = row ``idx[i]`` of b if ``from_b[i]`` else of a.

    The numpy reference is :func:`unmesh.fem.integration.merge_csr` with ``fast=False``.
    """
    for i in range(idx.shape[0]):
        o = new_off[i]
        j = idx[i]
        if from_b[i]:
            s = off_b[j]
            for r in range(off_b[j + 1] - s):
                for c in range(data_b.shape[1]):
                    out[o + r, c] = data_b[s + r, c]
        else:
            s = off_a[j]
            for r in range(off_a[j + 1] - s):
                for c in range(data_a.shape[1]):
                    out[o + r, c] = data_a[s + r, c]
