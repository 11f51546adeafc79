"""Ray casting of MLS surfaces for high-quality stills (thesis 3.1.3, Algorithm 3.1).

Rays through the pixel centres are intersected with the MLS surface of the surfel cloud by
:func:`unmesh.mls.intersect` (which also returns the MLS normals). Rays that cannot hit are
skipped: a pixel is cast only when the splatted surfel discs (no screen filter) cover a pixel
within ``margin`` pixels of it. The colour at a hit is the MLS-weighted average of the surfel
colours, ``c(x) = sum_i w_i(x) c_i / sum_i w_i(x)`` with the weights of the MLS surface
(3.10-3.12, :func:`unmesh.mls.interpolate`). The result goes
into the same G-buffer as every other renderer, so camera, shading and buffers are shared.

Example
-------
>>> import numpy as np
>>> from unmesh import SurfelCloud
>>> from unmesh.render import Camera
>>> g = np.stack(np.meshgrid(np.arange(-10, 11), np.arange(-10, 11)), -1).reshape(-1, 2) * 0.1
>>> plane = SurfelCloud(np.c_[g, np.zeros(len(g))], np.tile([0, 0, 1.0], (len(g), 1)), radii=np.full(len(g), 0.1))
>>> buf = GBuffer.empty(8, 8)
>>> draw_mls(buf, [plane], Camera((0, 0, 2), (0, 0, 0), width=8, height=8, ortho=1.0))
>>> bool(buf.coverage.all()), round(float(buf.depth[4, 4]), 6)
(True, 2.0)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.render.camera import Camera
from unmesh.render.shading import GBuffer
from unmesh.render.splat import SplatOptions, SplatRenderer
from unmesh.surfels import SurfelCloud

__all__ = ["draw_mls"]


def draw_mls(gbuffer: GBuffer, clouds: Sequence[SurfelCloud], camera: Camera, colors: np.ndarray | None = None,
             mls_options: Mapping[str, Any] | None = None, margin: int = 3, progress: bool = False) -> None:
    """Ray-cast the MLS surface of ``clouds`` into ``gbuffer`` (in place, z-buffered).

    Parameters
    ----------
    gbuffer : GBuffer
    clouds : sequence of SurfelCloud
        Treated as one MLS surface (joined by :meth:`SurfelCloud.concatenate`; attributes are
        not used).
    camera : Camera
    colors : (N, 3) array, optional
        Colour override for the concatenated surfels (e.g. an attribute through a colormap).
    mls_options : mapping, optional
        Options of :class:`unmesh.mls.MLSSurface` (``sigma_factor``, ``kernel``, ``degree``...)
        and of :func:`unmesh.mls.intersect` (``eps2``, ``max_iter``...).
    margin : int
        Pixels around the splatted discs that are also cast.
    progress : bool
        Show :func:`unmesh.mls.intersect`'s progress bar.
    """
    from unmesh.mls import MLSSurface, interpolate, intersect
    from unmesh.mls.surface import SURFACE_OPTIONS

    items = [c for c in clouds if len(c)]
    for i, c in enumerate(items):
        if not isinstance(c, SurfelCloud):
            raise InputError(f"clouds[{i}]: expected a SurfelCloud, got {type(c).__name__}")
    if not items:
        return
    cloud = SurfelCloud.concatenate(items, attributes="none")
    colors = cloud.colors if colors is None else np.ascontiguousarray(colors, dtype=np.float64)
    if colors.shape != cloud.colors.shape:
        raise InputError(f"colors: expected shape {cloud.colors.shape}, got {colors.shape}")
    opts = dict(mls_options or {})
    surf_keys = set(SURFACE_OPTIONS)
    surface = MLSSurface(cloud, **{k: v for k, v in opts.items() if k in surf_keys})
    cast_opts = {k: v for k, v in opts.items() if k not in surf_keys}
    # which pixels can see the surface: splatted discs (no screen filter), dilated
    probe = SplatRenderer(camera, SplatOptions(filter_radius=0.0, precision="double")).render(cloud)
    mask = probe.count > 0
    if margin > 0 and mask.any():
        from scipy.ndimage import binary_dilation

        mask = binary_dilation(mask, iterations=int(margin))
    rows, cols = np.nonzero(mask)
    if len(rows) == 0:
        return
    origins, dirs = camera.rays()
    o = origins[rows, cols]
    d = dirs[rows, cols]
    t, hit, nrm = intersect(surface, o, d, return_normals=True, progress=progress, **cast_opts)
    if not np.any(hit):
        return
    rows, cols, t, nrm, d, o = rows[hit], cols[hit], t[hit], nrm[hit], d[hit], o[hit]
    z = t * (d @ camera.forward)
    keep = (z > camera.near_distance) & (z < gbuffer.depth[rows, cols])
    rows, cols, z, nrm, t, d, o = rows[keep], cols[keep], z[keep], nrm[keep], t[keep], d[keep], o[keep]
    pts = o + t[:, None] * d
    gbuffer.depth[rows, cols] = z
    gbuffer.normal[rows, cols] = nrm
    gbuffer.albedo[rows, cols] = np.clip(interpolate(surface, pts, colors), 0.0, 1.0)
    gbuffer.coverage[rows, cols] = True
    gbuffer.weight[rows, cols] = 1.0
