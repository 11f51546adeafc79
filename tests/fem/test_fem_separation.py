"""Cuts that pass through the material separate it (9.3.2), on TetGen meshes and shipped scenes.

The expected pieces are computed independently of the cutting code, from the
uncut tetrahedral mesh: every tetrahedron is clipped by the half-spaces of the cut
surface, and two clipped pieces on the same side are connected when their shared
triangle has positive area on that side. Pieces smaller than ``1e-5`` of the total
volume (which snapping may legitimately attach to a neighbour) are not counted on
either side. The cut mesh is counted by its element adjacency graph (elements
sharing a node), so even a hinge at a single node counts as connected.
"""

from __future__ import annotations

import functools
import itertools
import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from unmesh.fem import PolyMesh, tetrahedralize
from unmesh.fem._meshcheck import convexity_violation
from unmesh.fem.cutting import CutMissWarning, Cutter, PolygonCut, apply_cuts
from unmesh.fem.events import BladeEvent

MIN_PIECE = 1e-5


@functools.cache
def _blob(spacing: float = 0.16) -> PolyMesh:
    from unmesh.shapes import Blob

    return tetrahedralize(Blob(center=(0.0, 0.46, 0.0)).mesh(spacing))


@functools.cache
def _sphere(spacing: float = 0.2) -> PolyMesh:
    from unmesh.shapes import Sphere

    return tetrahedralize(Sphere(radius=0.6).mesh(spacing))


def element_components(mesh: PolyMesh) -> tuple[np.ndarray, np.ndarray]:
    """Component label of every element (elements sharing a node are adjacent) and component volumes."""
    off, nodes = mesh.element_nodes()
    e = np.repeat(np.arange(mesh.n_elements), np.diff(off))
    inc = sp.csr_array((np.ones(len(nodes)), (e, nodes)), shape=(mesh.n_elements, mesh.n_nodes))
    _, lab = sp.csgraph.connected_components(inc @ inc.T, directed=False)
    return lab, np.bincount(lab, weights=mesh.volumes())


def actual_pieces(mesh: PolyMesh) -> int:
    _, vols = element_components(mesh)
    return int((vols >= MIN_PIECE * vols.sum()).sum())


def expected_pieces(tets: PolyMesh, side) -> int:
    """Pieces of the uncut tet mesh cut along the surface ``side(x) = 0`` (side: (n,3) -> (n,) signed).

    Each tetrahedron is clipped by ``side > 0`` and ``side < 0`` (the clipped volume from
    the vertex values, exact for a plane); pieces connect across a shared triangle
    that has positive area on their side.
    """
    _, nodes = tets.element_nodes()
    t = nodes.reshape(-1, 4)
    s = side(tets.points)
    vol = tets.volumes()
    ne = len(t)
    fe = tets.face_elements()
    inner = np.all(fe >= 0, axis=1)
    fnodes = tets.face_nodes.reshape(-1, 3)[inner]
    a, b = fe[inner, 0], fe[inner, 1]
    count = 0
    for sgn in (1.0, -1.0):
        sv = sgn * s
        frac = np.array([_clipped_fraction(sv[ti]) for ti in t])
        have = frac * vol > 0
        link = np.max(sv[fnodes], axis=1) > 0
        g = sp.coo_array((np.ones(int(link.sum())), (a[link], b[link])), shape=(ne, ne))
        _, lab = sp.csgraph.connected_components(g, directed=False)
        pv = np.bincount(lab, weights=frac * vol, minlength=ne)
        count += int(((pv >= MIN_PIECE * vol.sum()) & np.bincount(lab, weights=have, minlength=ne).astype(bool)).sum())
    return count


