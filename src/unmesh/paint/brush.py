"""The brush (thesis 5.4): a mass-spring skeleton with a surfel surface skinned to it.

Handle points are rigidly attached to the handle, which follows the pen pose; active masses
are integrated by Verlet. Springs follow (5.1) ``F = K_s (l - l_0) (x_0 - x_1)/l``. Active masses
that end up inside the object are projected out along the force-shading direction (5.5) and
slowed by friction; handle points inside give the penalty force ``K_p d N`` (5.6) and the
friction force ``-eta d v_t`` (5.7) that the haptic loop displays. A brush with several active
masses is *split* when the surface normals at its colliding masses differ by more than 60
degrees (5.4.3); each tip then gets its own paint buffer (5.5.1). The flat brush's body is one
cap of surfels per active mass (a bundle of bristles); the faces of a bundle that face a
neighbouring bundle are the brush's *internal surfaces*: they take no part in paint transfer
while the brush is whole and are activated when it splits (5.4.3), each with its own tip.

Brush frame: the tip mass at the origin, the handle along +z. Bristles are ``3 * size`` long.
The bristle body hangs ``c`` below each active mass (``c`` = the body's lower semi-axis), so a
mass projected onto the surface leaves the body penetrating it: that interpenetration is where
paint is exchanged (5.5).

Example
-------
>>> from unmesh.paint.strokes import Brush
>>> sk = skeleton(Brush("flat", 0.02))
>>> sk.active.shape, sk.handles.shape
((3, 3), (6, 3))
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from unmesh.paint._brush_kernels import spring_forces
from unmesh.paint.collide import BallKnn, collide
from unmesh.paint.strokes import Brush
from unmesh.spatial import KDTree

__all__ = ["SPLIT_ANGLE", "BrushState", "Skeleton", "cross3", "skeleton"]

#: Splitting threshold of 5.4.3 (degrees between collision normals of the active masses).
SPLIT_ANGLE = 60.0
#: Penalty stiffness K_p of (5.6) (force per unit depth) and Verlet velocity retention.
K_PENALTY = 200.0
DAMPING = 0.8
#: A bundle's surfels whose normals are within 45 degrees of the direction to a neighbouring
#: active mass form the brush's internal surfaces (5.4.3).
INTERNAL_COS = float(np.cos(np.radians(45.0)))
#: Paint a loaded brush surfel holds, in layers of the paint's thickness.
RESERVOIR = 25.0


@dataclass(frozen=True)
class Skeleton:
    """Rest geometry of a brush in its frame (tip at the origin, handle along +z).

    Attributes
    ----------
    active : (A, 3) float64
        Rest positions of the active masses.
    handles : (H, 3) float64
        Handle points.
    springs : (S, 2) int64
        Spring end points, indices into ``concat(active, handles)``.
    rest : (S,) float64
        Rest lengths.
    body : (B, 3) float64
        Brush surfels (rest), ``owner`` (B,) the active mass each is skinned to, ``weight`` (B,)
        its skinning weight to that mass (1 at the tip, 0 at the ferrule), ``bnormal`` (B, 3).
    internal : (B,) bool
        Surfels of a bundle facing a neighbouring active mass (the internal surfaces of 5.4.3).
    lower : float
        Lower semi-axis ``c`` of the body below each active mass.
    spacing : float
        Brush surfel spacing (the paint-buffer pixel size, 5.5).
    """

    active: np.ndarray
    handles: np.ndarray
    springs: np.ndarray
    rest: np.ndarray
    body: np.ndarray
    bnormal: np.ndarray
    owner: np.ndarray
    weight: np.ndarray
    internal: np.ndarray
    lower: float
    spacing: float


def _cap(center: np.ndarray, ax: float, ay: float, c: float, h: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Surfels on the lower half-ellipsoid (ax, ay, c) at ``center`` plus a tapered sleeve up to height h."""
    pts, nrm = [], []
    # lower half-ellipsoid: rings of latitude
    nlat = max(4, int(np.ceil(0.5 * np.pi * max(ax, ay) / spacing)))
    for i in range(nlat + 1):
        th = 0.5 * np.pi * i / nlat  # 0 at the bottom pole
        rr = np.sin(th)
        m = max(1, int(np.ceil(2 * np.pi * rr * max(ax, ay) / spacing)))
        ph = 2 * np.pi * (np.arange(m) + 0.5 * (i % 2)) / m
        p = np.stack([ax * rr * np.cos(ph), ay * rr * np.sin(ph), np.full(m, -c * np.cos(th))], axis=1)
        g = np.stack([p[:, 0] / ax ** 2, p[:, 1] / ay ** 2, p[:, 2] / c ** 2], axis=1)
        pts.append(p)
        nrm.append(g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300))
    # sleeve: ellipse rings tapering to 40 % at the ferrule
    nz = max(2, int(np.ceil(h / spacing)))
    for j in range(1, nz + 1):
        z = h * j / nz
        s = 1.0 - 0.6 * z / h
        m = max(4, int(np.ceil(2 * np.pi * s * max(ax, ay) / spacing)))
        ph = 2 * np.pi * (np.arange(m) + 0.5 * (j % 2)) / m
        p = np.stack([s * ax * np.cos(ph), s * ay * np.sin(ph), np.full(m, z)], axis=1)
        g = np.stack([np.cos(ph) / ax, np.sin(ph) / ay, np.zeros(m)], axis=1)
        pts.append(p)
        nrm.append(g / np.linalg.norm(g, axis=1, keepdims=True))
    return np.concatenate(pts) + center, np.concatenate(nrm)


