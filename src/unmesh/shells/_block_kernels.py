"""Vectorised (SIMD) evaluation of the elastic forces for a block of nodes (thesis 7.2.2, 7.5-7.17).

The per-fiber geometry (arc length B.4 and tangent angle 7.10 with their gradients) is the
bulk of a force pass. Here it runs on blocks of up to :data:`BLK` fibers (the fibers of
consecutive centre nodes, contiguous in the topology) stored as rows of one flat scratch
array, in loops without branches or library calls, so that the compiler turns them into
4-wide AVX instructions: first the edge vectors and centre normals are gathered, then the
speed samples of all fibers are accumulated sample by sample, then the angle and all
gradients are formed, and finally the node sums, energies and forces of each node of the
block are taken from the rows (:func:`block_forces`). The arithmetic is that of
:func:`unmesh.shells._fiber_kernels.arc` and ``angle`` (same formulas, up to round-off),
checked against the numpy reference in ``tests/shells/test_energy.py``.

Kernels here are compiled with ``error_model="numpy"`` (a division by zero gives inf
instead of raising), which the vectoriser needs; every division is guarded by a select.
"""

from __future__ import annotations

import math

from numba import njit

from unmesh.shells._fiber_kernels import FASTMATH, SOFT_X, atan2, degenerate_edges, umbrella_at

#: Fibers per block (one row of the scratch array).
BLK = 128
#: Rows of the scratch (each BLK doubles): edge vectors d1, d2 (0-5), centre normal (6-8),
#: regularisation (9), dl/dx1 (10-12, Gram entries before), l~ (13), dl/dx2 (14-16, speed
#: sums before), dtheta/dx1 (17-19), dtheta/dx2 (20-22), dtheta/dN (23-25), theta (26).
ROWS = 27
_D, _N, _SOFT, _GLA, _L, _GLC, _GA, _GC, _GN, _TH = 0, 6, 9, 10, 13, 14, 17, 20, 23, 26


