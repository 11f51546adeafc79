"""Surface animation by local frames (7.26-7.30): kernel vs reference, rigid motions, interpolation."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shells.conftest import sphere_with_nodes
from unmesh.shells import CrackSet
from unmesh.shells.skinning import (
    COVER_CAP,
    SkinnedSurface,
    bind_points,
    cover_radii_reference,
    deform_reference,
    frame_normals,
    skin_weight,
    usable_frames,
)


@pytest.fixture(scope="module")
def surface():
    cloud, idx = sphere_with_nodes(200, 1500)
    return cloud, idx, SkinnedSurface(cloud, cloud.positions[idx], cloud.normals[idx])


def rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def test_weight_function_7_30():
    assert np.isinf(skin_weight(np.array([0.0]))[0]) or skin_weight(np.array([0.0]))[0] > 1e20
    np.testing.assert_allclose(skin_weight(np.array([1.0, 1.5])), 0.0)
    w = skin_weight(np.linspace(0.05, 0.95, 10))
    assert np.all(np.diff(w) < 0)


def test_rigid_motion_is_reproduced_exactly(surface, rng):
    cloud, idx, surf = surface
    q = rotation(rng)
    x = cloud.positions[idx] @ q.T + [1.0, -2.0, 0.5]
    out = surf.deform(x, cloud.normals[idx] @ q.T)
    np.testing.assert_allclose(out.positions, cloud.positions @ q.T + [1.0, -2.0, 0.5], atol=1e-10)
    np.testing.assert_allclose(out.normals, cloud.normals @ q.T, atol=1e-8)
    np.testing.assert_allclose(out.radii, cloud.radii, rtol=1e-8)


def test_stretch_is_followed_along_the_frames(surface):
    """Each frame stretches only along e1 (7.26: e2, e3 are unit vectors); a uniformly scaled
    sphere is followed to within the surfel-to-node distance times the stretch."""
    cloud, idx, surf = surface
    out = surf.deform(cloud.positions[idx] * 1.5, cloud.normals[idx])
    r = np.linalg.norm(out.positions, axis=1)
    assert np.abs(r - 1.5).max() < 0.5 * 0.25    # node spacing ~0.25
    assert abs(r.mean() - 1.5) < 0.02
    np.testing.assert_allclose(out.normals, cloud.normals, atol=0.2)


def test_kernel_matches_reference(surface, rng):
    cloud, idx, surf = surface
    x = cloud.positions[idx] * (1 + 0.1 * np.sin(3 * cloud.positions[idx][:, :1])) + rng.normal(scale=0.01,
                                                                                              size=(len(idx), 3))
    n = cloud.normals[idx] + rng.normal(scale=0.05, size=(len(idx), 3))
    out = surf.deform(x, n)
    sel = rng.choice(len(surf), 200, replace=False)
    ref_p, ref_a = deform_reference(surf.node_rest, x, n, surf.node_normals, surf.bind[sel], surf.weights[sel],
                                    surf.points[sel], surf.axes[sel], surf.by_normals[sel])
    np.testing.assert_allclose(out.positions[sel], ref_p, atol=1e-10)
    axis_r = np.linalg.norm(ref_a, axis=2).max(axis=1)     # radii start there (exactly: next tests)
    assert np.all(out.radii[sel] >= axis_r * (1 - 1e-8)) and np.all(out.radii[sel] <= COVER_CAP * axis_r * (1 + 1e-8))


def test_surfels_at_nodes_follow_their_node(surface, rng):
    """(7.29) interpolates: a surfel at a node moves exactly with it."""
    cloud, idx, surf = surface
    x = cloud.positions[idx] + rng.normal(scale=0.05, size=(len(idx), 3))
    out = surf.deform(x, cloud.normals[idx])
    np.testing.assert_allclose(out.positions[idx], x, atol=1e-12)


def test_deformation_is_smooth(surface):
    """A smooth deformation field moves nearby surfels by nearly the same amount."""
    cloud, idx, surf = surface
    disp = lambda p: 0.1 * np.stack([np.sin(p[:, 1]), np.cos(p[:, 2]), p[:, 0] ** 2], axis=1)  # noqa: E731
    out = surf.deform(cloud.positions[idx] + disp(cloud.positions[idx]), cloud.normals[idx])
    err = np.linalg.norm(out.positions - cloud.positions - disp(cloud.positions), axis=1)
    assert err.max() < 0.02   # node spacing ~0.25: interpolation error second order


def test_visibility_binds_to_one_side_of_a_crack():
    nodes = np.array([[x, 0.0, z] for x in np.linspace(-1, 1, 9) for z in np.linspace(-1, 1, 9)])
    cracks = CrackSet()
    cracks.add([0.0, 0, 0], [1.0, 0, 0], 5.0, 0, 0.0)
    pts = np.array([[-0.1, 0.0, 0.05], [0.1, 0.0, -0.05]])
    bind, _w = bind_points(pts, nodes, 6, blocked=cracks.blocked)
    assert np.all(nodes[bind[0][bind[0] >= 0], 0] < 0)
    assert np.all(nodes[bind[1][bind[1] >= 0], 0] >= 0)


# -- splat radii that cover stretched seams (module notes of unmesh.shells.skinning) ----------
def _plane_surface(seed=0, n_side=24, spacing=0.1):
    """A jittered grid of surfels (radius 0.75 spacing) on a 7 x 7 sheet of nodes (spacing 0.4)."""
    from unmesh.shells.nodes import grid_sheet
    from unmesh.surfels import SurfelCloud

    rng = np.random.default_rng(seed)
    nodes, _ = grid_sheet(7, 7, spacing=0.4, jitter=0.1, seed=seed)
    g = (np.arange(n_side) + 0.5) * spacing
    xy = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    xy += rng.uniform(-0.1, 0.1, xy.shape) * spacing
    pts = np.column_stack([xy, np.zeros(len(xy))])
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    cloud = SurfelCloud(pts, up, radii=np.full(len(pts), 0.75 * spacing))
    return cloud, nodes, SkinnedSurface(cloud, nodes, np.tile([0.0, 0.0, 1.0], (len(nodes), 1)))


def _uncovered(cloud, probes):
    """Fraction of probe points (in the plane z = 0) inside no splat disc."""
    from unmesh.spatial import KDTree

    d, i = KDTree(cloud.positions).knn(probes, 8)
    return float(np.mean(~np.any(d <= cloud.radii[i], axis=1)))


def test_cover_radii_kernel_matches_reference(surface, rng):
    cloud, idx, surf = surface
    x = cloud.positions[idx] * (1 + 0.2 * rng.uniform(size=(len(idx), 1)))
    out = surf.deform(x, cloud.normals[idx])
    _, ref_a = deform_reference(surf.node_rest, x, cloud.normals[idx], surf.node_normals, surf.bind, surf.weights,
                                surf.points, surf.axes, surf.by_normals)
    axis_r = np.linalg.norm(ref_a, axis=2).max(axis=1)
    ref = cover_radii_reference(out.positions, surf._cover_nbr, surf._cover_scale2, axis_r)
    np.testing.assert_allclose(out.radii, ref, rtol=1e-10)
    assert np.all(out.radii >= axis_r * (1 - 1e-12)) and np.any(out.radii > 1.05 * axis_r)


def test_nonuniform_stretch_opens_no_holes():
    """Nodes stretched by a random factor each (up to 1.5): the splats still cover the sheet.

    Probes are rest points skinned with the same nodes (the surface the splats sample); with
    the deformed-axis radii alone some of them fall into gaps.
    """
    from unmesh.surfels import SurfelCloud

    cloud, nodes, surf = _plane_surface()
    rng = np.random.default_rng(3)
    stretch = rng.uniform(1.0, 1.5, size=(len(nodes), 1))
    x = nodes.copy()
    x[:, :2] = (nodes[:, :2] - 1.2) * stretch + 1.2
    up = np.tile([0.0, 0.0, 1.0], (len(nodes), 1))
    out = surf.deform(x, up)
    g = np.linspace(0.3, 2.1, 120)       # well inside the sheet (its border is not covered at rest either)
    probe_rest = np.column_stack([np.stack(np.meshgrid(g, g), -1).reshape(-1, 2), np.zeros(g.size ** 2)])
    assert _uncovered(cloud, probe_rest) == 0.0
    probes = SkinnedSurface(SurfelCloud(probe_rest, np.tile([0.0, 0.0, 1.0], (len(probe_rest), 1)),
                                        radii=np.full(len(probe_rest), 0.01)), nodes, up).deform(x, up).positions
    probes[:, 2] = 0.0
    assert np.abs(out.positions[:, 2]).max() < 1e-12
    assert _uncovered(out, probes) == 0.0
    _, axes = deform_reference(surf.node_rest, x, up, surf.node_normals, surf.bind, surf.weights, surf.points,
                               surf.axes, surf.by_normals)
    axis_only = SurfelCloud(out.positions, out.normals, radii=np.linalg.norm(axes, axis=2).max(axis=1))
    assert _uncovered(axis_only, probes) > 0.0


def test_cracks_stay_open():
    """Across a crack the two sides bind to disjoint nodes: pulled apart, no splat bridges the gap."""
    cloud, nodes, surf = _plane_surface()
    cracks = CrackSet()
    cracks.add([1.2, 1.2, 0.0], [1.0, 0.0, 0.0], 5.0, 0, 0.0)
    surf.rebind_near(np.array([[1.2, 1.2, 0.0]]), 5.0, cracks.blocked)
    x = nodes + np.where(nodes[:, :1] >= 1.2, 0.5, 0.0) * [1.0, 0.0, 0.0]
    out = surf.deform(x, np.tile([0.0, 0.0, 1.0], (len(nodes), 1)))
    np.testing.assert_allclose(out.radii, cloud.radii, rtol=1e-12)     # each side moved rigidly
    left = cloud.positions[:, 0] < 1.2
    gap = out.positions[~left, 0].min() - out.positions[left, 0].max()
    assert gap > 0.45


def test_the_two_sides_of_a_thin_part_are_not_cover_neighbours():
    """Surfels on the two faces of a thin plate (normals apart) never widen each other's splats."""
    from unmesh.surfels import SurfelCloud

    cloud, nodes, _ = _plane_surface()
    top = cloud.positions + np.array([0.0, 0.0, 0.02])        # a fifth of the spacing above, facing the other way
    both = SurfelCloud(np.vstack([cloud.positions, top]),
                       np.vstack([cloud.normals, -cloud.normals]), radii=np.concatenate([cloud.radii, cloud.radii]))
    surf = SkinnedSurface(both, nodes, np.tile([0.0, 0.0, 1.0], (len(nodes), 1)))
    n = len(cloud.positions)
    side = np.arange(len(both.positions)) >= n
    across = side[surf._cover_nbr] != side[:, None]
    assert across.any()                                # the nearest neighbour is often on the other face
    assert np.all(surf._cover_scale2[across] == 0.0)
    assert np.all(surf._cover_scale2[~across & (surf._cover_nbr != np.arange(len(side))[:, None])] > 0.0)


