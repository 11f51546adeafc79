"""Scene files for ``unmesh fem``: TOML -> :class:`FemSimulation` (format in docs/fem_scene.md).

Example
-------
>>> import tempfile, pathlib
>>> from unmesh.scene import load_scene
>>> p = pathlib.Path(tempfile.mkdtemp()) / "drop.toml"
>>> _ = p.write_text('''
... [simulation]
... dt = 0.01
... duration = 0.1
... [material]
... young = 50
... [ground]
... [[objects]]
... mesh = { type = "hex_grid", cells = [1, 1, 1], origin = [0, 0.5, 0] }
... ''')
>>> sim, settings = build_simulation(load_scene(p))
>>> sim.dyn.mesh.n_nodes, settings.fps
(8, 30.0)
"""

from __future__ import annotations

import numpy as np

from unmesh.fem import builders
from unmesh.fem.dynamics import Dynamics, Ground, Load, Prescribed
from unmesh.fem.events import BladeEvent, CutEvent, PlaneEvent, PolygonEvent, RandomSplitsEvent
from unmesh.fem.integration import IntegrationRule
from unmesh.fem.mesh import PolyMesh
from unmesh.fem.simulation import FemSimulation
from unmesh.scene import Table
from unmesh.sim import RunSettings

__all__ = ["build_mesh", "build_simulation"]

MESH_TYPES = ("hex_grid", "voronoi", "convex", "tetgen", "file")


#: Bytes per hexahedral cell of a grid mesh: its 24x24 stiffness block and the
#: sparse-matrix, integration and cutting data that go with it.
_CELL_BYTES = 8192


def build_mesh(t: Table) -> PolyMesh:
    """A mesh from an inline mesh table (``type`` one of hex_grid, voronoi, convex, tetgen, file).

    Example
    -------
    See the module example; ``{ type = "hex_grid", cells = [2, 2, 2] }`` gives
    a 2×2×2 grid.
    """
    if "file" in t and "type" not in t:
        kind = "file"
    else:
        kind = t.string("type", choices=MESH_TYPES)
    if kind == "hex_grid":
        cells = t.array_of_numbers("cells", [1, 1, 1], shape=(3,), positive=True)
        if np.any(cells % 1):
            raise t.error("cells", f"expected three positive integers, got {cells.tolist()}")
        size = t.vector("size", 3, (1.0, 1.0, 1.0), positive=True)
        origin = t.vector("origin", 3, (0.0, 0.0, 0.0))
        ncells = float(np.prod(cells))
        t.check_budget("cells", ncells * _CELL_BYTES, f"a hex grid of {' x '.join(str(int(c)) for c in cells)} "
                                                      f"= {ncells:.3g} cells")
        return t.call("cells", builders.hex_grid, cells.astype(int), size, origin)
    if kind == "voronoi":
        n = t.integer("cells", minimum=1)
        size = t.vector("size", 3, (1.0, 1.0, 1.0), positive=True)
        origin = t.vector("origin", 3, (0.0, 0.0, 0.0))
        seed = t.integer("seed", 0, minimum=0)
        t.check_budget("cells", float(n) * _CELL_BYTES * 4, f"a Voronoi foam of {n} cells")
        return t.call("cells", builders.voronoi_foam, n, size, origin, seed)
    if kind == "convex":
        if "points" in t:
            pts = t.array_of_numbers("points", shape=(None, 3))
        else:
            count = t.integer("random", minimum=4)
            t.check_budget("random", float(count) * 512, f"a convex hull of {count} random points")
            radius = t.number("radius", 0.5, positive=True)
            center = t.vector("center", 3, (0.0, 0.0, 0.0))
            seed = t.integer("seed", 0, minimum=0)
            rng = np.random.default_rng(seed)
            d = rng.normal(size=(count, 3))
            pts = center + radius * d / np.linalg.norm(d, axis=1, keepdims=True)
        return t.call("points", builders.convex_polyhedron, pts)
    if kind == "tetgen":
        shape = t.shape("shape")
        spacing = t.number("spacing", None, positive=True)
        max_volume = t.number("max_volume", None, positive=True)
        quality = t.number("quality", 1.6, minimum=1.0)
        with t.guard("shape"):
            surf = shape.mesh(spacing) if spacing is not None else shape.mesh()
        return t.call("shape", builders.tetrahedralize, surf, max_volume=max_volume, quality=quality)
    path = t.path("file")
    from unmesh.fem.vtk_io import read_vtu

    if path.suffix.lower() == ".vtu":
        return t.call("file", read_vtu, path)[0]
    from unmesh import io

    surf = t.call("file", io.load_mesh, path)
    return t.call("file", builders.tetrahedralize, surf, max_volume=t.number("max_volume", None, positive=True))


