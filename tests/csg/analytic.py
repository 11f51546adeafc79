"""Exact reference for CSG tests: analytic half-spaces and spheres, their patches, and an exact
ray cast of the same CSG tree (first boundary point along each ray that lies on the surface)."""

from __future__ import annotations

import numpy as np

from unmesh.csg import Patch
from unmesh.shapes import Sphere


class Prim:
    """Analytic primitive: ``kind`` "H" (point, outward normal) or "S" (centre, radius)."""

    def __init__(self, kind, a, b, name, color=(0.8, 0.8, 0.8)):
        self.kind, self.a, self.b, self.name, self.color = kind, np.asarray(a, float), b, name, color
        if kind == "H":
            self.b = np.asarray(b, float) / np.linalg.norm(b)

    def value(self, x):  # negative inside
        if self.kind == "H":
            return (x - self.a) @ self.b
        return np.linalg.norm(x - self.a, axis=-1) - self.b

    def normal(self, x):
        if self.kind == "H":
            return np.broadcast_to(self.b, x.shape)
        d = x - self.a
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def hits(self, o, d):  # (P, 2) ray parameters of boundary crossings (nan if none)
        if self.kind == "H":
            dn = d @ self.b
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((self.a - o) @ self.b) / dn
            return np.stack([t, np.full_like(t, np.nan)], axis=1)
        oc = o - self.a
        bq = np.einsum("ij,ij->i", oc, d)
        c = np.einsum("ij,ij->i", oc, oc) - self.b ** 2
        disc = bq * bq - c
        s = np.sqrt(np.where(disc >= 0, disc, np.nan))
        return np.stack([-bq - s, -bq + s], axis=1)

    def patch(self, spacing, extent=4.0):
        if self.kind == "H":
            return Patch.halfspace(self.a, self.b, extent, spacing, color=self.color, name=self.name)
        return Patch(Sphere(radius=self.b, center=self.a).surfels(spacing, color=self.color), name=self.name)


def evaluate(tree, fn):
    """Map an expression tree (Prim | ("|", a, b) | ("&", a, b) | ("-", a, b) | ("~", a)) with
    ``fn`` on leaves and Python operators on nodes."""
    if isinstance(tree, Prim):
        return fn(tree)
    op = tree[0]
    args = [evaluate(t, fn) for t in tree[1:]]
    if op == "|":
        return args[0] | args[1]
    if op == "&":
        return args[0] & args[1]
    if op == "-":
        return args[0] & ~args[1] if isinstance(args[0], np.ndarray) else args[0] - args[1]
    return ~args[0]


def prims(tree):
    if isinstance(tree, Prim):
        return [tree]
    return [p for t in tree[1:] for p in prims(t)]


def raycast(tree, camera):
    """Exact CSG ray cast: (H, W) depth (inf = miss), (H, W, 3) normal, (H, W) index of the hit primitive."""
    o, d = camera.rays()
    o = o.reshape(-1, 3)
    d = d.reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    ps = prims(tree)
    ts = np.concatenate([p.hits(o, d) for p in ps], axis=1)
    owner = np.repeat(np.arange(len(ps)), 2)
    ts = np.where(ts > 1e-9, ts, np.nan)
    order = np.argsort(np.where(np.isnan(ts), np.inf, ts), axis=1)
    best = np.full(len(o), np.inf)
    who = np.full(len(o), -1)
    eps = 1e-7
    for k in range(ts.shape[1]):
        t = np.take_along_axis(ts, order[:, k:k + 1], axis=1)[:, 0]
        ok = np.isfinite(t) & ~np.isfinite(best)
        if not ok.any():
            continue
        x0 = o + (t - eps)[:, None] * d
        x1 = o + (t + eps)[:, None] * d
        in0 = evaluate(tree, lambda p, x=x0: p.value(x) < 0)
        in1 = evaluate(tree, lambda p, x=x1: p.value(x) < 0)
        hit = ok & ~in0 & in1
        best[hit] = t[hit]
        who[hit] = owner[order[hit, k]]
    x = o + np.where(np.isfinite(best), best, 0)[:, None] * d
    normal = np.zeros_like(x)
    for i, p in enumerate(ps):
        m = who == i
        if m.any():
            nn = p.normal(x[m])
            flip = np.einsum("ij,ij->i", nn, d[m]) > 0
            normal[m] = np.where(flip[:, None], -nn, nn)
    fwd = camera.rotation[2]
    depth = np.where(np.isfinite(best), best * (d @ fwd), np.inf)
    h, w = camera.shape
    return depth.reshape(h, w), normal.reshape(h, w, 3), who.reshape(h, w)