def test_cover_pair_kernel_matches_the_reference():
    from unmesh.shells.skinning import _cover_pairs, _cover_pairs_reference

    rng = np.random.default_rng(11)
    bind = rng.integers(-1, 40, size=(3000, 7))
    nbr = rng.integers(0, 3000, size=(3000, 6))
    nbr[::50, 0] = np.arange(0, 3000, 50)                  # a surfel listed as its own neighbour
    rows = np.sort(rng.choice(3000, 1200, replace=False))
    got = _cover_pairs(bind, nbr, rows)
    np.testing.assert_array_equal(got, _cover_pairs_reference(bind, nbr, rows))
    assert 0 < got.sum() < got.size


def test_within_reach_grid_equals_the_plain_loop():
    """Many points and centres: the centres binned in a grid give every point the plain loop's answer."""
    from unmesh.shells import _skinning_kernels as sk

    rng = np.random.default_rng(12)
    pts = rng.uniform(-5, 5, size=(5000, 3))
    pts[:, 2] *= 0.01                                         # nearly flat, as a sheet
    reach = rng.uniform(0.2, 1.0, 5000)
    centers = rng.uniform(-4, 4, size=(30, 3))
    centers[:, 2] = 0.0
    rows = np.sort(rng.choice(5000, 4000, replace=False))
    got = sk.within_reach(pts, rows, reach, 0.3, centers)
    d = np.linalg.norm(pts[rows][:, None] - centers[None], axis=2)
    np.testing.assert_array_equal(got, (d <= (reach[rows] + 0.3)[:, None]).any(axis=1))
    assert 0 < got.sum() < len(rows)