def skeleton(brush: Brush) -> Skeleton:
    """The rest skeleton and surfel body of a brush (Fig. 5.3)."""
    s = brush.size
    L = 3.0 * s
    hz = 0.6 * L
    if brush.type == "flat":
        active = np.array([[-s, 0, 0], [0, 0, 0], [s, 0, 0]], float)
        t = 0.5 * s
        handles = np.array([[x, y, hz] for x in (-s, 0.0, s) for y in (-t, t)], float)
        springs = [(a, 3 + 2 * a + k) for a in range(3) for k in range(2)]
        springs += [(0, 1), (1, 2), (0, 3 + 2), (1, 3 + 0), (1, 3 + 4), (2, 3 + 2)]
        lower, ax, ay = 0.25 * s, 0.5 * s, 0.25 * s
    else:
        r = s if brush.type == "round" else 1.2 * s
        active = np.zeros((1, 3))
        handles = np.array([[r, 0, hz], [-r, 0, hz], [0, r, hz], [0, -r, hz]], float)
        springs = [(0, 1 + k) for k in range(4)]
        if brush.type == "round":
            lower, ax, ay = 0.4 * s, s, s
        else:
            lower, ax, ay = 0.3 * s, 0.5 * s, 0.5 * s
    springs = np.asarray(springs, dtype=np.int64)
    allp = np.concatenate([active, handles])
    rest = np.linalg.norm(allp[springs[:, 0]] - allp[springs[:, 1]], axis=1)
    spacing = min(ax, ay) / 5.0 if brush.type != "flat" else s / 8.0
    bodies, normals, owner, weight = [], [], [], []
    for a, m in enumerate(active):
        p, nn = _cap(m, ax, ay, lower, hz * 0.9, spacing)
        bodies.append(p)
        normals.append(nn)
        owner.append(np.full(len(p), a, np.int64))
        weight.append(np.clip(1.0 - (p[:, 2] - m[2]) / hz, 0.0, 1.0))
    body, own, bnormal = np.concatenate(bodies), np.concatenate(owner), np.concatenate(normals)
    # internal surfaces: the faces of a mass's bundle that face a neighbouring mass (within 45 degrees)
    internal = np.zeros(len(body), bool)
    for a, b in springs[(springs[:, 0] < len(active)) & (springs[:, 1] < len(active))]:
        ab = (active[b] - active[a]) / np.linalg.norm(active[b] - active[a])
        internal |= (own == a) & (bnormal @ ab > INTERNAL_COS)
        internal |= (own == b) & (bnormal @ -ab > INTERNAL_COS)
    return Skeleton(active, handles, springs, rest, body, bnormal, own, np.concatenate(weight), internal,
                    float(lower), float(spacing))