def _clipped_fraction(d: np.ndarray) -> float:
    """Volume fraction of a tetrahedron with vertex values d where the (linear) value is positive.

    Exact: the convex hull of the positive corners and the edge crossings, in barycentric space.
    """
    from scipy.spatial import ConvexHull

    pos = d > 0
    k = int(pos.sum())
    if k in (0, 4):
        return float(k // 4)
    corners = np.eye(4)
    pts = [corners[i] for i in range(4) if pos[i]]
    for i in range(4):
        for j in range(4):
            if pos[i] and not pos[j]:
                t = d[i] / (d[i] - d[j])
                pts.append((1 - t) * corners[i] + t * corners[j])
    return float(ConvexHull(np.array(pts)[:, 1:]).volume * 6.0)


def _check_mesh(mesh: PolyMesh, volume: float) -> float:
    assert mesh.volume() == pytest.approx(volume, abs=1e-9)
    mesh.check()
    assert np.all(mesh.volumes() > 0)
    return float(convexity_violation(mesh)[0].max())


def _plane_polygon(origin: np.ndarray, normal: np.ndarray, size: float = 3.0) -> np.ndarray:
    n = normal / np.linalg.norm(normal)
    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    return origin + size * np.array([u + w, -u + w, -u - w, u - w])


def test_clipped_fraction_matches_monte_carlo():
    rng = np.random.default_rng(0)
    for _ in range(5):
        d = rng.normal(size=4)
        w = rng.dirichlet(np.ones(4), size=200_000)
        assert _clipped_fraction(d) == pytest.approx(float(np.mean(w @ d > 0)), abs=5e-3)


@pytest.mark.parametrize("shape", ["sphere", "blob"])
def test_random_full_polygon_cuts_separate_tet_meshes(shape):
    mesh = _sphere() if shape == "sphere" else _blob()
    rng = np.random.default_rng(7 if shape == "sphere" else 8)
    V = mesh.volume()
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    for _ in range(4):
        origin = lo + (0.3 + 0.4 * rng.random(3)) * (hi - lo)
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        r = apply_cuts(mesh, [PolygonCut(_plane_polygon(origin, normal))])
        viol = _check_mesh(r.mesh, V)
        assert viol < 1e-9  # tetrahedra are split through triangles: every cap is planar
        expected = expected_pieces(mesh, lambda x, o=origin, n=normal: (x - o) @ n)
        if shape == "sphere":
            assert expected == 2
        assert actual_pieces(r.mesh) == expected


def test_plane_cut_through_nodes_and_faces_still_separates():
    # cut exactly through existing nodes (snapping everywhere) and along existing faces
    from unmesh.fem import hex_grid, tet_mesh

    g = hex_grid((4, 4, 4))
    _, nodes = g.element_nodes()
    corners = nodes.reshape(-1, 8)  # corner x + 2y + 4z (sorted node ids)
    six = [[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]]
    tets = tet_mesh(g.points, np.concatenate([corners[:, s] for s in six]))
    V = tets.volume()
    for origin, normal in (((0.5, 0.5, 0.5), (0, 1, 0)), ((0.5, 0.5, 0.5), (1, 1, 1)), ((0.5, 0.5, 0.5), (1, -1, 0)),
                           ((0.5, 0.2501, 0.5), (0, 1, 0.001))):
        o, n = np.asarray(origin, float), np.asarray(normal, float)
        r = apply_cuts(tets, [PolygonCut(_plane_polygon(o, n))])
        _check_mesh(r.mesh, V)
        assert actual_pieces(r.mesh) == 2


def test_partial_polygon_cut_keeps_material_connected():
    mesh = _sphere()
    # half of the mid plane: a crack from the side to the centre
    poly = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 0], [-1, 0, 0]], float)
    r = apply_cuts(mesh, [PolygonCut(poly)])
    _check_mesh(r.mesh, mesh.volume())
    assert actual_pieces(r.mesh) == 1
    assert r.mesh.n_nodes > mesh.n_nodes  # nodes in the cut were duplicated: a crack opened
    area = r.mesh.surface().area()
    assert area > mesh.surface().area() + 2 * 0.5 * 0.9 * np.pi * 0.6**2 * 0.9  # two crack sides (~half disc each)


def _sweep(mesh: PolyMesh, blade: BladeEvent, steps: int, snap: float = 0.02) -> PolyMesh:
    """Apply a blade's progressive cuts step by step (one commit per step, as the simulation does)."""
    t = np.linspace(blade.start, blade.stop, steps + 1)
    for t0, t1 in itertools.pairwise(t):
        ops = blade.operations(t0, t1)
        cutter = Cutter(mesh, snap)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CutMissWarning)
            for op in ops:
                cutter.polygon(op.polygon)
        if cutter.touched:
            mesh = cutter.commit().mesh
    return mesh