def _material(t: Table | None, default: tuple[float, float, float]) -> tuple[float, float, float]:
    if t is None:
        return default
    y = t.number("young", default[0], positive=True)
    nu = t.number("poisson", default[1], minimum=-0.999, maximum=0.499)
    rho = t.number("density", default[2], positive=True)
    return y, nu, rho


def _select(t: Table, mesh: PolyMesh, key: str) -> np.ndarray:
    sel = t.table(key)
    if "nodes" in sel:
        idx = sel.array_of_numbers("nodes", shape=(None,))
        if np.any(idx % 1) or np.any(idx < 0) or np.any(idx >= mesh.n_nodes):
            raise sel.error("nodes", f"expected node indices in [0, {mesh.n_nodes})")
        return idx.astype(np.int64)
    box = sel.array_of_numbers("box", shape=(2, 3))
    lo, hi = box.min(axis=0), box.max(axis=0)
    inside = np.all((mesh.points >= lo) & (mesh.points <= hi), axis=1)
    nodes = np.flatnonzero(inside)
    if len(nodes) == 0:
        raise sel.error("box", f"selects no node (mesh bounds {mesh.points.min(axis=0).tolist()} to "
                               f"{mesh.points.max(axis=0).tolist()})")
    return nodes


def _events(scene: Table) -> list[CutEvent]:
    out: list[CutEvent] = []
    for c in scene.array("cuts"):
        kind = c.string("type", choices=("plane", "polygon", "polygons", "random_planes", "blade"))
        if kind == "plane":
            out.append(PlaneEvent(c.number("time", 0.0, nonnegative=True), tuple(c.vector("origin", 3)),
                                  tuple(c.vector("normal", 3))))
        elif kind == "polygon":
            out.append(PolygonEvent(c.number("time", 0.0, nonnegative=True), c.array_of_numbers("points", shape=(None, 3))))
        elif kind == "polygons":
            polys = c.raw("polygons")
            times = c.array_of_numbers("times", shape=(None,))
            if not isinstance(polys, list) or len(polys) != len(times):
                raise c.error("polygons", f"expected a list of {len(times)} polygons (one per entry of 'times')")
            for k, (poly, tm) in enumerate(zip(polys, times, strict=True)):
                try:
                    arr = np.asarray(poly, dtype=np.float64)
                except (TypeError, ValueError):
                    raise c.error("polygons", f"polygon {k}: expected a list of [x, y, z] points") from None
                if arr.ndim != 2 or arr.shape[1] != 3 or len(arr) < 3:
                    raise c.error("polygons", f"polygon {k}: expected at least 3 points [x, y, z], got shape {arr.shape}")
                out.append(PolygonEvent(float(tm), arr))
        elif kind == "random_planes":
            out.append(RandomSplitsEvent(c.number("time", 0.0, nonnegative=True), c.integer("count", minimum=1),
                                         c.integer("seed", 0, minimum=0)))
        else:
            start = c.number("start", nonnegative=True)
            stop = c.number("stop", positive=True)
            path = c.array_of_numbers("path", shape=(None, 2, 3))
            out.append(c.call("path", BladeEvent, start, stop, path))
    return out


