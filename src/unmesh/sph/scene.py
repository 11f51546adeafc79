"""Build an SPH simulation from a TOML scene file (format: ``docs/sph_scene.md``).

Example
-------
>>> import tempfile, pathlib
>>> from unmesh.scene import load_scene
>>> f = pathlib.Path(tempfile.mkdtemp()) / "s.toml"
>>> _ = f.write_text('''
... [simulation]
... dimension = 2
... spacing = 0.05
... dt = 0.0005
... duration = 0.1
... [materials.water]
... stiffness = 500.0
... [[objects]]
... material = "water"
... shape = { type = "box", center = [0.25, 0.25, 0], size = [0.5, 0.5, 1] }
... [[boundaries]]
... type = "box"
... min = [0, 0, 0]
... max = [1, 1, 0]
... ''')
>>> sim, settings = build_simulation(load_scene(f))
>>> sim.summary_header()["particles"], settings.duration
(110, 0.1)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from unmesh.errors import SceneError
from unmesh.scene import Table
from unmesh.sim import RunSettings
from unmesh.sph.boundary import BoundaryParticles, Plane, box_planes, sample_boundary
from unmesh.sph.materials import Material
from unmesh.sph.phase import HeatSource
from unmesh.sph.sampling import LATTICES, sample_shape
from unmesh.sph.simulation import SPHConfig, SPHObject, SPHSimulation

__all__ = ["MATERIAL_KEYS", "build_simulation"]

#: Scene keys of a material and their defaults (see :class:`unmesh.sph.Material`).
MATERIAL_KEYS: dict[str, Any] = {
    "density": 1.0, "stiffness": 200.0, "gamma": 1.0, "negative_pressure": 0.01, "viscosity": 0.0,
    "xsph": 0.0, "artificial_viscosity": 0.05, "elastic_stiffness": 0.0, "goal_deformation": 0.5,
    "young": 0.0, "poisson": 0.3, "docking_rate": math.inf, "docking_gain": math.inf, "docking_loss": 0.0,
    "fracture_stretch": math.inf, "diffusivity": 0.0, "melt_rate": 0.0, "melting_point": math.inf,
    "freeze_rate": 0.0, "freezing_point": -math.inf, "freeze_min_neighbors": 1, "freeze_max_velocity": math.inf,
    "freeze_max_force": math.inf, "density_diffusion": 0.0,
    "density_passes": 1, "plastic_yield": math.inf, "plastic_creep": math.inf,
}


def _material(name: str, t: Table) -> Material:
    values: dict[str, Any] = {}
    for key, default in MATERIAL_KEYS.items():
        if key == "density_diffusion" and t.raw(key, default) == "off":  # δ-SPH density filter disabled
            values[key] = 0.0
        elif key in ("freeze_min_neighbors", "density_passes"):
            values[key] = t.integer(key, default=default, minimum=0 if key == "freeze_min_neighbors" else 1)
        else:
            values[key] = t.number(key, default, infinite=True)
    return t.call(None, Material, name, **values)


#: Bytes per lattice point while sampling a shape (positions, inside tests, temporaries).
_SAMPLE_BYTES = 128


def _sample(obj: Table, shape: Any, spacing: float, dim: int, lattice: str, centered: bool) -> np.ndarray:
    with obj.guard("shape"):
        lo, hi = np.asarray(shape.bounds(), dtype=np.float64)
    extent = np.maximum(hi - lo, spacing)[:dim]
    points = float(np.prod(extent / spacing + 1.0))
    obj.check_budget("shape", points * _SAMPLE_BYTES, f"sampling this shape at spacing {spacing:g} "
                                                       f"(about {points:.3g} lattice points)")
    return obj.call("shape", sample_shape, shape, spacing, dim, lattice=lattice, centered=centered)


def _boundaries(scene: Table, dim: int, spacing: float, h: float) -> tuple[list[Plane], BoundaryParticles | None,
                                                                            list[tuple[Any, bool]]]:
    planes: list[Plane] = []
    parts: list[BoundaryParticles] = []
    shapes: list[tuple[Any, bool]] = []
    for b in scene.array("boundaries"):
        kind = b.string("type", choices=("box", "plane", "particles"))
        with b.guard(None):
            if kind == "box":
                planes += box_planes(b.vector("min", 3), b.vector("max", 3), dim, open_top=b.boolean("open_top", False),
                                     no_slip=b.boolean("no_slip", False))
            elif kind == "plane":
                normal = b.vector("normal", 3)
                if dim == 2 and normal[2] != 0:
                    raise b.error("normal", "expected z = 0 in a 2D scene")
                planes.append(Plane(b.vector("point", 3), normal, b.boolean("no_slip", False)))
            else:
                shape = b.shape("shape")
                inside = b.string("side", default="outside", choices=("outside", "inside")) == "inside"
                parts.append(sample_boundary(shape, b.number("spacing", default=spacing, positive=True), h, dim,
                                             b.boolean("no_slip", False)))
                shapes.append((shape, inside))
    boundary = None
    if parts:
        pos = np.concatenate([p.positions for p in parts])
        vol = np.concatenate([p.volumes for p in parts])
        if len(parts) > 1:  # recompute volumes where layers of different shapes meet
            from unmesh.sph.boundary import boundary_volumes

            vol = boundary_volumes(pos, h, dim)
        boundary = BoundaryParticles(pos, vol, np.concatenate([p.no_slip for p in parts]))
    return planes, boundary, shapes


def _check_overlaps(scene: Table, objects: list[SPHObject], shapes: list[Any]) -> None:
    """Objects whose particles lie inside another object's shape overlap (SceneError)."""
    for a, obj in enumerate(objects):
        for b, shape in enumerate(shapes):
            if a == b:
                continue
            inside = np.asarray(shape.contains(obj.positions), dtype=bool)
            if inside.any():
                k = int(np.flatnonzero(inside)[0])
                raise SceneError(f"{scene.file.name}: objects {obj.name!r} and {objects[b].name!r} overlap "
                                 f"({int(inside.sum())} particles of {obj.name!r} inside the shape of "
                                 f"{objects[b].name!r}, e.g. at {np.round(obj.positions[k], 6).tolist()}); move them apart")