# -- bindings whose nodes have no plane (module notes: frame_normals) -------------------------
def _ball_binding():
    """A node and the six around it spread about equally in all three directions (an ear's base
    at the node scale), with normals pointing away from the z axis and up."""
    nodes = np.array([[0.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0], [0, 1.05, 0], [0, -1.05, 0], [0, 0, 1.1], [0, 0, -1.1]])
    normals = np.column_stack([nodes[:, 0], nodes[:, 1], np.full(7, 0.5)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return nodes, normals


def test_frame_normals_flag_bindings_without_a_plane():
    flat = np.array([[x, y, 0.01 * (x * y)] for x in range(3) for y in range(3)], dtype=float)
    up = np.tile([0.0, 0.0, 1.0], (9, 1))
    plane, flag = frame_normals(flat, up, np.array([[4, 0, 1, 2, 3, 5, 6]]))
    assert flag.tolist() == [0] and plane[0, 2] > 0.999
    nodes, normals = _ball_binding()
    plane, flag = frame_normals(nodes, normals, np.arange(7)[None])
    assert flag.tolist() == [1]
    o = normals.sum(axis=0)
    np.testing.assert_allclose(plane[0], o / np.linalg.norm(o), atol=1e-12)
    # a plane that crosses the surface: nodes on a flat strip whose normals lie in the strip
    strip = np.array([[x, y, 0.0] for x in range(4) for y in (0.0, 0.3)])
    sideways = np.tile([0.0, 1.0, 0.2], (8, 1))
    plane, flag = frame_normals(strip, sideways, np.arange(7)[None])
    assert flag.tolist() == [1]


def test_a_binding_without_a_plane_does_not_amplify_node_motion():
    """Small node motions move a surfel bound to nodes without a plane by about as much: frames
    on the least-squares plane turned its normal with the noise and threw the surfel off (a
    detached splat behind the plastic blob's ear); rigid motions stay exact."""
    from unmesh.shells import _skinning_kernels as sk

    nodes, normals = _ball_binding()
    cloud_p = np.array([[0.1, -0.05, 0.3]])
    from unmesh.surfels import SurfelCloud

    cloud = SurfelCloud(cloud_p, [[0.0, 0.0, 1.0]], radii=[0.2])
    surf = SkinnedSurface(cloud, nodes, normals, skin_nodes=6)
    assert surf.by_normals.tolist() == [1]
    rng = np.random.default_rng(1)
    q = rotation(rng)
    moved = surf.deform(nodes @ q.T + 1.0, normals @ q.T)
    np.testing.assert_allclose(moved.positions, cloud_p @ q.T + 1.0, atol=1e-12)
    _, raw = bind_points(cloud_p, nodes, 6)
    setups = []
    for flag in (0, 1):                       # least-squares plane frames (7.26) vs node-normal frames
        plane = np.empty((1, 3))
        sk.rest_plane_normals(nodes, normals, surf.bind, plane)
        if flag:
            plane = surf.dense.view("plane").copy()
        w = usable_frames(nodes, surf.bind, raw, plane)
        coords = np.empty((1, surf.k, sk.COORDS))
        sk.local_coordinates(nodes, surf.bind, w, plane, surf.points, surf.axes, coords)
        setups.append((w, coords))
    worst = {0: 0.0, 1: 0.0}
    for _ in range(50):
        eps = 0.02 * rng.normal(size=nodes.shape)
        for flag, (w, coords) in enumerate(setups):
            out_p, out_n, out_r = np.empty((1, 3)), np.empty((1, 3)), np.empty(1)
            sk.deform(nodes, nodes + eps, normals, surf.bind, w, coords, surf.points, surf.axes,
                      np.ones(1), np.array([flag], dtype=np.uint8), out_p, out_n, out_r)
            worst[flag] = max(worst[flag], np.linalg.norm(out_p[0] - cloud_p[0]) / np.abs(eps).max())
    print(f"displacement / node motion: plane frames {worst[0]:.1f}, node-normal frames {worst[1]:.1f}")
    assert worst[1] < 3.0 < worst[0]


# -- thin parts: the far face is not bound (module notes: bind_points facing) ---------------------
def _double_sheet(thickness=0.12, seed=0):
    """The two faces of a thin plate, ``thickness`` apart (under half the node spacing 0.4, as
    at the tip of the plastic blob's ear): jittered surfels (spacing 0.1) and a node sheet on
    each face, with outward normals (-z below, +z above)."""
    from unmesh.surfels import SurfelCloud

    cloud, nodes, _ = _plane_surface(seed)
    up = np.tile([0.0, 0.0, 1.0], (len(cloud.positions), 1))
    lift = np.array([0.0, 0.0, thickness])
    both = SurfelCloud(np.vstack([cloud.positions, cloud.positions + lift]), np.vstack([-up, up]),
                       radii=np.concatenate([cloud.radii, cloud.radii]))
    node_up = np.tile([0.0, 0.0, 1.0], (len(nodes), 1))
    return both, np.vstack([nodes, nodes + lift]), np.vstack([-node_up, node_up]), len(cloud.positions), len(nodes)


def test_bind_points_facing_equals_the_brute_force_binding():
    """With ``facing`` every point binds to its K + 1 nearest nodes among those whose normal is
    within 90° of its own (the same face of a thin plate); the weights are those of (7.30)
    over that node list."""
    cloud, nodes, normals, _, _ = _double_sheet()
    pts, pn = cloud.positions, cloud.normals
    b, w = bind_points(pts, nodes, 6, facing=(pn, normals))
    b_all, _ = bind_points(pts, nodes, 6)
    assert (normals[b_all] @ [0.0, 0.0, 1.0] * (pn @ [0.0, 0.0, 1.0])[:, None] < 0).any(axis=1).mean() > 0.9
    for s in range(0, len(pts), 7):
        ok = np.flatnonzero(normals @ pn[s] >= 0.0)
        d = np.linalg.norm(nodes[ok] - pts[s], axis=1)
        order = np.argsort(d, kind="stable")[:7]
        np.testing.assert_array_equal(b[s], ok[order])
        np.testing.assert_allclose(w[s], skin_weight(d[order][1:] / d[order][-1]), rtol=1e-12)


def test_the_far_face_of_a_thin_part_does_not_move_the_surfels():
    """Moving one face of a thin plate leaves the surfels of the other face where they are, with
    their normals: bound also to the far face's nodes (the nearest by distance), the surfels of
    the plastic blob's ear followed the far side's motion (a dark, sunken fleck at the tip)."""
    cloud, nodes, normals, n_low, n_nodes = _double_sheet()
    surf = SkinnedSurface(cloud, nodes, normals)
    top = np.arange(len(cloud.positions)) >= n_low
    assert not (surf.bind[top] < n_nodes).any()                 # the lower face's nodes are not bound
    rng = np.random.default_rng(3)
    x = nodes.copy()
    x[:n_nodes] += [0.1, -0.05, 0.0] + 0.03 * rng.normal(size=(n_nodes, 3))   # shear and crumple the lower face
    out = surf.deform(x, normals)
    np.testing.assert_allclose(out.positions[top], cloud.positions[top], atol=1e-12)
    np.testing.assert_allclose(out.normals[top], cloud.normals[top], atol=1e-12)
    # without the facing test the upper face's surfels are bound to lower-face nodes too
    b, _ = bind_points(cloud.positions, nodes, 6)
    assert (b[top] < n_nodes).any(axis=1).mean() > 0.9


def test_a_rim_surfel_between_two_faces_takes_the_node_normals():
    """A surfel on the rim of a thin plate (normal along the plate) whose nodes lie on its two
    faces: their least-squares plane is the plate's, about 90° from the surfel's normal, so the
    frames use the node normals (``PLANE_SURFACE_AGREEMENT``), whose sum points out of the rim."""
    nodes = np.array([[0.0, 0, 0.06], [0, 0, -0.06], [-0.4, 0.3, 0.06], [-0.4, 0.3, -0.06], [-0.4, -0.3, 0.06],
                      [-0.4, -0.3, -0.06], [-0.8, 0, 0.06]])
    normals = np.array([[0.7, 0, 0.7], [0.7, 0, -0.7], [0, 0, 1], [0, 0, -1], [0, 0, 1], [0, 0, -1], [0, 0, 1.0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    bind = np.arange(7)[None]
    plane, flag = frame_normals(nodes, normals, bind)
    assert flag.tolist() == [0] and abs(plane[0, 2]) > 0.99        # the nodes alone: a fine plane
    plane, flag = frame_normals(nodes, normals, bind, points=np.array([[1.0, 0.0, 0.0]]))
    assert flag.tolist() == [1]
    o = normals.sum(axis=0)
    np.testing.assert_allclose(plane[0], o / np.linalg.norm(o), atol=1e-12)


def test_a_frame_turned_onto_the_normal_fades():
    """A frame node that rolls over onto the frame normal (a node across the rim of a thin part,
    as at the plastic blob's ear when it bends on impact: its edge went from 40° to 10° off N)
    spans almost nothing across its edge (7.26) and alone throws the surfel's normal far off;
    faded (``FRAME_FADE_*``) the surfel moves as if that frame were not there. Rigid motions
    stay exact."""
    from unmesh.shells import _skinning_kernels as sk

    cloud, nodes, surf = _plane_surface()
    s = int(np.argmax(surf.weights.max(axis=1) < 0.5 * surf.weights.sum(axis=1)))   # several frames count
    i = int(np.argmax(surf.weights[s]))
    o, j = surf.bind[s, 0], surf.bind[s, i + 1]
    up = np.tile([0.0, 0.0, 1.0], (len(nodes), 1))
    x = nodes.copy()
    length = np.linalg.norm(nodes[j] - nodes[o])
    side = (nodes[j] - nodes[o]) / length
    for _ in range(50):                        # node j 10° off the plane normal of the moved nodes
        n = np.array(sk.plane_normal(x, up, surf.bind[s]))
        t = side - (side @ n) * n
        x[j] = nodes[o] + length * (np.cos(np.radians(10.0)) * n + np.sin(np.radians(10.0)) * t / np.linalg.norm(t))
    e = x[j] - x[o]
    assert abs(abs(e @ np.array(sk.plane_normal(x, up, surf.bind[s]))) / length - np.cos(np.radians(10.0))) < 1e-6

    def skin(weights):
        p, n, r = np.empty((1, 3)), np.empty((1, 3)), np.empty(1)
        sk.deform(nodes, x, up, surf.bind[s:s + 1], weights, surf.dense.view("coords")[s:s + 1],
                  surf.points[s:s + 1], surf.axes[s:s + 1], surf.dense.view("orient")[s:s + 1],
                  surf.by_normals[s:s + 1], p, n, r)
        return p[0], np.degrees(np.arccos(np.clip(n[0] @ cloud.normals[s], -1, 1)))

    w = surf.weights[s:s + 1].copy()
    p, turn = skin(w)
    alone = np.zeros_like(w)
    alone[0, i] = 1.0
    _, turn_alone = skin(alone)
    w[0, i] = 0.0
    p_without, turn_without = skin(w)
    print(f"normal turned {turn:.2f} degrees; without the turned frame {turn_without:.2f}, it alone {turn_alone:.1f}")
    assert turn_alone > 30.0
    assert abs(turn - turn_without) < 0.5 and np.linalg.norm(p - p_without) < 0.01 * length
    np.testing.assert_allclose(surf.deform(x, up).positions[s], p, atol=1e-12)
    q = rotation(np.random.default_rng(2))
    moved = surf.deform(nodes @ q.T + 0.5, up @ q.T)
    np.testing.assert_allclose(moved.positions, cloud.positions @ q.T + 0.5, atol=1e-10)
