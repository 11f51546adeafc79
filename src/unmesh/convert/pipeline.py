"""The conversion pipeline (chapter 6): surfels -> mesh -> patches -> atlas, with a report.

:func:`convert_cloud` runs the stages and returns the :class:`TexturedMesh` and a report
(counts, patch-size histogram, fill per page, errors per stage, uncovered triangles,
timings); :func:`to_textured_mesh` returns only the mesh.

Inputs without normals are not possible as :class:`~unmesh.surfels.SurfelCloud` (normals are
required); point files without normals get estimated normals when loaded
(:func:`unmesh.io.load_surfels`). Clouds that carry the default grey everywhere give a plain
texture (every patch stays at level 0).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from unmesh.convert.atlas import assemble, patch_corners, patch_masks
from unmesh.convert.fit import fit_vertices
from unmesh.convert.options import ConvertOptions
from unmesh.convert.packing import base_angles, fill_bound, pack
from unmesh.convert.patches import render_patches, triangle_frames
from unmesh.convert.reconstruct import MIN_POINTS, clean_mesh, reconstruct, reconstruct_poisson
from unmesh.convert.simplify import mesh_distance, simplify_mesh, simplify_to_error, topology
from unmesh.convert.textured import TexturedMesh
from unmesh.errors import InputError
from unmesh.meshes import TriangleMesh
from unmesh.mls import MLSSurface
from unmesh.surfels import SurfelCloud

__all__ = ["Conversion", "cloud_from_mesh", "convert_cloud", "to_textured_mesh"]


def cloud_from_mesh(mesh: TriangleMesh) -> SurfelCloud:
    """The vertices of a mesh (a scan) as surfels: vertex normals, estimated radii, vertex colours.

    Example
    -------
    >>> from unmesh.shapes import Sphere
    >>> c = cloud_from_mesh(Sphere().mesh(0.2))
    >>> bool((c.radii > 0).all())
    True
    """
    from unmesh.surfels import estimate_radii

    used = np.unique(mesh.faces)
    nrm = mesh.computed_vertex_normals()[used]
    pos = mesh.vertices[used]
    col = None if mesh.vertex_colors is None else mesh.vertex_colors[used]
    return SurfelCloud(pos, nrm, radii=estimate_radii(pos, nrm), colors=col)


@dataclass
class Conversion:
    """A textured mesh and the report of its conversion."""

    textured: TexturedMesh
    mesh: TriangleMesh
    report: dict[str, Any] = field(default_factory=dict)


def _check_cloud(cloud: Any) -> SurfelCloud:
    if not isinstance(cloud, SurfelCloud):
        raise InputError(f"cloud: expected a SurfelCloud, got {type(cloud).__name__}")
    cloud = cloud.visible()
    if len(cloud) < MIN_POINTS:
        raise InputError(f"cloud: expected at least {MIN_POINTS} surfels, got {len(cloud)}")
    if np.ptp(cloud.positions, axis=0).max() <= 0:
        raise InputError("cloud: expected surfels spanning a surface, got all at one point")
    return cloud


def convert_cloud(cloud: SurfelCloud, options: ConvertOptions | None = None) -> Conversion:
    """Convert a surfel cloud into a textured triangle mesh (thesis chapter 6).

    Parameters
    ----------
    cloud : SurfelCloud
        At least 20 surfels (NaN and inf are rejected by :class:`SurfelCloud` itself).
    options : ConvertOptions, optional

    Returns
    -------
    Conversion
        ``textured`` (:class:`TexturedMesh`), ``mesh`` (the simplified mesh) and ``report``.

    Raises
    ------
    unmesh.errors.InputError
        Too few surfels, no surface, or patches that do not fit ``page_size``.
    """
    opt = options if options is not None else ConvertOptions()
    if not isinstance(opt, ConvertOptions):
        raise InputError(f"options: expected ConvertOptions, got {type(opt).__name__}")
    cloud = _check_cloud(cloud)
    times: dict[str, float] = {}
    report: dict[str, Any] = {"points": len(cloud), "options": {k: getattr(opt, k) for k in opt.__dataclass_fields__}}
    diag = float(np.linalg.norm(np.ptp(cloud.positions, axis=0)))
    bar = _Stages(opt.progress)

    t0 = time.perf_counter()
    bar.stage("reconstruction")
    if opt.backend == "poisson":
        raw = reconstruct_poisson(cloud)
    else:
        raw = reconstruct(cloud, opt.grid_factor, MLSSurface(cloud))
    times["reconstruction"] = time.perf_counter() - t0
    topo = topology(raw)
    report["reconstruction"] = {"faces": len(raw.faces), "vertices": len(raw.vertices), "euler": topo[0],
                                "boundary_edges": topo[1], "manifold": topo[2], "backend": opt.backend}

    t0 = time.perf_counter()
    bar.stage("simplification")
    bound = opt.mesh_error * diag
    if opt.faces is not None:
        mesh = simplify_mesh(raw, opt.faces)
        err = max(mesh_distance(mesh, cloud))
        rec: dict[str, Any] = {"faces": len(mesh.faces), "error": err, "met": None, "tries": 1}
    else:
        mesh, rec = simplify_to_error(raw, cloud, bound)
    mesh = clean_mesh(mesh, min_component=1)
    rec = dict(rec)
    if opt.fit_mesh:
        mesh = fit_vertices(mesh, cloud)
        rec["error_before_fit"] = rec["error"]
        rec["error"] = max(mesh_distance(mesh, cloud))
    times["simplification"] = time.perf_counter() - t0
    rec["error_relative"] = rec["error"] / diag
    rec["bound_relative"] = opt.mesh_error if opt.faces is None else None
    rec["euler"] = topology(mesh)[0]
    report["simplification"] = rec

    t0 = time.perf_counter()
    bar.stage("texture patches")
    normal_error = opt.normal_error if opt.normal_map else None
    patches = render_patches(mesh, cloud, texture_error=opt.texture_error, normal_error=normal_error,
                             max_level=opt.max_level, progress=opt.progress, depth=opt.depth_map,
                             depth_error=opt.depth_error * diag)
    times["patches"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    bar.stage("packing")
    frames = triangle_frames(mesh)
    corners = patch_corners(frames, patches.level, patches.height, patches.offset)
    masks, _, _ = patch_masks(corners, patches.width, patches.height)
    place = pack(masks, base_angles(frames.length, frames.apex), opt.page_size)
    times["packing"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    bar.stage("atlas")
    textured = assemble(mesh, frames, patches, place, opt.normal_map, opt.mipmaps)
    times["atlas"] = time.perf_counter() - t0
    bar.close()

    texels = np.array([m.sum() for m in masks])
    conv = ~patches.capped
    report["patches"] = {
        "triangles": len(mesh.faces),
        "level_histogram": np.bincount(patches.level, minlength=opt.max_level + 1).tolist(),
        "color_level_histogram": np.bincount(patches.color_level, minlength=opt.max_level + 1).tolist(),
        "normal_level_histogram": np.bincount(patches.normal_level, minlength=opt.max_level + 1).tolist(),
        "texel_histogram": _histogram(texels),
        "texels_min": int(texels.min()), "texels_max": int(texels.max()), "texels_total": int(texels.sum()),
        "capped": int(patches.capped.sum()),
        "color_error_max_converged": float(patches.color_error[conv].max()) if conv.any() else 0.0,
        "normal_error_max_converged": float(patches.normal_error[conv].max()) if conv.any() else 0.0,
        "depth_error_max_converged": (float(patches.depth_error[conv].max()) if conv.any() else 0.0)
        if patches.depth_error is not None else None,
        "color_error_mean": float(patches.color_error.mean()),
        "uncovered_triangles": int((patches.uncovered > 0).sum()),
        "uncovered_texels": int(patches.uncovered.sum()),
        "triangles_without_samples": int((patches.samples == 0).sum()),
    }
    report["_levels"] = patches.level.tolist()  # per triangle of ``mesh``, for tests and figures
    report["_color_levels"] = patches.color_level.tolist()
    report["atlas"] = {"pages": list(place.pages), "fill": list(place.fill),
                       "fill_total": float(texels.sum() / sum(e * e for e in place.pages)),
                       "fill_bound": fill_bound(masks)}
    times["total"] = float(sum(times.values()))
    report["timings"] = times
    return Conversion(textured, mesh, report)


def to_textured_mesh(cloud: SurfelCloud, options: ConvertOptions | None = None) -> TexturedMesh:
    """The textured mesh of a surfel cloud (thesis chapter 6); see :func:`convert_cloud`.

    Example
    -------
    >>> import numpy as np
    >>> from unmesh.surfels import SurfelCloud
    >>> rng = np.random.default_rng(1)
    >>> n = rng.normal(size=(3000, 3)); n /= np.linalg.norm(n, axis=1, keepdims=True)
    >>> tm = to_textured_mesh(SurfelCloud(n, n, radii=np.full(3000, 0.06)), ConvertOptions(faces=200))
    >>> tm.face_count <= 200
    True
    """
    return convert_cloud(cloud, options).textured


def _histogram(values: np.ndarray) -> dict[str, int]:
    """Counts per power-of-two bin of texel counts: {"<=8": n, "<=16": n, ...}."""
    edges = 2 ** np.arange(3, 21)
    out: dict[str, int] = {}
    lo = 0
    for e in edges:
        n = int(((values > lo) & (values <= e)).sum())
        if n:
            out[f"<={int(e)}"] = n
        lo = e
    if (values > lo).any():
        out[f">{int(lo)}"] = int((values > lo).sum())
    return out


class _Stages:
    """One tqdm bar over the stages (each stage also has its own bar where it is long)."""

    NAMES = ("reconstruction", "simplification", "texture patches", "packing", "atlas")

    def __init__(self, enabled: bool) -> None:
        self.bar = None
        if enabled:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=len(self.NAMES), desc="convert", unit="stage", leave=False)
        self.count = 0

    def stage(self, name: str) -> None:
        if self.bar is not None:
            if self.count:
                self.bar.update(1)
            self.bar.set_description(f"convert: {name}")
        self.count += 1

    def close(self) -> None:
        if self.bar is not None:
            self.bar.update(1)
            self.bar.close()