def spring_forces_reference(x: np.ndarray, h: np.ndarray, springs: np.ndarray, rest: np.ndarray,
                            stiffness: float) -> np.ndarray:
    """Plain reference of :func:`unmesh.paint._brush_kernels.spring_forces`, (A + H, 3)."""
    allp = np.concatenate([x, h])
    i, j = springs[:, 0], springs[:, 1]
    dv = allp[j] - allp[i]
    ln = np.maximum(np.linalg.norm(dv, axis=1), 1e-300)
    f = (stiffness * (ln - rest) / ln)[:, None] * dv  # on i, towards j when stretched
    out = np.zeros_like(allp)
    np.add.at(out, i, f)
    np.add.at(out, j, -f)
    return out


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, (3,) float64: the same products and differences (so the
    same bits) without its per-call cost (about 10x).

    Example
    -------
    >>> cross3(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])).tolist()
    [0.0, 0.0, 1.0]
    """
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], dtype=np.float64)


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation matrix taking unit ``a`` to unit ``b`` (Rodrigues)."""
    v = cross3(a, b)
    c = float(np.dot(a, b))
    if c < -1 + 1e-12:
        h = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
        u = cross3(a, h)
        u /= np.linalg.norm(u)
        return 2 * np.outer(u, u) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


class BrushState:
    """A brush in the world: handle pose, active masses, contact and paint on its surfels.

    Parameters
    ----------
    brush : Brush

    Attributes
    ----------
    x, x_prev : (A, 3) float64
        Active masses (Verlet state).
    rotation : (3, 3), origin : (3,)
        Handle pose (brush frame to world).
    wet, vw : (B, 3), (B,) float64
        Paint on the brush surfels (wet colour and volume; brush paint does not dry, 5.6.1).
    split : bool
        Whether the brush is split (5.4.3).
    ball : BallKnn or None
        The originals near the brush fetched by the last :meth:`simulate` (exact k-nearest
        queries there, for the paint event that follows).
    """

    def __init__(self, brush: Brush) -> None:
        self.brush = brush
        self.sk = skeleton(brush)
        nb = len(self.sk.body)
        self.wet = np.zeros((nb, 3))
        self.vw = np.zeros(nb)
        self.rotation = np.eye(3)
        self.origin = np.zeros(3)
        self.x = self.sk.active.copy()
        self.x_prev = self.x.copy()
        self.placed = False
        self.split = False
        self.contact_normals = np.zeros((len(self.x), 3))
        self.colliding = np.zeros(len(self.x), bool)
        self.handle_depth = np.zeros(len(self.sk.handles))
        self.handle_normal = np.zeros((len(self.sk.handles), 3))
        self.handle_velocity = np.zeros(3)
        self.spring_reaction = np.zeros(3)
        self.ball: BallKnn | None = None

    def load(self, color: tuple[float, float, float], thickness: float) -> None:
        """Dip the brush: every surfel carries ``RESERVOIR * thickness * spacing^2`` of paint of
        ``color`` (the bristles hold many layers)."""
        self.wet[:] = color
        self.vw[:] = RESERVOIR * thickness * self.sk.spacing ** 2

    def handles_world(self) -> np.ndarray:
        return self.sk.handles @ self.rotation.T + self.origin

    def volume(self) -> float:
        return float(self.vw.sum())

    def pose(self, origin: np.ndarray, rotation: np.ndarray) -> None:
        """Place the handle; the first call puts the active masses at their rest positions."""
        if not self.placed:
            self.x = self.sk.active @ rotation.T + origin
            self.x_prev = self.x.copy()
            self.placed = True
        self.handle_velocity = origin - self.origin
        self.origin = np.asarray(origin, float)
        self.rotation = np.asarray(rotation, float)

    def _forces(self, x: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Spring forces (5.1) on the active masses (A,3) and their sum on the handle (3,)."""
        out = np.empty((len(x) + len(h), 3))
        spring_forces(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(h, dtype=np.float64),
                      self.sk.springs, self.sk.rest, float(self.brush.stiffness), out)
        na = len(x)
        return out[:na], out[na:].sum(axis=0)

    def simulate(self, tree: KDTree, positions: np.ndarray, normals: np.ndarray, origin: np.ndarray,
                 rotation: np.ndarray, steps: int = 12) -> None:
        """Move the handle to the new pose over ``steps`` Verlet steps (dt = 1, mass 1) with
        collision projection (5.5) and friction of the active masses, then evaluate the
        contact state of handle points (5.6/5.7) and the split test (5.4.3)."""
        o0, r0 = self.origin.copy(), self.rotation.copy()
        first = not self.placed
        self.pose(origin, rotation)
        if first:
            o0, r0 = self.origin, self.rotation
        eta = self.brush.friction
        # the originals the active masses can meet during these steps, fetched once (exact: the
        # queries that could reach past them go to the tree)
        reach = float(np.linalg.norm(self.origin - o0)) + float(np.abs(self.sk.active).max()) + self.brush.size
        near = BallKnn(tree, self.x.mean(axis=0), reach) if isinstance(tree, KDTree) else tree
        self.ball = near if isinstance(near, BallKnn) else None
        for s in range(1, steps + 1):
            a = s / steps
            o = (1 - a) * o0 + a * self.origin
            h = self.sk.handles @ ((1 - a) * r0 + a * self.rotation).T + o
            f, _ = self._forces(self.x, h)
            xn = self.x + DAMPING * (self.x - self.x_prev) + f
            inside, d, n = collide(near, positions, normals, xn)
            prev = self.x.copy()
            if inside.any():
                xn[inside] += d[inside, None] * n[inside]
                # friction (5.7) on the tangential motion of the colliding masses
                v = xn[inside] - self.x[inside]
                vt = v - np.einsum("mi,mi->m", v, n[inside])[:, None] * n[inside]
                xn[inside] -= eta * vt
                # inelastic contact: the projection leaves no normal velocity (Verlet keeps
                # velocity as x - x_prev, so the projected jump must not carry on)
                prev[inside] = xn[inside] - (1.0 - eta) * vt
            self.x_prev = prev
            self.x = xn
            self.colliding = inside
            self.contact_normals = n
        h = self.handles_world()
        f, reaction = self._forces(self.x, h)
        self.spring_reaction = reaction
        inside, d, n = collide(tree, positions, normals, h)
        self.handle_depth = np.where(inside, d, 0.0)
        self.handle_normal = n
        self.split = self.is_split()

    def is_split(self) -> bool:
        """5.4.3: colliding active masses whose normals differ by more than 60 degrees."""
        idx = np.flatnonzero(self.colliding)
        if len(idx) < 2:
            return False
        nn = self.contact_normals[idx]
        cosines = nn @ nn.T
        return bool(cosines.min() < np.cos(np.radians(SPLIT_ANGLE)))

    def transfer_body(self, tip: int | None = None) -> np.ndarray:
        """Indices of the brush surfels that exchange paint (5.4.3, 5.5.1), (K,) int64.

        The whole brush (``tip`` None): every surfel but the internal surfaces. Tip ``tip`` of a
        split brush: the surfels skinned to that active mass, its internal surfaces included.
        """
        if tip is None:
            return np.flatnonzero(~self.sk.internal)
        return np.flatnonzero(self.sk.owner == tip)

    def penalty(self) -> np.ndarray:
        """Penalty (5.6) plus friction (5.7) on the handle points, (3,)."""
        d = self.handle_depth
        n = self.handle_normal
        fp = K_PENALTY * (d[:, None] * n).sum(axis=0)
        v = self.handle_velocity
        ft = np.zeros(3)
        for k in np.flatnonzero(d > 0):
            vt = v - np.dot(v, n[k]) * n[k]
            ft -= self.brush.friction * d[k] * vt
        return fp + ft

    def surfels(self) -> tuple[np.ndarray, np.ndarray]:
        """Brush surfels in the world by linear blend skinning of the rigid handle transform and
        each active mass's bone transform (rest bone: mass -> ferrule), (B,3) positions and normals."""
        sk = self.sk
        R, o = self.rotation, self.origin
        rigid = sk.body @ R.T + o
        rn = sk.bnormal @ R.T
        out = rigid.copy()
        nout = rn.copy()
        ferrule = np.array([0.0, 0.0, 0.6 * 3.0 * self.brush.size])
        for a in range(len(sk.active)):
            sel = sk.owner == a
            top = (sk.active[a] + ferrule) @ R.T + o
            rest_dir = R @ ferrule / np.linalg.norm(ferrule)
            cur = top - self.x[a]
            ln = np.linalg.norm(cur)
            if ln < 1e-12:
                continue
            Q = _rotation_between(rest_dir, cur / ln) @ R
            bone = (sk.body[sel] - sk.active[a]) @ Q.T + self.x[a]
            w = sk.weight[sel][:, None]
            out[sel] = w * bone + (1 - w) * rigid[sel]
            bn = w * (sk.bnormal[sel] @ Q.T) + (1 - w) * rn[sel]
            nout[sel] = bn / np.maximum(np.linalg.norm(bn, axis=1, keepdims=True), 1e-300)
        return out, nout
