"""Numba kernels: 3D mean value coordinates and their gradients (9.8–9.10, Appendix D).

For a triangle T = (a, b, c) of the (outward) triangulated element boundary and an
evaluation point x, with d_k = v_k - x, the spherical triangle's moment
``m_T = ∫ u dS = ½ Σ_edges θ_pq (d_p × d_q)/|d_p × d_q|`` is written as
``m_T = Σ_k w_{T,k} d_k`` (Cramer's rule), which gives

    w_{T,i} = m_T · (d_j × d_k) / D_T,   D_T = d_i · (d_j × d_k) = 6 V_{i,j,k}(x),

the volume ratios of (9.8). Summing over T gives the weights w_i; (9.10)
normalises them. Because Σ_T m_T = ∫_{S²} u dS = 0, Σ_i w_i d_i = 0, which is
linear precision (9.11). Gradients are the exact derivatives of these
expressions (the corrected Appendix D: ∇D_T = -(v_j - v_i) × (v_k - v_i)).
Triangles of zero area contribute nothing and are skipped (9.1.1, "numerical
issues").

Robustness near faces: every weight is multiplied by σ = Π h_U, the distances to the
planes of the (up to) three triangles with the largest weights. φ is unchanged, but the
nearest triangles' weights become ``Ñ_T Π_{U≠T} h_U`` without the division by their small
h_T, so ∇φ no longer forms O(1) results from O(1/h²) terms (which cost 4.7e-9 of linear
precision at h ≈ 1e-8; now ~1e-12 at h = 1e-10 from a face). Within h of an edge the
great-circle normal of that edge still has relative error ~eps/h (a known limit).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True)
def _triangle_terms(pa, pb, pc, x, N, gN, nrm, want_grad):
    """Numerators of triangle (pa, pb, pc) for point x; returns D_T.

    Writes ``N[r] = m_T · (d_j × d_k)`` (3,), their gradients ``gN[r]`` (3, 3) and
    the (unnormalised) face normal ``nrm`` (3,). The triangle's weights are
    ``N[r] / D_T``; D_T = 0 (x in the face plane) means no contribution.
    """
    d = np.empty((3, 3))
    for k in range(3):
        d[0, k] = pa[k] - x[k]
        d[1, k] = pb[k] - x[k]
        d[2, k] = pc[k] - x[k]
    # D = (v_a - x) . ((v_b - v_a) x (v_c - v_a)), exact near the face plane
    e1 = np.empty(3)
    e2 = np.empty(3)
    for k in range(3):
        e1[k] = pb[k] - pa[k]
        e2[k] = pc[k] - pa[k]
    nrm[0] = e1[1] * e2[2] - e1[2] * e2[1]
    nrm[1] = e1[2] * e2[0] - e1[0] * e2[2]
    nrm[2] = e1[0] * e2[1] - e1[1] * e2[0]
    D = d[0, 0] * nrm[0] + d[0, 1] * nrm[1] + d[0, 2] * nrm[2]
    if D == 0.0:
        return 0.0
    m = np.zeros(3)
    J = np.zeros((3, 3))
    for e in range(3):
        p = e
        q = (e + 1) % 3
        ax = d[p, 0]
        ay = d[p, 1]
        az = d[p, 2]
        bx = d[q, 0]
        by = d[q, 1]
        bz = d[q, 2]
        cx = ay * bz - az * by
        cy = az * bx - ax * bz
        cz = ax * by - ay * bx
        s = np.sqrt(cx * cx + cy * cy + cz * cz)
        t = ax * bx + ay * by + az * bz
        if s == 0.0:
            continue  # x on the edge line: the edge's term vanishes (θ = 0) or x is on the boundary
        th = np.arctan2(s, t)
        nx = cx / s
        ny = cy / s
        nz = cz / s
        m[0] += 0.5 * th * nx
        m[1] += 0.5 * th * ny
        m[2] += 0.5 * th * nz
        if want_grad:
            # ∇θ = (t n×(b-a) + s (a+b)) / (s² + t²)
            gx = bx - ax
            gy = by - ay
            gz = bz - az
            qx = ny * gz - nz * gy
            qy = nz * gx - nx * gz
            qz = nx * gy - ny * gx
            den = s * s + t * t
            tx = (t * qx + s * (ax + bx)) / den
            ty = (t * qy + s * (ay + by)) / den
            tz = (t * qz + s * (az + bz)) / den
            # J(θ n) = n ∇θᵀ + (θ/s)(I - n nᵀ)[b - a]_x
            r = th / s
            # [g]_x with g = b - a
            G = np.array(((0.0, -gz, gy), (gz, 0.0, -gx), (-gy, gx, 0.0)))
            nv = np.array((nx, ny, nz))
            tv = np.array((tx, ty, tz))
            for j in range(3):
                ng = nv[0] * G[0, j] + nv[1] * G[1, j] + nv[2] * G[2, j]
                for i in range(3):
                    J[i, j] += 0.5 * (nv[i] * tv[j] + r * (G[i, j] - nv[i] * ng))
    for r in range(3):
        j = (r + 1) % 3
        k = (r + 2) % 3
        # c = d_j x d_k
        cx = d[j, 1] * d[k, 2] - d[j, 2] * d[k, 1]
        cy = d[j, 2] * d[k, 0] - d[j, 0] * d[k, 2]
        cz = d[j, 0] * d[k, 1] - d[j, 1] * d[k, 0]
        N[r] = m[0] * cx + m[1] * cy + m[2] * cz
        if want_grad:
            # ∇N = Jᵀ c + m × (d_k - d_j)
            ex = d[k, 0] - d[j, 0]
            ey = d[k, 1] - d[j, 1]
            ez = d[k, 2] - d[j, 2]
            gN[r, 0] = J[0, 0] * cx + J[1, 0] * cy + J[2, 0] * cz + (m[1] * ez - m[2] * ey)
            gN[r, 1] = J[0, 1] * cx + J[1, 1] * cy + J[2, 1] * cz + (m[2] * ex - m[0] * ez)
            gN[r, 2] = J[0, 2] * cx + J[1, 2] * cy + J[2, 2] * cz + (m[0] * ey - m[1] * ex)
    return D


@njit(cache=True)
def _on_triangle(pa, pb, pc, x, eps):
    """Barycentric coordinates if x lies on triangle (pa, pb, pc) within eps, else bary[0] = nan.

    Scalar arithmetic (the cross products of ``np.cross`` written out, same operation order):
    array expressions and ``np.cross`` cost more to compile than the whole test.
    """
    bary = np.full(3, np.nan)
    e1x, e1y, e1z = pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]
    e2x, e2y, e2z = pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    nn = np.sqrt(nx * nx + ny * ny + nz * nz)
    if nn == 0.0:
        return bary
    rx, ry, rz = x[0] - pa[0], x[1] - pa[1], x[2] - pa[2]
    dist = abs(rx * nx + ry * ny + rz * nz) / nn
    if dist > eps:
        return bary
    # (r × e2) · n and (e1 × r) · n
    l1 = ((ry * e2z - rz * e2y) * nx + (rz * e2x - rx * e2z) * ny + (rx * e2y - ry * e2x) * nz) / (nn * nn)
    l2 = ((e1y * rz - e1z * ry) * nx + (e1z * rx - e1x * rz) * ny + (e1x * ry - e1y * rx) * nz) / (nn * nn)
    l0 = 1.0 - l1 - l2
    lim = -eps / np.sqrt(nn)
    if l0 >= lim and l1 >= lim and l2 >= lim:
        bary[0] = l0
        bary[1] = l1
        bary[2] = l2
    return bary


@njit(cache=True)
def mvc_point(verts, tris, x, scale, phi, grad, want_grad):
    """Coordinates (and gradients) of one point for one polyhedron; writes phi (n,), grad (n,3).

    Points on the boundary (within 1e-12·scale) get the barycentric coordinates of
    the triangle they lie on; their gradient is evaluated 1e-7·scale inside.
    """
    n = verts.shape[0]
    mt = tris.shape[0]
    eps = 1e-12 * scale
    # on a vertex / on a face: the limit is barycentric on the boundary triangle
    hit = -1
    bary = np.full(3, np.nan)
    for t in range(mt):
        b = _on_triangle(verts[tris[t, 0]], verts[tris[t, 1]], verts[tris[t, 2]], x, eps)
        if not np.isnan(b[0]):
            hit = t
            bary = b
            break
    xe = x.copy()
    if hit >= 0:
        for k in range(n):
            phi[k] = 0.0
        for r in range(3):
            phi[tris[hit, r]] += bary[r]
        if not want_grad:
            return
        c = np.zeros(3)
        for k in range(n):
            c += verts[k]
        c /= n
        dirv = c - x
        dn = np.sqrt((dirv * dirv).sum())
        xe = x + 1e-7 * scale * dirv / dn
    # per-triangle numerators N_{T,r}, gradients and D_T (weights w_{T,r} = N_{T,r} / D_T)
    Nt = np.zeros((mt, 3))
    gNt = np.zeros((mt, 3, 3))
    nt = np.zeros((mt, 3))
    Dt = np.zeros(mt)
    for t in range(mt):
        a = tris[t, 0]
        b = tris[t, 1]
        c2 = tris[t, 2]
        e1x, e1y, e1z = verts[b, 0] - verts[a, 0], verts[b, 1] - verts[a, 1], verts[b, 2] - verts[a, 2]
        e2x, e2y, e2z = verts[c2, 0] - verts[a, 0], verts[c2, 1] - verts[a, 1], verts[c2, 2] - verts[a, 2]
        crx = e1y * e2z - e1z * e2y
        cry = e1z * e2x - e1x * e2z
        crz = e1x * e2y - e1y * e2x
        if np.sqrt(crx * crx + cry * cry + crz * crz) <= 1e-14 * (
                (e1x * e1x + e1y * e1y + e1z * e1z) + (e2x * e2x + e2y * e2y + e2z * e2z)):
            continue  # zero-area triangle: no net contribution
        D = _triangle_terms(verts[a], verts[b], verts[c2], xe, Nt[t], gNt[t], nt[t], want_grad)
        if D == 0.0:
            continue
        # normalise by |nrm|: w_{T,r} = Ñ_{T,r} / h_T with h_T = D_T/|nrm_T| the distance to the plane
        ln = np.sqrt((nt[t] * nt[t]).sum())
        Dt[t] = D / ln
        for r in range(3):
            Nt[t, r] /= ln
            for j in range(3):
                gNt[t, r, j] /= ln
        for j in range(3):
            nt[t, j] /= ln
    # Rescale every weight by σ = Π_{U∈S} h_U over the set S of (up to) three triangles with the
    # largest weights (the faces nearest to x: one near a face, two near an edge, three near a
    # vertex). φ is invariant under a common factor, but near a face (h → 0) the plain weights
    # grow like 1/h and their gradients like 1/h², and forming ∇φ from them loses digits in
    # proportion to 1/h (4.7e-9 at h ≈ 1e-8). Scaled, a triangle T ∈ S contributes
    # Ñ_T Π_{U∈S∖T} h_U, free of division by its small h_T; every term stays bounded.
    sel = np.full(3, -1, dtype=np.int64)
    selw = np.full(3, -np.inf)
    for t in range(mt):
        if Dt[t] == 0.0:
            continue
        wt = (Nt[t, 0] + Nt[t, 1] + Nt[t, 2]) / Dt[t]
        if wt > selw[2]:
            k = 2
            while k > 0 and wt > selw[k - 1]:
                selw[k] = selw[k - 1]
                sel[k] = sel[k - 1]
                k -= 1
            selw[k] = wt
            sel[k] = t
    ns = 0
    for k in range(3):
        if sel[k] >= 0:
            ns += 1
    sig = 1.0
    gsig = np.zeros(3)
    for k in range(ns):
        sig *= Dt[sel[k]]
    for k in range(ns):
        pr = 1.0
        for k2 in range(ns):
            if k2 != k:
                pr *= Dt[sel[k2]]
        for j in range(3):
            gsig[j] -= nt[sel[k], j] * pr  # ∇h_U = -n̂_U
    w = np.zeros(n)
    gw = np.zeros((n, 3))
    for t in range(mt):
        h = Dt[t]
        if h == 0.0:
            continue
        ks = -1
        for k in range(ns):
            if sel[k] == t:
                ks = k
        if ks >= 0:
            # P_T = Π_{U∈S∖T} h_U and its gradient
            P = 1.0
            gP = np.zeros(3)
            for k in range(ns):
                if k == ks:
                    continue
                P *= Dt[sel[k]]
                pr = 1.0
                for k2 in range(ns):
                    if k2 != k and k2 != ks:
                        pr *= Dt[sel[k2]]
                for j in range(3):
                    gP[j] -= nt[sel[k], j] * pr
            for r in range(3):
                i = tris[t, r]
                w[i] += Nt[t, r] * P
                if want_grad:
                    for j in range(3):
                        gw[i, j] += gNt[t, r, j] * P + Nt[t, r] * gP[j]
        else:
            q = sig / h
            for r in range(3):
                i = tris[t, r]
                wi = Nt[t, r] / h
                w[i] += wi * sig
                if want_grad:
                    # ∇(σ Ñ / h) = (σ/h) ∇Ñ + (Ñ/h) (∇σ + (σ/h) n̂)
                    for j in range(3):
                        gw[i, j] += q * gNt[t, r, j] + wi * (gsig[j] + q * nt[t, j])
    W = w.sum()
    if hit < 0:
        for k in range(n):
            phi[k] = w[k] / W
    if want_grad:
        gW = np.zeros(3)
        for k in range(n):
            gW += gw[k]
        for k in range(n):
            pk = w[k] / W
            for j in range(3):
                grad[k, j] = (gw[k, j] - pk * gW[j]) / W


@njit(cache=True)
def _scale(verts):
    """Diagonal of the bounding box of ``verts`` (n, 3)."""
    s2 = 0.0
    for k in range(3):
        lo = verts[0, k]
        hi = verts[0, k]
        for i in range(1, verts.shape[0]):
            lo = min(lo, verts[i, k])
            hi = max(hi, verts[i, k])
        s2 += (hi - lo) ** 2
    return np.sqrt(s2)


@njit(cache=True, parallel=True)
def mvc_many(verts, tris, points, want_grad):
    """Coordinates of many points in one polyhedron: phi (P,n), grad (P,n,3)."""
    # A thin prange loop (no array expressions in the parallel function: each would be a parfor).
    n = verts.shape[0]
    P = points.shape[0]
    phi = np.empty((P, n))
    grad = np.empty((P, n, 3))
    scale = _scale(verts)
    for p in prange(P):
        _zero_grad(grad[p])
        mvc_point(verts, tris, points[p], scale, phi[p], grad[p], want_grad)
    return phi, grad


@njit(cache=True)
def _zero_grad(grad):
    for i in range(grad.shape[0]):
        for j in range(3):
            grad[i, j] = 0.0


@njit(cache=True)
def _element_gradients(e, points, node_off, nodes, tri_off, tris_local, sample_off, samples, gofs, phi, grad):
    """Shape functions and gradients at the samples of element ``e`` (body of :func:`mvc_elements`)."""
    n = node_off[e + 1] - node_off[e]
    verts = np.empty((n, 3))
    for k in range(n):
        verts[k] = points[nodes[node_off[e] + k]]
    tris = tris_local[tri_off[e]:tri_off[e + 1]]
    scale = _scale(verts)
    want_grad = n > 0  # a run-time bool (always true): the same compiled mvc_point as mvc_many's
    for q in range(sample_off[e], sample_off[e + 1]):
        base = gofs[e] + (q - sample_off[e]) * n
        mvc_point(verts, tris, samples[q], scale, phi[base:base + n], grad[base:base + n], want_grad)


@njit(cache=True)
def _gradient_offsets(node_off, sample_off):
    ne = node_off.shape[0] - 1
    gofs = np.zeros(ne + 1, dtype=np.int64)
    for e in range(ne):
        gofs[e + 1] = gofs[e] + (node_off[e + 1] - node_off[e]) * (sample_off[e + 1] - sample_off[e])
    return gofs, np.zeros(gofs[ne]), np.zeros((gofs[ne], 3))


@njit(cache=True, parallel=True)
def mvc_elements(points, node_off, nodes, tri_off, tris_local, sample_off, samples):
    """Gradients of all shape functions at each element's samples.

    ``tris_local`` index into the element's sorted node list. Element e has
    samples ``sample_off[e]:sample_off[e+1]``; its gradients occupy
    ``grad[gofs[e] + q*n_e + i]`` with ``gofs[e] = Σ_{e'<e} n_{e'} · q_{e'}``.
    Returns (phi_flat, grad_flat (·,3), gofs (E+1,)).
    """
    ne = node_off.shape[0] - 1
    gofs, phi, grad = _gradient_offsets(node_off, sample_off)
    for e in prange(ne):
        _element_gradients(np.int64(e), points, node_off, nodes, tri_off, tris_local, sample_off, samples, gofs, phi, grad)
    return phi, grad, gofs
