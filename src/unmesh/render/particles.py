"""Particles drawn as ray-cast shaded spheres (or flat camera-facing discs) into the G-buffer.

Radii come from :attr:`unmesh.Particles.radii`, an explicit ``radius``, or half the median
nearest-neighbour distance (:func:`estimate_radius`). Spheres are exact per pixel (depth and
normal of the ray-sphere hit); a sphere smaller than a pixel still covers the pixels within the
screen filter radius of its projected centre, so distant particles never vanish.

Example
-------
>>> from unmesh import Particles
>>> from unmesh.render import Camera
>>> p = Particles([[0.0, 0.0, 0.0]], radii=[0.5])
>>> g = GBuffer.empty(16, 16)
>>> draw_particles(g, [p], Camera((0, 0, 3), (0, 0, 0), width=16, height=16, ortho=2.0))
>>> bool(g.coverage[8, 8]), round(float(g.depth[8, 8]), 3)  # sphere front at z = 2.5
(True, 2.508)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from unmesh._validate import positive_scalar
from unmesh.errors import InputError
from unmesh.particles import Particles
from unmesh.render._kernels import SERIAL_BELOW, bin_boxes, box_visits, serial_if_small, tile_order
from unmesh.render._raster_kernels import sphere_setup, sphere_tiles
from unmesh.render.camera import Camera
from unmesh.render.shading import GBuffer

__all__ = ["DEFAULT_PARTICLE_COLOR", "OBJECT_PALETTE", "draw_particles", "estimate_radius", "particle_colors",
           "particle_radii"]

#: Colour of particles without colour data or ``color_by`` (a water blue).
DEFAULT_PARTICLE_COLOR = (0.22, 0.52, 0.85)
#: Colours of particles by their integer ``object`` attribute (id modulo 8); id 0 is the default blue.
OBJECT_PALETTE = np.array([DEFAULT_PARTICLE_COLOR, (0.93, 0.55, 0.18), (0.35, 0.70, 0.35), (0.84, 0.30, 0.32),
                           (0.58, 0.45, 0.78), (0.60, 0.42, 0.34), (0.88, 0.55, 0.75), (0.55, 0.55, 0.55)])
_TILE = 32


def estimate_radius(points: np.ndarray, sample: int = 2000) -> float:
    """Half the median nearest-neighbour distance of up to ``sample`` evenly chosen points.

    Uses :func:`unmesh.spatial.knn`. Fewer than two distinct points give ``0.01`` times the
    bounding-box diagonal (or 0.05 for a single point).

    Example
    -------
    >>> estimate_radius(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]))
    0.5
    """
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n < 2:
        return 0.05
    from unmesh.spatial import knn

    step = max(1, n // sample)
    dist, _ = knn(pts, 2, queries=pts[::step])
    d = dist[:, 1]
    d = d[np.isfinite(d) & (d > 0)]
    if d.size == 0:
        diag = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        return 0.01 * diag if diag > 0 else 0.05
    return 0.5 * float(np.median(d))


def particle_radii(particles: Particles, radius: float | None = None) -> np.ndarray:
    """Drawing radii (N,): ``radius`` if given, else ``particles.radii``, else :func:`estimate_radius`.

    Example
    -------
    >>> particle_radii(Particles([[0, 0, 0], [0.2, 0, 0]])).tolist()
    [0.1, 0.1]
    """
    n = len(particles)
    if radius is not None:
        return np.full(n, positive_scalar(radius, "particle_radius"))
    if particles.radii is not None:
        return particles.radii
    return np.full(n, estimate_radius(particles.positions))


def particle_colors(particles: Particles) -> np.ndarray:
    """Colours (N,3) stored with the particles (``colors`` (N,3) or ``red/green/blue``
    attributes, 0-1 or 0-255), else by an integer ``object`` attribute (simulation object ids,
    :data:`OBJECT_PALETTE`), else :data:`DEFAULT_PARTICLE_COLOR`.

    Example
    -------
    >>> p = Particles([[0, 0, 0], [1, 0, 0]], attributes={"object": [0, 1]})
    >>> particle_colors(p)[1].tolist()
    [0.93, 0.55, 0.18]
    """
    a = particles.attributes
    n = len(particles)
    col = None
    if "colors" in a and np.shape(a["colors"]) == (n, 3):
        col = np.asarray(a["colors"], dtype=np.float64)
    elif all(k in a for k in ("red", "green", "blue")):
        col = np.stack([np.asarray(a[k], dtype=np.float64) for k in ("red", "green", "blue")], axis=1)
    if col is None:
        obj = a.get("object")
        if obj is not None and np.ndim(obj) == 1 and np.issubdtype(np.asarray(obj).dtype, np.number):
            ids = np.asarray(obj)
            if np.all(np.isfinite(ids)):
                return OBJECT_PALETTE[np.mod(np.rint(ids).astype(np.int64), len(OBJECT_PALETTE))].copy()
        return np.tile(np.asarray(DEFAULT_PARTICLE_COLOR), (n, 1))
    if col.size and col.max() > 1.0:
        col = col / 255.0
    return np.clip(col, 0.0, 1.0)


def draw_particles(gbuffer: GBuffer, particles: Sequence[Particles], camera: Camera,
                   colors: Sequence[np.ndarray | None] | None = None, radius: float | None = None,
                   style: str = "sphere", filter_radius: float = 1.0,
                   radii: Sequence[np.ndarray | None] | None = None) -> None:
    """Draw particle sets into ``gbuffer`` (in place, z-buffered against its depth).

    Parameters
    ----------
    gbuffer : GBuffer
    particles : sequence of Particles
    camera : Camera
    colors : sequence of (N, 3) arrays or None, optional
        Colour per particle set (e.g. an attribute through a colormap); default
        :func:`particle_colors`.
    radius : float, optional
        One drawing radius for all particles (overrides stored radii).
    style : {"sphere", "disc"}
        Shaded spheres or flat discs facing the camera.
    filter_radius : float
        Pixels around the projected centre that always see the particle.
    radii : sequence of (N,) arrays or None, optional
        Precomputed radii per set (e.g. fixed over an animation).

    Example
    -------
    >>> from unmesh.render import Camera
    >>> g = GBuffer.empty(8, 8)
    >>> draw_particles(g, [Particles([[0, 0, 0]], radii=[0.3])], Camera((0, 0, 3), (0, 0, 0), width=8, height=8),
    ...                style="disc")
    >>> float(g.depth[4, 4])
    3.0
    """
    if style not in ("sphere", "disc"):
        raise InputError(f"particle_style: expected 'sphere' or 'disc', got {style!r}")
    h, w = camera.shape
    f, cx, cy, ortho, near = camera.kernel_params()
    frame = camera.rotation
    for pi, p in enumerate(particles):
        if not isinstance(p, Particles):
            raise InputError(f"particles[{pi}]: expected Particles, got {type(p).__name__}")
        n = len(p)
        if n == 0:
            continue
        rad = radii[pi] if radii is not None and radii[pi] is not None else particle_radii(p, radius)
        rad = np.ascontiguousarray(rad, dtype=np.float64)
        col = colors[pi] if colors is not None and colors[pi] is not None else particle_colors(p)
        S = np.empty((n, 8))
        box = np.empty((n, 4), dtype=np.int32)
        with serial_if_small(len(box)):
            sphere_setup(p.positions, rad, frame, camera.eye, f, cx, cy, ortho, near, w, h, filter_radius, S, box)
            ntx = (w + _TILE - 1) // _TILE
            nty = (h + _TILE - 1) // _TILE
            offsets, items = bin_boxes(box, np.zeros(n, dtype=np.int8), 1, _TILE, ntx, nty, 8)
        with serial_if_small(box_visits(box), 20 * SERIAL_BELOW):
            sphere_tiles(S, box, items, offsets, tile_order(ntx * nty), _TILE, w, h, f, cx, cy, ortho, near,
                         filter_radius, style == "disc", np.ascontiguousarray(col, dtype=np.float64), frame,
                         gbuffer.depth, gbuffer.albedo, gbuffer.normal, gbuffer.coverage, gbuffer.weight)
