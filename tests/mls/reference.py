"""Plain numpy reference implementation of the MLS operators (for tests only).

Neighbours come from :func:`unmesh.spatial.radius_neighbors`; everything else is
vectorised numpy per query. Mirrors ``unmesh.mls._kernels`` step by step but shares
no code with it (eigenvectors by ``numpy.linalg.eigh``, the quadratic fit by
``numpy.linalg.lstsq``, ray starts by a brute-force test of all discs).
"""

from __future__ import annotations

import numpy as np

from unmesh.mls import MLSSurface
from unmesh.spatial import radius_neighbors


def _weights(d2: np.ndarray, s: np.ndarray, cutoff: float, kernel: str) -> np.ndarray:
    if kernel == "gaussian":
        lim = cutoff * s
        return np.where(d2 < lim * lim, np.exp(-d2 / (s * s)), 0.0)
    u = np.sqrt(d2) / (cutoff * s)
    return np.where(u < 1, (1 - u) ** 4 * (1 + 4 * u), 0.0)


def frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def local_fit(surf: MLSSurface, x: np.ndarray):
    """(foot p, normal n, mean q, sigma_local) of the local fit at x, or None."""
    c = surf.cloud
    off, idx = radius_neighbors(c.positions, surf.support * (1 + 1e-9), queries=x[None])
    idx = idx[off[0]:off[1]]
    if len(idx) == 0:
        return None
    xi = c.positions[idx]
    s = surf.sigmas[idx]
    w = _weights(((xi - x) ** 2).sum(1), s, surf.cutoff, surf.kernel)
    keep = w > 0
    if not keep.any():
        return None
    xi, w, ni, s = xi[keep], w[keep], c.normals[idx][keep], s[keep]
    W = w.sum()
    q = (w[:, None] * xi).sum(0) / W  # (3.6)
    h = (w[:, None] * ni).sum(0) / W  # (3.8)
    if surf.normal == "hermite":
        N = h / np.linalg.norm(h)
    else:
        r = xi - q
        cov = (w[:, None, None] * r[:, :, None] * r[:, None, :]).sum(0) / W  # (3.5)
        _, vec = np.linalg.eigh(cov)
        N = vec[:, 0] * np.sign(vec[:, 0] @ h or 1.0)
    o = x + (N @ (q - x)) * N
    sl = (w * s).sum() / W
    p, n = o, N
    if surf.degree == 2 and len(w) >= 6:
        t1, t2 = frame(N)
        r = xi - o
        u, v, z = r @ t1, r @ t2, r @ N
        B = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=1)
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(B * sw[:, None], z * sw, rcond=None)  # (3.3)
        p = o + coef[0] * N  # (3.4)
        n = N - coef[1] * t1 - coef[2] * t2
        n /= np.linalg.norm(n)
    return p, n, q, sl


def project(surf: MLSSurface, x: np.ndarray, max_iter: int = 30, tol: float = 1e-7):
    pts = np.full((len(x), 3), np.nan)
    nrm = np.full((len(x), 3), np.nan)
    for i, xx in enumerate(x):
        y = xx.copy()
        n = None
        for _ in range(max_iter):
            fit = local_fit(surf, y)
            if fit is None:
                n = None
                break
            p, n, _, sl = fit
            ynew = xx - (n @ (xx - p)) * n
            step = np.linalg.norm(ynew - y)
            y = ynew
            if step <= tol * sl:
                break
        if n is not None:
            pts[i], nrm[i] = y, n
    return pts, nrm


def inside(surf: MLSSurface, x: np.ndarray) -> np.ndarray:
    p, n = project(surf, x)
    return ~(np.einsum("ij,ij->i", x - p, n) > 0)  # (3.9), sign corrected


#: Number of regula-falsi steps taken by :func:`intersect` (lets tests check that the bracketing ran).
BRACKET_STEPS = [0]


def intersect(surf: MLSSurface, o: np.ndarray, d: np.ndarray, max_iter: int = 30, tol: float = 1e-7,
              eps2: float = 0.5, max_attempts: int = 32, bracket: bool = True):
    """Algorithm 3.1 with brute-force disc starts; returns (t, hit).

    ``bracket=False``: plain plane steps only (no regula falsi once a bracket exists).
    """
    c = surf.cloud
    rho = np.minimum(np.maximum(c.radii, surf.sigmas), surf.support * (1 + 1e-6))
    t_out = np.full(len(o), np.inf)
    hit = np.zeros(len(o), bool)
    for i in range(len(o)):
        oo, dd = o[i], d[i]
        dn = np.linalg.norm(dd)
        den = c.normals @ dd
        with np.errstate(divide="ignore", invalid="ignore"):
            th = np.einsum("ij,ij->i", c.normals, c.positions - oo) / den
        e = oo + th[:, None] * dd - c.positions
        ok = (den != 0) & (np.einsum("ij,ij->i", e, e) <= rho**2)
        tlo = -rho.max() / dn
        for _ in range(max_attempts):
            cand = ok & (th >= tlo)
            if not cand.any():
                break
            j = np.flatnonzero(cand)[np.argmin(th[cand])]
            t0 = t = th[j]
            conv = False
            a = b = None  # bracket ends (t, step) with step > 0 / step < 0
            last = 0
            for _ in range(max_iter):
                fit = local_fit(surf, oo + t * dd)
                if fit is None:
                    break
                p, n, q, sl = fit
                nd = n @ dd
                if abs(nd) < 1e-3 * dn:
                    break
                g = n @ (p - (oo + t * dd)) / nd  # plane-ray intersection (Alg. 3.1, line 4)
                tn = t + g
                if abs(tn - t0) * dn > surf.support:
                    break
                if abs(g) * dn <= tol * sl:
                    conv, t = True, tn
                    break
                if g > 0:
                    if last == 1 and b is not None:
                        b = (b[0], b[1] / 2)  # Illinois
                    a, last = (t, g), 1
                else:
                    if last == 2 and a is not None:
                        a = (a[0], a[1] / 2)
                    b, last = (t, g), 2
                if bracket and a is not None and b is not None:
                    if abs(b[0] - a[0]) * dn <= tol * sl:
                        conv, t = True, tn
                        break
                    tn = (a[0] * b[1] - b[0] * a[1]) / (b[1] - a[1])  # regula falsi in the bracket
                    BRACKET_STEPS[0] += 1
                t = tn
            if conv and t > 0:
                if np.linalg.norm(q - (oo + t * dd)) < eps2 * sl:
                    t_out[i], hit[i] = t, True
                    break
            tlo = th[j] + rho[j] / dn
    return t_out, hit


def interpolate(surf: MLSSurface, x: np.ndarray, values: np.ndarray) -> np.ndarray:
    """MLS-weighted average of per-surfel ``values`` (N, k) at ``x`` (M, 3); nearest surfel where no kernel reaches."""
    c = surf.cloud
    out = np.empty((len(x), values.shape[1]))
    for i, xx in enumerate(x):
        w = _weights(((c.positions - xx) ** 2).sum(1), surf.sigmas, surf.cutoff, surf.kernel)
        if w.sum() > 0:
            out[i] = (w[:, None] * values).sum(0) / w.sum()
        else:
            out[i] = values[np.argmin(((c.positions - xx) ** 2).sum(1))]
    return out