@pytest.mark.parametrize("shape", ["sphere", "blob"])
def test_curved_blade_sweep_through_tet_mesh_separates(shape):
    mesh = _sphere() if shape == "sphere" else _blob()
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    z0 = 0.5 * (lo[2] + hi[2]) + 0.05
    # the blade spans x, moves down in y while its z follows a bent path (three key positions)
    ys = [hi[1] + 0.1, 0.5 * (lo[1] + hi[1]), lo[1] - 0.1]
    zs = [z0 - 0.15, z0 + 0.05, z0 - 0.1]
    path = np.array([[[lo[0] - 0.2, y, z], [hi[0] + 0.2, y, z]] for y, z in zip(ys, zs, strict=True)])
    blade = BladeEvent(0.0, 1.0, path)
    cut = _sweep(mesh, blade, 24)
    _check_mesh(cut, mesh.volume())

    def side(x: np.ndarray) -> np.ndarray:
        return x[:, 2] - np.interp(-x[:, 1], [-y for y in ys], zs)

    assert actual_pieces(cut) == expected_pieces(mesh, side)
    assert actual_pieces(cut) >= 2


# 13 tetrahedra of the blob mesh (``_blob()``) around the bend of the curved blade path of
# the test above, with the node length scales of the full mesh (which set the snapping bands).
_BEND_POINTS = np.array([
    [-3.7989476363991859e-01, 8.0071560514657358e-01, 1.0523636008152870e-04],
    [-3.7989476363991859e-01, 7.5374533488757312e-01, 1.6010523636008145e-01],
    [-2.1989476363991867e-01, 8.3960096306820975e-01, 1.0523636008152870e-04],
    [-2.1989476363991867e-01, 7.9765486947681019e-01, 1.6010523636008145e-01],
    [-4.2286189359296666e-01, 7.4911621611647106e-01, 8.6454680982062881e-02],
    [-2.9989476363991863e-01, 7.2942528562382736e-01, 2.1438127703188772e-01],
    [-2.9989476363991863e-01, 7.7570010218219165e-01, 1.6010523636008145e-01],
    [-3.1777884914331989e-01, 6.4756563973078285e-01, 7.9654896876885248e-02],
    [-9.1851424482397470e-02, 6.0508902943493170e-01, 1.4962153803374312e-01],
    [-2.3713291932334540e-01, 6.6771042445155659e-01, 2.1160055957541729e-01],
    [-3.4212715541596395e-01, 6.5924767692721298e-01, 1.9930837357797451e-01],
    [-4.2912980370532777e-01, 6.6533518126971036e-01, 1.4424291994576929e-01]])
_BEND_TETS = [[5, 6, 7, 9], [0, 4, 6, 7], [0, 3, 6, 7], [3, 7, 8, 9], [0, 2, 3, 7], [5, 6, 7, 10], [1, 4, 7, 11],
              [1, 7, 10, 11], [2, 3, 7, 8], [5, 7, 9, 10], [1, 6, 7, 10], [1, 4, 6, 7], [3, 6, 7, 9]]
_BEND_SCALES = np.array([0.22629486981113847, 0.16675193038823724, 0.3065382366795456, 0.23148781260411963,
                         0.1525064588435553, 0.15865698739638873, 0.1806260650863019, 0.35660323729563836,
                         0.33734380017871424, 0.2219792440051121, 0.1560813126014115, 0.13364806510712507])


def test_blade_bend_does_not_snap_the_far_side_onto_the_cut_plane():
    """Regression for the hinge of the curved blob sweep (issue 5), on 13 tetrahedra.

    At the bend the new blade plane meets the previous one; a face the previous step
    cut, next to the bend line, lies within the snapping band of the new plane, so an
    element above it cannot be split (its in-plane face bounds neither half). The old
    fallback snapped the side closer to the plane: a node on the far side of the cut
    surface, 9 snapping bands off the plane. The element then bridged the cut (one
    piece instead of two). Now the element stays behind its in-plane face and the
    nodes snapped are those beyond the bend, outside the cut polygon.
    """
    from unmesh.fem import tet_mesh

    t = tet_mesh(_BEND_POINTS, _BEND_TETS)
    mesh = PolyMesh.from_arrays(t.points, t.face_nodes, t.face_offsets, t.elem_faces, t.elem_signs, t.elem_offsets,
                                node_scale=_BEND_SCALES)
    lo = np.array([-0.7480824856921311, 0.016309295904857024, -0.3561594159270203])
    hi = np.array([0.7999855051424705, 1.3800480106884274, 0.3561594159270203])
    z0 = 0.5 * (lo[2] + hi[2]) + 0.05
    ys = [hi[1] + 0.1, 0.5 * (lo[1] + hi[1]), lo[1] - 0.1]
    zs = [z0 - 0.15, z0 + 0.05, z0 - 0.1]
    path = np.array([[[lo[0] - 0.2, y, z], [hi[0] + 0.2, y, z]] for y, z in zip(ys, zs, strict=True)])
    cut = _sweep(mesh, BladeEvent(0.0, 1.0, path), 24)
    _check_mesh(cut, mesh.volume())

    def side(x: np.ndarray) -> np.ndarray:
        return x[:, 2] - np.interp(-x[:, 1], [-y for y in ys], zs)

    assert expected_pieces(mesh, side) == 2
    assert actual_pieces(cut) == 2