@njit(cache=True, fastmath=FASTMATH, error_model="numpy", inline="always")
def _angle_terms(d10, d11, d12, d20, d21, d22, n0, n1, n2, soft):
    """Branch-free tangent angle and gradients (same formulas as ``_fiber_kernels.angle``)."""
    t00 = -1.25 * d10 - 0.25 * d20
    t01 = -1.25 * d11 - 0.25 * d21
    t02 = -1.25 * d12 - 0.25 * d22
    t10 = 0.25 * d10 + 1.25 * d20
    t11 = 0.25 * d11 + 1.25 * d21
    t12 = 0.25 * d12 + 1.25 * d22
    tc0 = 0.5 * (d20 - d10)
    tc1 = 0.5 * (d21 - d11)
    tc2 = 0.5 * (d22 - d12)
    u0 = n1 * tc2 - n2 * tc1
    u1 = n2 * tc0 - n0 * tc2
    u2 = n0 * tc1 - n1 * tc0
    tt = tc0 * tc0 + tc1 * tc1 + tc2 * tc2
    ss = soft * soft
    rho = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2 + ss * tt)
    ir0 = 1.0 / rho
    ir = ir0 if rho > 0.0 else 0.0
    a0 = u0 * ir
    a1 = u1 * ir
    a2 = u2 * ir
    c0 = t01 * t12 - t02 * t11
    c1 = t02 * t10 - t00 * t12
    c2 = t00 * t11 - t01 * t10
    ta0 = t00 * a0 + t01 * a1 + t02 * a2
    ta1 = t10 * a0 + t11 * a1 + t12 * a2
    X = t00 * t10 + t01 * t11 + t02 * t12 - ta0 * ta1 + SOFT_X * tt
    Y = a0 * c0 + a1 * c1 + a2 * c2
    theta = atan2(Y, X)
    D = X * X + Y * Y
    iD0 = 1.0 / D
    iD = iD0 if D > 0.0 else 0.0           # no gradient where the angle is undefined
    gx = -Y * iD
    gy = X * iD
    # dtheta/dt0 = gy (t1 x a) + gx (t1 - (t1.a) a), dtheta/dt1 = gy (a x t0) + gx (t0 - (t0.a) a)
    p0 = t11 * a2 - t12 * a1
    p1 = t12 * a0 - t10 * a2
    p2 = t10 * a1 - t11 * a0
    r0 = a1 * t02 - a2 * t01
    r1 = a2 * t00 - a0 * t02
    r2 = a0 * t01 - a1 * t00
    g00 = gy * p0 + gx * (t10 - ta1 * a0)
    g01 = gy * p1 + gx * (t11 - ta1 * a1)
    g02 = gy * p2 + gx * (t12 - ta1 * a2)
    g10 = gy * r0 + gx * (t00 - ta0 * a0)
    g11 = gy * r1 + gx * (t01 - ta0 * a1)
    g12 = gy * r2 + gx * (t02 - ta0 * a2)
    # through a = u/rho, u = N x tc: dtheta/da = gy (t0 x t1) - gx ((t1.a) t0 + (t0.a) t1)
    ga0 = gy * c0 - gx * (ta1 * t00 + ta0 * t10)
    ga1 = gy * c1 - gx * (ta1 * t01 + ta0 * t11)
    ga2 = gy * c2 - gx * (ta1 * t02 + ta0 * t12)
    ug = (u0 * ga0 + u1 * ga1 + u2 * ga2) * (ir * ir * ir)
    gu0 = ga0 * ir - u0 * ug
    gu1 = ga1 * ir - u1 * ug
    gu2 = ga2 * ir - u2 * ug
    gt0 = gu1 * n2 - gu2 * n1
    gt1 = gu2 * n0 - gu0 * n2
    gt2 = gu0 * n1 - gu1 * n0
    sx = ss * ug - 2.0 * SOFT_X * gx
    gt0 -= sx * tc0
    gt1 -= sx * tc1
    gt2 -= sx * tc2
    return (theta,
            -1.25 * g00 + 0.25 * g10 - 0.5 * gt0, -1.25 * g01 + 0.25 * g11 - 0.5 * gt1,
            -1.25 * g02 + 0.25 * g12 - 0.5 * gt2,
            -0.25 * g00 + 1.25 * g10 + 0.5 * gt0, -0.25 * g01 + 1.25 * g11 + 0.5 * gt1,
            -0.25 * g02 + 1.25 * g12 + 0.5 * gt2,
            tc1 * gu2 - tc2 * gu1, tc2 * gu0 - tc0 * gu2, tc0 * gu1 - tc1 * gu0)


