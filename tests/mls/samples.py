"""Analytic near-uniform surfel samplings of a sphere and a torus, with exact geometry."""

from __future__ import annotations

import numpy as np

from unmesh.surfels import SurfelCloud

GOLDEN = np.pi * (3.0 - np.sqrt(5.0))
#: Sample spacing of the accuracy tests (issue: "sampled with spacing 0.02").
H = 0.02
#: Surfel radius in units of the spacing: the hole-free covering radius of a hexagonal
#: sampling (1/sqrt(3) = 0.577) with a margin, like the radii of unmesh's samplers.
RADIUS_FACTOR = 0.65


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees between unit row vectors."""
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))


def sphere_cloud(spacing: float, radius: float = 1.0, center=(0.0, 0.0, 0.0)) -> SurfelCloud:
    """Fibonacci sphere with hexagonal-like spacing ``spacing``; surfel radius = RADIUS_FACTOR·spacing."""
    area = 4 * np.pi * radius**2
    n = int(np.rint(2 * area / (np.sqrt(3) * spacing**2)))
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    rr = np.sqrt(1 - z * z)
    phi = GOLDEN * i
    nrm = np.stack([rr * np.cos(phi), rr * np.sin(phi), z], axis=1)
    return SurfelCloud(nrm * radius + np.asarray(center), nrm, radii=np.full(n, RADIUS_FACTOR * spacing))


def sphere_distance(x: np.ndarray, radius: float = 1.0) -> np.ndarray:
    """Signed distance to the sphere (negative inside)."""
    return np.linalg.norm(x, axis=1) - radius


def sphere_normal(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def torus_cloud(spacing: float, R: float = 1.0, r: float = 0.35) -> SurfelCloud:
    """Torus around the z axis: rings of constant tube angle phi, hexagonally staggered."""
    dphi = spacing * np.sqrt(3) / 2 / r
    nphi = int(np.rint(2 * np.pi / dphi))
    pos, nrm = [], []
    for a in range(nphi):
        phi = 2 * np.pi * a / nphi
        rho = R + r * np.cos(phi)
        nth = int(np.rint(2 * np.pi * rho / spacing))
        th = 2 * np.pi * (np.arange(nth) + 0.5 * (a % 2)) / nth
        n = np.stack([np.cos(phi) * np.cos(th), np.cos(phi) * np.sin(th), np.full(nth, np.sin(phi))], axis=1)
        p = np.stack([rho * np.cos(th), rho * np.sin(th), np.full(nth, r * np.sin(phi))], axis=1)
        pos.append(p)
        nrm.append(n)
    pos = np.concatenate(pos)
    return SurfelCloud(pos, np.concatenate(nrm), radii=np.full(len(pos), RADIUS_FACTOR * spacing))


def torus_distance(x: np.ndarray, R: float = 1.0, r: float = 0.35) -> np.ndarray:
    """Signed distance to the torus (negative inside)."""
    rho = np.hypot(x[:, 0], x[:, 1])
    return np.hypot(rho - R, x[:, 2]) - r


def torus_normal(x: np.ndarray, R: float = 1.0) -> np.ndarray:
    rho = np.hypot(x[:, 0], x[:, 1])
    c = np.stack([R * x[:, 0] / rho, R * x[:, 1] / rho, np.zeros(len(x))], axis=1)
    v = x - c
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def torus_surface_points(n: int, rng: np.random.Generator, R: float = 1.0, r: float = 0.35):
    """Uniform random points on the torus surface (rejection sampling on the tube angle) and normals."""
    out = []
    while sum(len(o) for o in out) < n:
        th = rng.uniform(0, 2 * np.pi, 2 * n)
        phi = rng.uniform(0, 2 * np.pi, 2 * n)
        keep = rng.uniform(0, R + r, 2 * n) < R + r * np.cos(phi)
        out.append(np.stack([th[keep], phi[keep]], axis=1))
    tp = np.concatenate(out)[:n]
    th, phi = tp[:, 0], tp[:, 1]
    nrm = np.stack([np.cos(phi) * np.cos(th), np.cos(phi) * np.sin(th), np.sin(phi)], axis=1)
    rho = R + r * np.cos(phi)
    pts = np.stack([rho * np.cos(th), rho * np.sin(th), r * np.sin(phi)], axis=1)
    return pts, nrm


def sphere_surface_points(n: int, rng: np.random.Generator, radius: float = 1.0):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v * radius, v


def ray_sphere(o: np.ndarray, d: np.ndarray, radius: float = 1.0) -> np.ndarray:
    """First t > 0 of o + t d on the sphere; inf for misses."""
    a = np.einsum("ij,ij->i", d, d)
    b = 2 * np.einsum("ij,ij->i", o, d)
    c = np.einsum("ij,ij->i", o, o) - radius**2
    disc = b * b - 4 * a * c
    t = np.full(len(o), np.inf)
    ok = disc >= 0
    sq = np.sqrt(np.where(ok, disc, 0))
    t1 = (-b - sq) / (2 * a)
    t2 = (-b + sq) / (2 * a)
    t = np.where(ok & (t1 > 0), t1, np.where(ok & (t2 > 0), t2, np.inf))
    return t


def ray_torus(o: np.ndarray, d: np.ndarray, R: float = 1.0, r: float = 0.35) -> np.ndarray:
    """First t > 0 of o + t d on the torus (quartic roots, polished by Newton); inf for misses."""
    out = np.full(len(o), np.inf)
    for i in range(len(o)):
        oo, dd = o[i], d[i]
        # |p|^2 + R^2 - r^2 = 2R sqrt(px^2+py^2) squared -> quartic in t
        dd2 = dd @ dd
        od = oo @ dd
        oo2 = oo @ oo
        k = oo2 + R * R - r * r
        # (dd2 t^2 + 2 od t + k)^2 - 4 R^2 ((ox + t dx)^2 + (oy + t dy)^2) = 0
        a2 = dd[0] ** 2 + dd[1] ** 2
        b2 = 2 * (oo[0] * dd[0] + oo[1] * dd[1])
        c2 = oo[0] ** 2 + oo[1] ** 2
        poly = np.polysub(np.polymul([dd2, 2 * od, k], [dd2, 2 * od, k]), 4 * R * R * np.array([0, 0, a2, b2, c2]))
        roots = np.roots(poly)
        real = roots[np.abs(roots.imag) < 1e-6].real
        real = np.sort(real[real > 1e-9])
        for t in real:
            for _ in range(4):  # Newton polish on the signed distance
                p = oo + t * dd
                f = torus_distance(p[None], R, r)[0]
                g = torus_normal(p[None], R)[0] @ dd
                if abs(g) > 1e-12:
                    t -= f / g
            if abs(torus_distance((oo + t * dd)[None], R, r)[0]) < 1e-9 and t > 0:
                out[i] = t
                break
    return out


def varying_sphere_cloud(h0: float, ratio: float = 5.0, radius: float = 1.0) -> SurfelCloud:
    """Unit-sphere spiral whose spacing (and surfel radius) grows ``ratio``-fold from z = -1 to z = 1.

    Local spacing ``h(z) = h0·(1 + (ratio - 1)(z + 1)/2)``: the z of the samples follow the
    cumulative density ``∝ ∫ dz / h(z)²`` (hexagonal-like density ``2/(√3 h²)`` per area),
    longitudes the golden angle; radii ``RADIUS_FACTOR·h(z)``.
    """
    b = (ratio - 1.0) / 2.0
    a = 1.0 + b
    total = (1.0 - 1.0 / ratio) / b  # ∫_{-1}^{1} dz / (a + b z)²
    n = int(np.rint(2 * np.pi * 2 / (np.sqrt(3) * (h0 * radius) ** 2) * total))
    i = np.arange(n) + 0.5
    u = i / n * total
    z = (1.0 / (1.0 - b * u) - a) / b
    rr = np.sqrt(np.clip(1 - z * z, 0.0, None))
    phi = GOLDEN * i
    nrm = np.stack([rr * np.cos(phi), rr * np.sin(phi), z], axis=1)
    h = h0 * radius * (a + b * z)
    return SurfelCloud(nrm * radius, nrm, radii=RADIUS_FACTOR * h)