def build_simulation(scene: Table) -> tuple[SPHSimulation, RunSettings]:
    """Read a scene's root table and build the simulation and its run settings.

    Raises
    ------
    unmesh.errors.SceneError
        Naming the file and key for invalid values, unknown keys, empty scenes,
        overlapping objects and particles outside the boundaries.

    Example
    -------
    >>> from unmesh.scene import load_scene
    >>> from unmesh.scenes import path
    >>> sim, settings = build_simulation(load_scene(path("sph/elastic_cube_2d.toml"), {"simulation.spacing": 0.04}))
    >>> sim.dim, settings.fps
    (2, 30.0)
    """
    sim_t = scene.table("simulation")
    dim = sim_t.integer("dimension", default=3, minimum=2, maximum=3)
    spacing = sim_t.number("spacing", positive=True)
    smoothing = sim_t.number("smoothing", default=2.0, positive=True)
    dt = sim_t.number("dt", positive=True)
    cfl = sim_t.number("cfl", default=None, positive=True)
    duration = sim_t.number("duration", positive=True)
    fps = sim_t.number("fps", default=30.0, positive=True)
    gravity = sim_t.vector("gravity", 3, default=(0.0, -9.81, 0.0))
    seed = sim_t.integer("seed", default=0, minimum=0)
    wall_pressure = sim_t.number("wall_pressure", default=2.0, positive=True)
    name = sim_t.string("name", default=scene.file.stem)
    lattice = sim_t.string("lattice", default="closest", choices=LATTICES)
    tensile = sim_t.number("tensile_correction", default=4.0, nonnegative=True)
    damping = sim_t.number("contact_damping", default=0.0, nonnegative=True)
    neighbor_skin = sim_t.number("neighbor_skin", default=0.2, nonnegative=True)
    config = sim_t.call(None, SPHConfig, dim=dim, spacing=spacing, dt=dt, smoothing=smoothing, cfl=cfl,
                        gravity=gravity, seed=seed, wall_pressure=wall_pressure, lattice=lattice,
                        tensile_correction=tensile, contact_damping=damping, neighbor_skin=neighbor_skin)
    out_t = scene.table("output", required=False)
    surfaces = "none"
    resolution = 0.5
    skin = False
    if out_t is not None:
        surfaces = out_t.string("surface", default="none", choices=("none", "fluid", "all"))
        resolution = out_t.number("surface_resolution", default=0.5, positive=True)
        skin = out_t.boolean("skin", default=False)
        if (surfaces != "none" or skin) and dim != 3:
            raise out_t.error("surface" if surfaces != "none" else "skin", "surface meshes need dimension = 3")
    materials = {name_: _material(name_, t) for name_, t in scene.tables("materials", required=True).items()}
    objects: list[SPHObject] = []
    shapes: list[Any] = []
    for k, o in enumerate(scene.array("objects")):
        oname = o.string("name", default=f"object{k}")
        mat = o.string("material", choices=tuple(materials))
        shape = o.shape("shape")
        phase = o.string("phase", default="fluid", choices=("fluid", "solid"))
        # solids: mirror-symmetric sampling, so that a body dropped flat gets no spin from its lattice
        pos = _sample(o, shape, spacing, dim, lattice, centered=phase == "solid")
        shapes.append(shape)
        if len(pos) == 0:
            raise o.error("shape", f"samples no particles at spacing {spacing}"
                          + (" (a 2D scene samples the shape's cross-section with z = 0)" if dim == 2 else ""))
        surface = None
        if o.boolean("skin", default=True) and skin:
            surface = shape.mesh(spacing)
        with o.guard(None):
            objects.append(SPHObject(
                oname, pos, mat, velocity=o.vector("velocity", 3, default=(0.0, 0.0, 0.0)),
                angular_velocity=o.vector("angular_velocity", 3, default=(0.0, 0.0, 0.0)),
                temperature=o.number("temperature", default=0.0),
                phase=phase,
                fixed=o.boolean("fixed", default=False), anchor=o.shape("anchor", default=None), surface=surface))
    if not objects:
        raise scene.error(None, "the scene has no objects: add at least one [[objects]] table")
    _check_overlaps(scene, objects, shapes)
    h = config.h
    planes, boundary, bshapes = _boundaries(scene, dim, spacing, h)
    heat: list[HeatSource] = []
    for k, hs in enumerate(scene.array("heat_sources")):
        with hs.guard(None):
            heat.append(HeatSource(hs.shape("shape"), hs.number("temperature"), hs.number("rate", positive=True),
                                   hs.number("distance", default=0.0, nonnegative=True), name=f"heat_sources[{k}]"))
    scene.finish()
    sim = scene.call(None, SPHSimulation, config, materials, objects, planes=planes, boundary=boundary,
                     boundary_shapes=bshapes, heat_sources=heat, surfaces=surfaces, surface_resolution=resolution,
                     name=name)
    return sim, RunSettings(duration=duration, fps=fps)
