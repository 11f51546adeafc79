"""Shell scene files: TOML -> :class:`~unmesh.shells.simulation.ShellSimulation` (format in ``docs/shell_scene.md``).

Tables: ``[simulation]`` (dt, fps, duration, gravity), ``[surface]`` (input surfels from a
built-in shape, a mesh file or a surfel PLY; node count; neighbourhood sizes; optional
clipping plane), ``[material]`` (K_s, K_b, damping D, density, with optional
``[material.plasticity]``, ``[material.fracture]``, ``[material.anisotropy]`` and
``[[material.regions]]``), ``[initial]`` (velocity), ``[[colliders]]``, ``[[pinned]]``,
``[[handles]]`` and ``[[forces]]``. Paths are relative to the scene file.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from unmesh.scene import Table
from unmesh.shells.dynamics import PlaneCollider, Pressure, SphereCollider
from unmesh.shells.material import Anisotropy, MaterialRegion, ShellMaterial
from unmesh.shells.plasticity import Plasticity
from unmesh.sim import RunSettings

#: Bytes per surfel while sampling a surface (the cloud and the sampler's temporaries).
_SURFEL_BYTES = 256

__all__ = ["build_shell_simulation", "build_simulation", "read_surface"]


def _inf(t: Table, key: str, default: float = math.inf, **kw: Any) -> float:
    """A number where ``inf`` / ``"off"`` mean "no limit" (the shared :func:`unmesh.scene.parse_infinite`)."""
    return t.number(key, default, infinite=True, **kw)


def _check_manifold_mesh(t: Table, key: str, shape: Any) -> None:
    from unmesh.shapes import MeshShape

    if not isinstance(shape, MeshShape):
        return
    mesh = shape.mesh()
    e = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    bad = int((counts > 2).sum())
    if bad:
        raise t.error(key, f"the mesh is non-manifold: {bad} edges are shared by more than two triangles; "
                           "a thin shell needs a manifold surface")


def read_surface(t: Table) -> tuple[Any, float | None]:
    """The dense input cloud of ``[surface]`` and its area (None when unknown).

    Exactly one of ``shape`` (built-in shape or mesh file, sampled every ``spacing``) and
    ``surfels`` (a surfel PLY, used as is). ``clip = { point, normal }`` keeps the
    surfels on the normal's side (a dome from a sphere); ``color`` sets their colour.
    """
    from unmesh.surfels import SurfelCloud

    has_shape, has_file = "shape" in t, "surfels" in t
    if has_shape == has_file:
        raise t.error(None, "expected exactly one of 'shape' (a shape or mesh file) and 'surfels' (a surfel PLY)")
    color = t.vector("color", 3, default=None)
    area = None
    if has_shape:
        shape = t.shape("shape")
        _check_manifold_mesh(t, "shape", shape)
        spacing = t.number("spacing", positive=True)
        with t.guard("shape"):
            area = float(shape.area())
        count = area / spacing**2 if np.isfinite(area) else math.inf
        t.check_budget("spacing", count * _SURFEL_BYTES, f"sampling the surface at spacing {spacing:g} "
                                                         f"(about {count:.3g} surfels)")
        with t.guard("shape"):
            cloud = shape.surfels(spacing, color=color)
    else:
        from unmesh import io

        path = t.path("surfels")
        cloud = t.call("surfels", io.load, path)
        if not isinstance(cloud, SurfelCloud):
            raise t.error("surfels", f"expected a surfel PLY (x y z nx ny nz radius ...), got a {type(cloud).__name__}; "
                                     "use 'shape = { file = ... }' for meshes")
        if color is not None:
            cloud = cloud.replace(colors=np.tile(color, (len(cloud), 1)))
    clip = t.table("clip", required=False)
    if clip is not None:
        point = clip.vector("point", 3)
        normal = clip.vector("normal", 3)
        if not np.linalg.norm(normal) > 0:
            raise clip.error("normal", "expected a non-zero vector")
        keep = (cloud.positions - point) @ normal >= 0
        if keep.sum() < 20:
            raise clip.error(None, f"the clipping plane keeps only {int(keep.sum())} surfels")
        if area is not None:
            area *= keep.mean()
        cloud = cloud.subset(keep)
    return cloud, area


def _material(t: Table) -> ShellMaterial:
    plast = t.table("plasticity", required=False)
    plasticity = Plasticity()
    if plast is not None:
        alpha = plast.number("alpha", default=0.0, nonnegative=True)
        beta = _inf(plast, "beta", nonnegative=True)
        plasticity = Plasticity(
            creep_stretch=plast.number("alpha_stretch", default=alpha, nonnegative=True),
            creep_bend=plast.number("alpha_bend", default=alpha, nonnegative=True),
            yield_stretch=_inf(plast, "beta_stretch", beta, nonnegative=True),
            yield_bend=_inf(plast, "beta_bend", beta, nonnegative=True),
            weakening=plast.number("weakening", default=0.0, nonnegative=True))
    frac = t.table("fracture", required=False)
    gs = gb = math.inf
    if frac is not None:
        gs = _inf(frac, "gamma_s", positive=True)
        gb = _inf(frac, "gamma_b", positive=True)
    aniso = None
    at = t.table("anisotropy", required=False)
    if at is not None:
        aniso = at.call("direction", Anisotropy, at.vector("direction", 3), at.vector("stretch", 2, default=(1.0, 1.0)),
                        at.vector("bend", 2, default=(1.0, 1.0)))
    regions = []
    for r in t.array("regions"):
        regions.append(MaterialRegion(r.shape("region"), r.number("stretch", default=1.0, nonnegative=True),
                                      r.number("bend", default=1.0, nonnegative=True),
                                      r.number("fracture", default=1.0, positive=True)))
    with t.guard(None):
        return ShellMaterial(ks=t.number("ks", nonnegative=True), kb=t.number("kb", nonnegative=True),
                             damping=t.number("damping", default=0.0, nonnegative=True),
                             density=t.number("density", default=1.0, positive=True), plasticity=plasticity,
                             fracture_stretch=gs, fracture_bend=gb, anisotropy=aniso, regions=tuple(regions),
                             arc_samples=t.integer("arc_samples", default=4, minimum=1))


def _colliders(scene: Table) -> list[Any]:
    out: list[Any] = []
    for c in scene.array("colliders"):
        kind = c.string("type", choices=("plane", "sphere"))
        e = c.number("restitution", default=0.0, minimum=0.0, maximum=1.0)
        mu = c.number("friction", default=0.5, nonnegative=True)
        if kind == "plane":
            n = c.vector("normal", 3, default=(0.0, 1.0, 0.0))
            if not np.linalg.norm(n) > 0:
                raise c.error("normal", "expected a non-zero vector")
            out.append(PlaneCollider(c.vector("point", 3, default=(0.0, 0.0, 0.0)), n, e, mu))
        else:
            out.append(SphereCollider(c.vector("center", 3), c.number("radius", positive=True), e, mu))
    return out


def build_simulation(scene: Table) -> tuple[Any, RunSettings]:
    """Build the simulation and run settings of a shell scene (the ``unmesh shell`` builder).

    Parameters
    ----------
    scene : unmesh.scene.Table
        Root table of a loaded scene file.

    Returns
    -------
    (ShellSimulation, RunSettings)

    Raises
    ------
    unmesh.errors.SceneError
        Naming the file and key for every invalid or unknown value, and for bad inputs
        (too few nodes, a disconnected or non-manifold surface).
    """
    from unmesh.shells.simulation import ShellSimulation

    sim = scene.table("simulation")
    dt = sim.number("dt", positive=True)
    settings = RunSettings(duration=sim.number("duration", positive=True), fps=sim.number("fps", default=25.0,
                                                                                           positive=True))
    gravity = sim.vector("gravity", 3, default=(0.0, -9.81, 0.0))
    max_cracks = sim.integer("max_cracks_per_step", default=8, minimum=1)
    surf = scene.table("surface")
    cloud, area = read_surface(surf)
    nodes = surf.integer("nodes", minimum=1)
    neighbors = surf.integer("neighbors", default=12, minimum=3, maximum=64)
    min_angle = surf.number("min_angle", default=120.0, minimum=90.0, maximum=180.0)
    skin = surf.integer("skin_nodes", default=6, minimum=2, maximum=32)
    material = _material(scene.table("material"))
    init = scene.table("initial", required=False)
    velocity = init.vector("velocity", 3, default=(0.0, 0.0, 0.0)) if init is not None else np.zeros(3)
    colliders = _colliders(scene)
    pinned = [p.shape("region") for p in scene.array("pinned")]
    handles = [{"region": h.shape("region"), "velocity": h.vector("velocity", 3),
                "start": h.number("start", default=0.0, nonnegative=True),
                "stop": _inf(h, "stop", nonnegative=True),
                "acceleration": h.vector("acceleration", 3, default=(0.0, 0.0, 0.0))} for h in scene.array("handles")]
    pulls: list[dict[str, Any]] = []
    pressure = None
    for f in scene.array("forces"):
        kind = f.string("type", choices=("pull", "pressure"))
        if kind == "pull":
            pulls.append({"region": f.shape("region"), "force": f.vector("force", 3),
                          "ramp": f.number("ramp", default=0.0, nonnegative=True),
                          "start": f.number("start", default=0.0, nonnegative=True), "stop": _inf(f, "stop")})
        else:
            if pressure is not None:
                raise f.error("type", "only one pressure force per scene")
            pressure = Pressure(f.number("pressure", default=0.0), f.number("rate", default=0.0),
                                _inf(f, "max"), _inf(f, "release", positive=True))
    if nodes >= len(cloud):
        raise surf.error("nodes", f"expected fewer simulation nodes than surfels ({len(cloud)}), got {nodes}; "
                                  "lower 'nodes' or the surfel 'spacing'")
    scene.finish()
    name = scene.file.stem
    with scene.guard(None):
        shell = ShellSimulation(cloud, material, dt, nodes=nodes, neighbors=neighbors, min_angle=min_angle,
                                skin_nodes=skin, gravity=gravity, velocity=velocity, colliders=colliders,
                                pinned=pinned, handles=handles, pulls=pulls, pressure=pressure, total_area=area,
                                max_cracks=max_cracks, name=name)
    return shell, settings


def build_shell_simulation(scene: Table) -> tuple[Any, RunSettings]:
    """Deprecated name of :func:`build_simulation` (the builders of sph, shells and fem share one name)."""
    warnings.warn("unmesh.shells.build_shell_simulation is deprecated; use unmesh.shells.build_simulation",
                  DeprecationWarning, stacklevel=2)
    return build_simulation(scene)