def build_simulation(scene: Table) -> tuple[FemSimulation, RunSettings]:
    """Build the FEM simulation and run settings of a scene (see docs/fem_scene.md).

    Example
    -------
    See the module example.
    """
    sim_t = scene.table("simulation")
    dt = sim_t.number("dt", positive=True)
    duration = sim_t.number("duration", positive=True)
    fps = sim_t.number("fps", 30.0, positive=True)
    solver = sim_t.string("solver", "auto", choices=("auto", "lu-pcg", "cg", "direct"))
    cg_tol = sim_t.number("cg_tolerance", 1e-6, positive=True)
    warping = sim_t.boolean("warping", True)
    correction = sim_t.boolean("correction", True)
    integration = sim_t.call("integration", IntegrationRule.parse, sim_t.string("integration", "thesis"))
    gravity = sim_t.vector("gravity", 3, (0.0, -9.81, 0.0))
    damping = sim_t.vector("damping", 2, (0.0, 0.0))
    if np.any(damping < 0):
        raise sim_t.error("damping", f"expected two numbers >= 0 (Rayleigh alpha, beta), got {damping.tolist()}")
    snap = sim_t.number("snap", 0.02, nonnegative=True, maximum=0.25)
    slivers = sim_t.number("slivers", 0.0, nonnegative=True, maximum=0.5)
    default = _material(scene.table("material", required=False), (1e3, 0.3, 1.0))
    ground_t = scene.table("ground", required=False)
    ground = None
    if ground_t is not None:
        ground = Ground(ground_t.number("height", 0.0), tuple(ground_t.vector("normal", 3, (0.0, 1.0, 0.0))),
                        ground_t.number("friction", 0.5, nonnegative=True))
        if not np.linalg.norm(ground.normal) > 0:
            raise ground_t.error("normal", "expected a non-zero vector")
    objs = scene.array("objects", required=True)
    if not objs:
        raise scene.error("objects", "expected at least one [[objects]] table")
    meshes, mats, vels = [], [], []
    for o in objs:
        mesh = build_mesh(o.table("mesh"))
        meshes.append(mesh)
        mats.append(_material(o.table("material", required=False), default))
        vels.append(o.vector("velocity", 3, (0.0, 0.0, 0.0)))
    mesh = meshes[0] if len(meshes) == 1 else _concat(meshes)
    counts = [m.n_elements for m in meshes]
    young = np.repeat([m[0] for m in mats], counts)
    poisson = np.repeat([m[1] for m in mats], counts)
    density = np.repeat([m[2] for m in mats], counts)
    prescribed = []
    for b in scene.array("boundary"):
        nodes = _select(b, mesh, "select")
        prescribed.append(Prescribed(nodes, tuple(b.vector("velocity", 3, (0.0, 0.0, 0.0))),
                                     b.number("start", 0.0, nonnegative=True), b.number("stop", float("inf"), positive=True, infinite=True)))
    loads = []
    for ld in scene.array("loads"):
        loads.append(Load(_select(ld, mesh, "select"), tuple(ld.vector("force", 3))))
    events = _events(scene)
    scene.finish()
    with scene.guard(None):
        dyn = Dynamics(mesh, young, poisson, density, gravity=gravity, prescribed=prescribed, ground=ground,
                       loads=loads, rayleigh=(float(damping[0]), float(damping[1])), solver=solver, warping=warping,
                       correction=correction, cg_tol=cg_tol, rule=integration)
    offset = 0
    for m, v in zip(meshes, vels, strict=True):
        dyn.v[offset:offset + m.n_nodes] = v
        offset += m.n_nodes
    if ground is not None:
        low = float((mesh.points @ ground.unit_normal()).min())
        if low < ground.height - 1e-9 * float(np.ptp(mesh.points, axis=0).max()):
            raise scene.error("ground", f"the mesh starts below the ground plane (lowest node at {low:.4g}, "
                                        f"ground at {ground.height:.4g})")
    sim = FemSimulation(dyn, dt, events, snap=snap, sliver_threshold=slivers)
    return sim, RunSettings(duration=duration, fps=fps)


def _concat(meshes: list[PolyMesh]) -> PolyMesh:
    pts, fn, fo, ef, es, eo = [], [], [0], [], [], [0]
    n_off = f_off = 0
    for m in meshes:
        pts.append(m.points)
        fn.append(m.face_nodes + n_off)
        fo.extend((m.face_offsets[1:] + fo[-1]).tolist())
        ef.append(m.elem_faces + f_off)
        es.append(m.elem_signs)
        eo.extend((m.elem_offsets[1:] + eo[-1]).tolist())
        n_off += m.n_nodes
        f_off += m.n_faces
    return PolyMesh.from_arrays(np.concatenate(pts), np.concatenate(fn), fo, np.concatenate(ef), np.concatenate(es), eo,
                                tolerance=max(m.tolerance for m in meshes),
                                abs_tolerance=max(m.abs_tolerance for m in meshes))