def test_straight_blade_sweep_in_many_steps_separates():
    mesh = _blob()
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    path = np.array([[[lo[0] - 0.2, hi[1] + 0.1, 0.1], [hi[0] + 0.2, hi[1] + 0.1, 0.1]],
                     [[lo[0] - 0.2, lo[1] - 0.1, 0.25], [hi[0] + 0.2, lo[1] - 0.1, 0.25]]])
    cut = _sweep(mesh, BladeEvent(0.0, 1.0, path), 30)
    _check_mesh(cut, mesh.volume())
    n = np.cross(path[0, 1] - path[0, 0], path[1, 0] - path[0, 0])
    assert actual_pieces(cut) == expected_pieces(mesh, lambda x: (x - path[0, 0]) @ n)


def test_cut_geometry_half_way_leaves_a_progressive_crack():
    mesh = _sphere()
    lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
    path = np.array([[[lo[0] - 0.2, hi[1] + 0.1, 0.02], [hi[0] + 0.2, hi[1] + 0.1, 0.02]],
                     [[lo[0] - 0.2, lo[1] - 0.1, 0.02], [hi[0] + 0.2, lo[1] - 0.1, 0.02]]])
    blade = BladeEvent(0.0, 1.0, path)
    t = np.linspace(0.0, 1.0, 21)
    m = mesh
    for t0, t1 in itertools.pairwise(t[:11]):  # only the upper half
        c = Cutter(m)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CutMissWarning)
            for op in blade.operations(t0, t1):
                c.polygon(op.polygon)
        if c.touched:
            m = c.commit().mesh
    assert actual_pieces(m) == 1
    _check_mesh(m, mesh.volume())


@pytest.mark.parametrize("name", ["blob_slicing", pytest.param("progressive_slicing", marks=pytest.mark.slow)])
def test_shipped_scenes_cut_geometry_separates(name):
    """Every cut of a shipped scene, applied step by step in rest coordinates, separates.

    Blob slicing is the regression test of the kept snapping decisions
    (:meth:`Cutter.keep_snapped`): without them a node forced onto the blade plane in one
    step is cut off again in the next, leaving a non-convex sliver (violation 0.094) or,
    kept only within twice its own band, a sliver that bridges the cut (3 pieces, not 4)."""
    from unmesh import scenes
    from unmesh.fem.scene import build_simulation
    from unmesh.scene import load_scene

    over = {"objects[0].mesh.spacing": 0.15} if name == "blob_slicing" else {}
    sim, settings = build_simulation(load_scene(scenes.path(f"fem/{name}.toml"), overrides=over))
    mesh0 = sim.dyn.mesh
    mesh = mesh0
    t = 0.0
    while t < settings.duration:
        ops = [op for ev in sim.events for op in ev.operations(t, t + sim.dt)]
        if ops:
            c = Cutter(mesh, sim.snap)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", CutMissWarning)
                for op in ops:
                    c.polygon(op.polygon)
            if c.touched:
                mesh = c.commit().mesh
        t += sim.dt
    _check_mesh(mesh, mesh0.volume())
    blades = [ev for ev in sim.events if isinstance(ev, BladeEvent)]

    def plane_side(b: BladeEvent):
        a0, b0 = b.path[0]
        a1 = b.path[-1][0]
        n = np.cross(b0 - a0, a1 - a0)
        return lambda x: (x - a0) @ n

    if name == "blob_slicing":  # tetrahedra: independent expected count, two planes never meet in the blob
        s1, s2 = (plane_side(b) for b in blades)
        side_of_1 = np.sign(s1(mesh0.element_centers()).mean())  # the body is on this side of blade 1
        expected = (expected_pieces(mesh0, s1) - 1) + (expected_pieces(mesh0, s2) - 1) + 1
        assert side_of_1 != 0
        assert actual_pieces(mesh) == expected
        assert expected >= 3  # two slices and the body (plus the ear tip the first blade takes)
    else:
        assert actual_pieces(mesh) == 3  # two slices and the middle
