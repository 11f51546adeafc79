"""Particles as ray-cast spheres and discs, colour by attribute, legends."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import Particles
from unmesh.errors import InputError
from unmesh.render import Camera, GBuffer, render
from unmesh.render._reference import spheres_reference
from unmesh.render.particles import draw_particles, estimate_radius


def test_sphere_depth_and_normals_are_analytic():
    cam = Camera((0, 0, 5), (0, 0, 0), width=64, height=64, ortho=2.0)
    res = render(Particles([[0.0, 0.0, 0.0]], radii=[0.8]), cam)
    o, _ = cam.rays()
    x, y = o[..., 0], o[..., 1]
    inside = x * x + y * y < 0.8**2
    assert np.array_equal(res.coverage, inside)
    z = np.sqrt(np.clip(0.8**2 - x * x - y * y, 0, None))
    assert np.allclose(res.depth[inside], 5 - z[inside])
    assert np.allclose(res.normal[inside], np.stack([x, y, z], -1)[inside] / 0.8)


@pytest.mark.parametrize("ortho", [False, True])
def test_kernel_matches_reference(rng, ortho):
    centers = rng.normal(size=(40, 3)) * 0.6
    radii = rng.uniform(0.02, 0.3, 40)
    cam = Camera((0.3, 0.4, 3), (0, 0, 0), width=50, height=40, fov=None if ortho else 45, ortho=2.5 if ortho else None)
    g = GBuffer.empty(40, 50)
    draw_particles(g, [Particles(centers, radii=radii)], cam, filter_radius=0.75)
    depth, index, normal = spheres_reference(centers, radii, cam, filter_radius=0.75)
    assert np.array_equal(g.coverage, index >= 0)
    m = index >= 0
    assert np.abs(g.depth[m] - depth[m]).max() < 1e-9
    assert np.abs(g.normal[m] - normal[m]).max() < 1e-9


def test_tiny_particles_never_vanish():
    rng = np.random.default_rng(4)
    pts = rng.uniform(-1, 1, (50, 3))
    cam = Camera((0, 0, 5), (0, 0, 0), width=40, height=40, ortho=2.5)
    res = render(Particles(pts, radii=np.full(50, 1e-6)), cam)
    row, col, _ = cam.project(pts)
    assert res.coverage[np.floor(row).astype(int), np.floor(col).astype(int)].all()


def test_discs_face_the_camera():
    cam = Camera((0, 0, 5), (0, 0, 0), width=32, height=32, ortho=2.0)
    res = render(Particles([[0.0, 0.0, 0.0]], radii=[0.5]), cam, particle_style="disc", shading="none")
    assert np.allclose(res.depth[res.coverage], 5.0)
    assert np.allclose(res.normal[res.coverage], [0, 0, 1])
    with pytest.raises(InputError):
        render(Particles([[0.0, 0.0, 0.0]]), cam, particle_style="cube")


def test_radius_estimate_from_spacing():
    g = np.stack(np.meshgrid(np.arange(10), np.arange(10), np.arange(10)), -1).reshape(-1, 3) * 0.1
    assert estimate_radius(g) == pytest.approx(0.05)
    cam = Camera((0.5, 0.5, 5), (0.5, 0.5, 0), width=64, height=64, ortho=1.2)
    res = render(Particles(g), cam, shading="none")
    assert res.coverage[10:54, 10:54].mean() > 0.7  # touching spheres (radius = half spacing)


def test_color_by_attribute_with_colormap_and_legend():
    p = Particles([[-0.5, 0, 0], [0.5, 0, 0]], radii=[0.3, 0.3], attributes={"density": [1.0, 3.0], "v": [[0, 0, 0], [3, 4, 0]]})
    cam = Camera((0, 0, 5), (0, 0, 0), width=120, height=80, ortho=2.0)
    res = render(p, cam, color_by="density", shading="none", legend=False)
    assert res.color_range == (1.0, 3.0)
    from unmesh.render import colormap

    vir = colormap("viridis")
    row, col, _ = cam.project(p.positions)
    assert np.allclose(res.color[int(row[0]), int(col[0])], vir(np.array([0.0]))[0])
    assert np.allclose(res.color[int(row[1]), int(col[1])], vir(np.array([1.0]))[0])
    speed = render(p, cam, color_by="v", shading="none", legend=False, color_range=(0, 10))
    assert np.allclose(speed.color[int(row[1]), int(col[1])], vir(np.array([0.5]))[0])
    with_legend = render(p, cam, color_by="density", shading="none")
    diff = np.abs(with_legend.color - res.color).sum(-1) > 0
    assert diff.any() and diff[:, : 120 // 2].sum() < diff[:, 120 // 2 :].sum()  # bar on the right
    with pytest.raises(InputError, match="available"):
        render(p, cam, color_by="pressure")


def test_mixed_scene_particles_and_surfels_share_the_depth_buffer():
    from unmesh import SurfelCloud

    surf = SurfelCloud([[0, 0, 0]], [[0, 0, 1]], radii=[1.0], colors=[[0, 1.0, 0]])
    front = Particles([[0.3, 0, 0.5]], radii=[0.2])
    back = Particles([[-0.3, 0, -0.5]], radii=[0.2])
    cam = Camera((0, 0, 5), (0, 0, 0), width=40, height=40, ortho=3.0)
    res = render([surf, front, back], cam, shading="none")
    row, col, _ = cam.project([[0.3, 0, 0], [-0.3, 0, 0]])
    assert np.allclose(res.color[int(row[0]), int(col[0])], [0.22, 0.52, 0.85])  # particle in front
    assert np.allclose(res.color[int(row[1]), int(col[1])], [0, 1, 0], atol=1e-6)  # surfel hides the back one


def test_object_ids_get_distinct_colours():
    p = Particles([[-0.5, 0, 0], [0.5, 0, 0]], radii=[0.3, 0.3], attributes={"object": [0.0, 1.0]})
    cam = Camera((0, 0, 5), (0, 0, 0), width=40, height=20, ortho=1.0)
    res = render(p, cam, shading="none")
    assert np.allclose(res.color[10, 10], [0.22, 0.52, 0.85]) and np.allclose(res.color[10, 30], [0.93, 0.55, 0.18])