@njit(cache=True, fastmath=FASTMATH, error_model="numpy", inline="always")
def block_geometry(k0, m, x, fibers, s, soft, gram, blk):
    """l~, theta and their gradients of the fibers ``k0 .. k0 + m`` (m <= BLK) into the rows of ``blk``.

    ``s`` (N, 3) are the umbrella vectors (normals of the tangent angles) of the centre
    nodes, ``soft`` (N,) their regularisation, ``gram`` the table of
    :func:`unmesh.shells._fiber_kernels.gram_weights`.
    """
    B = BLK
    for q in range(m):                                  # gather
        k = k0 + q
        j1 = fibers[k, 0]
        i = fibers[k, 1]
        j2 = fibers[k, 2]
        blk[(_D + 0) * B + q] = x[j1, 0] - x[i, 0]
        blk[(_D + 1) * B + q] = x[j1, 1] - x[i, 1]
        blk[(_D + 2) * B + q] = x[j1, 2] - x[i, 2]
        blk[(_D + 3) * B + q] = x[j2, 0] - x[i, 0]
        blk[(_D + 4) * B + q] = x[j2, 1] - x[i, 1]
        blk[(_D + 5) * B + q] = x[j2, 2] - x[i, 2]
        blk[(_N + 0) * B + q] = s[i, 0]
        blk[(_N + 1) * B + q] = s[i, 1]
        blk[(_N + 2) * B + q] = s[i, 2]
        blk[_SOFT * B + q] = soft[i]
    for q in range(m):                                  # Gram entries of the edge vectors
        d10 = blk[(_D + 0) * B + q]
        d11 = blk[(_D + 1) * B + q]
        d12 = blk[(_D + 2) * B + q]
        d20 = blk[(_D + 3) * B + q]
        d21 = blk[(_D + 4) * B + q]
        d22 = blk[(_D + 5) * B + q]
        blk[(_GLA + 0) * B + q] = d10 * d10 + d11 * d11 + d12 * d12
        blk[(_GLA + 1) * B + q] = d10 * d20 + d11 * d21 + d12 * d22
        blk[(_GLA + 2) * B + q] = d20 * d20 + d21 * d21 + d22 * d22
        blk[_L * B + q] = 0.0
        blk[(_GLC + 0) * B + q] = 0.0
        blk[(_GLC + 1) * B + q] = 0.0
        blk[(_GLC + 2) * B + q] = 0.0
    for r in range(gram.shape[0]):                      # speed samples (B.4), sample by sample
        c0 = gram[r, 0]
        c1 = gram[r, 1]
        c2 = gram[r, 2]
        e0 = gram[r, 3]
        e1 = gram[r, 4]
        e2 = gram[r, 5]
        for q in range(m):
            v = c0 * blk[(_GLA + 0) * B + q] + c1 * blk[(_GLA + 1) * B + q] + c2 * blk[(_GLA + 2) * B + q]
            sp = math.sqrt(max(v, 0.0))
            inv0 = 1.0 / sp
            inv = inv0 if sp > 0.0 else 0.0
            blk[_L * B + q] += sp
            blk[(_GLC + 0) * B + q] += e0 * inv
            blk[(_GLC + 1) * B + q] += e1 * inv
            blk[(_GLC + 2) * B + q] += e2 * inv
    scale = 2.0 / gram.shape[0]
    for q in range(m):                                  # angle (7.10) and all gradients
        d10 = blk[(_D + 0) * B + q]
        d11 = blk[(_D + 1) * B + q]
        d12 = blk[(_D + 2) * B + q]
        d20 = blk[(_D + 3) * B + q]
        d21 = blk[(_D + 4) * B + q]
        d22 = blk[(_D + 5) * B + q]
        th, ga0, ga1, ga2, gc0, gc1, gc2, gn0, gn1, gn2 = _angle_terms(
            d10, d11, d12, d20, d21, d22, blk[(_N + 0) * B + q], blk[(_N + 1) * B + q], blk[(_N + 2) * B + q],
            blk[_SOFT * B + q])
        s11 = blk[(_GLC + 0) * B + q]
        s12 = blk[(_GLC + 1) * B + q]
        s22 = blk[(_GLC + 2) * B + q]
        blk[_L * B + q] *= scale
        blk[(_GLA + 0) * B + q] = s11 * d10 + s12 * d20
        blk[(_GLA + 1) * B + q] = s11 * d11 + s12 * d21
        blk[(_GLA + 2) * B + q] = s11 * d12 + s12 * d22
        blk[(_GLC + 0) * B + q] = s12 * d10 + s22 * d20
        blk[(_GLC + 1) * B + q] = s12 * d11 + s22 * d21
        blk[(_GLC + 2) * B + q] = s12 * d12 + s22 * d22
        blk[(_GA + 0) * B + q] = ga0
        blk[(_GA + 1) * B + q] = ga1
        blk[(_GA + 2) * B + q] = ga2
        blk[(_GC + 0) * B + q] = gc0
        blk[(_GC + 1) * B + q] = gc1
        blk[(_GC + 2) * B + q] = gc2
        blk[(_GN + 0) * B + q] = gn0
        blk[(_GN + 1) * B + q] = gn1
        blk[(_GN + 2) * B + q] = gn2
        blk[_TH * B + q] = th


@njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def block_forces(a, b, x, pairs, pstart, pcount, soft, fibers, fstart, fcount, lorig, lplast, aorig, aplast,
                 sscale, bscale, ks, kb, gram, ref, offs, buf, blk, out_len, out_ang, out_s, out_normal, out_node,
                 out_es, out_eb, scatter, only, ratio2):
    """Umbrellas, fiber measures, node terms, energies and (``scatter``) forces of nodes ``a .. b-1``
    (with a non-empty mask ``only`` (N,), the forces of the listed nodes only).

    The fibers of the block (at most :data:`BLK`) go through :func:`block_geometry`; then
    per node as :func:`unmesh.shells._force_kernels.node_forces`: ``buf -= dE/dx``. Returns the
    number of fibers whose angle moved by more than pi/2 from ``ref`` and (``ratio2 > 0``)
    the number of degenerate fibers
    (:func:`unmesh.shells._fiber_kernels.degenerate_edges`, from the gathered edge vectors).
    """
    B = BLK
    for i in range(a, b):
        umbrella_at(i, x, pairs, pstart[i], pstart[i] + pcount[i], out_s, out_normal)
    k0 = fstart[a]
    m = fstart[b - 1] + fcount[b - 1] - k0
    block_geometry(k0, m, x, fibers, out_s, soft, gram, blk)
    two_pi = 2.0 * math.pi
    inv_two_pi = 1.0 / two_pi
    half_pi = 0.5 * math.pi
    folds = 0
    bad = 0
    if ratio2 > 0.0:
        for q in range(m):
            if degenerate_edges(blk[(_D + 0) * B + q], blk[(_D + 1) * B + q], blk[(_D + 2) * B + q],
                                blk[(_D + 3) * B + q], blk[(_D + 4) * B + q], blk[(_D + 5) * B + q],
                                blk[(_N + 0) * B + q], blk[(_N + 1) * B + q], blk[(_N + 2) * B + q],
                                blk[_SOFT * B + q], ratio2):
                bad += 1
    for q in range(m):                                  # the branch nearest the reference angle
        k = k0 + q
        th = blk[_TH * B + q]
        r = ref[k]
        th += two_pi * math.floor((r - th) * inv_two_pi + 0.5)
        if abs(th - r) > half_pi:
            folds += 1
        blk[_TH * B + q] = th
        out_ang[k] = th
        out_len[k] = blk[_L * B + q]
    q4 = math.pi / 4.0
    masked = only.shape[0] > 0
    for i in range(a, b):
        mi = fcount[i]
        push = scatter and (not masked or only[i])
        if mi == 0:
            for c in range(4):
                out_node[i, c] = 0.0
            out_es[i] = 0.0
            out_eb[i] = 0.0
            continue
        f0 = fstart[i]
        area = 0.0
        area0 = 0.0
        sig = 0.0
        bsum = 0.0
        h = 0.0
        h0 = 0.0
        for k in range(f0, f0 + mi):
            q = k - k0
            ln = blk[_L * B + q]
            l0 = lorig[k] + lplast[k]
            area += q4 * ln * ln
            area0 += q4 * l0 * l0
            sig += sscale[k]
            bk = bscale[k]
            bsum += bk
            h += bk * blk[_TH * B + q]
            h0 += bk * (aorig[k] + aplast[k])
        inv_m = 1.0 / mi
        area *= inv_m
        area0 *= inv_m
        sig *= inv_m
        if bsum > 0.0:
            h /= bsum
            h0 /= bsum
        out_node[i, 0] = area
        out_node[i, 1] = area0
        out_node[i, 2] = h
        out_node[i, 3] = h0
        da = area - area0 - offs[i, 0]
        dh = h - h0 - offs[i, 1]
        esum = 0.0
        gs0 = 0.0
        gs1 = 0.0
        gs2 = 0.0
        fi0 = 0.0
        fi1 = 0.0
        fi2 = 0.0
        kd = kb * area0 * dh * inv_m
        for k in range(f0, f0 + mi):
            q = k - k0
            ln = blk[_L * B + q]
            l0 = lorig[k] + lplast[k]
            dak = q4 * (ln * ln - l0 * l0)
            sk = sscale[k]
            esum += sk * dak * dak
            if not push:
                continue
            de_dl = ks * inv_m * (sig * da + sk * dak) * (0.5 * math.pi) * ln
            de_dth = kd * bscale[k]
            a0 = de_dl * blk[(_GLA + 0) * B + q] + de_dth * blk[(_GA + 0) * B + q]
            a1 = de_dl * blk[(_GLA + 1) * B + q] + de_dth * blk[(_GA + 1) * B + q]
            a2 = de_dl * blk[(_GLA + 2) * B + q] + de_dth * blk[(_GA + 2) * B + q]
            c0 = de_dl * blk[(_GLC + 0) * B + q] + de_dth * blk[(_GC + 0) * B + q]
            c1 = de_dl * blk[(_GLC + 1) * B + q] + de_dth * blk[(_GC + 1) * B + q]
            c2 = de_dl * blk[(_GLC + 2) * B + q] + de_dth * blk[(_GC + 2) * B + q]
            j1 = fibers[k, 0]
            j2 = fibers[k, 2]
            buf[j1, 0] -= a0
            buf[j1, 1] -= a1
            buf[j1, 2] -= a2
            buf[j2, 0] -= c0
            buf[j2, 1] -= c1
            buf[j2, 2] -= c2
            fi0 += a0 + c0
            fi1 += a1 + c1
            fi2 += a2 + c2
            gs0 += de_dth * blk[(_GN + 0) * B + q]
            gs1 += de_dth * blk[(_GN + 1) * B + q]
            gs2 += de_dth * blk[(_GN + 2) * B + q]
        out_es[i] = 0.5 * ks * (sig * da * da + esum * inv_m)
        out_eb[i] = 0.5 * kb * area0 * bsum * inv_m * dh * dh
        if not push:
            continue
        if gs0 != 0.0 or gs1 != 0.0 or gs2 != 0.0:
            # through the umbrella vector s_i = sum e_a x e_b: dE/dx_a = e_b x g, dE/dx_b = g x e_a
            xi0 = x[i, 0]
            xi1 = x[i, 1]
            xi2 = x[i, 2]
            for p in range(pstart[i], pstart[i] + pcount[i]):
                pa = pairs[p, 0]
                pb = pairs[p, 1]
                eb0 = x[pb, 0] - xi0
                eb1 = x[pb, 1] - xi1
                eb2 = x[pb, 2] - xi2
                ea0 = x[pa, 0] - xi0
                ea1 = x[pa, 1] - xi1
                ea2 = x[pa, 2] - xi2
                ga0 = eb1 * gs2 - eb2 * gs1
                ga1 = eb2 * gs0 - eb0 * gs2
                ga2 = eb0 * gs1 - eb1 * gs0
                gb0 = gs1 * ea2 - gs2 * ea1
                gb1 = gs2 * ea0 - gs0 * ea2
                gb2 = gs0 * ea1 - gs1 * ea0
                buf[pa, 0] -= ga0
                buf[pa, 1] -= ga1
                buf[pa, 2] -= ga2
                buf[pb, 0] -= gb0
                buf[pb, 1] -= gb1
                buf[pb, 2] -= gb2
                fi0 += ga0 + gb0
                fi1 += ga1 + gb1
                fi2 += ga2 + gb2
        buf[i, 0] += fi0
        buf[i, 1] += fi1
        buf[i, 2] += fi2
    return folds, bad
