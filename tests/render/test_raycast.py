"""MLS ray casting (3.1.3) with the shared camera, shading and buffers; agreement with splatting."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import SurfelCloud
from unmesh.render import Camera, render

from .conftest import fibonacci_sphere


@pytest.fixture(scope="module")
def colourful_sphere():
    c = fibonacci_sphere(4000)
    p = c.positions
    col = 0.5 + 0.5 * np.stack([np.sin(4 * p[:, 0]), np.sin(4 * p[:, 1]), np.cos(4 * p[:, 2])], 1)
    return c.replace(colors=col)


def test_raycast_depth_and_normals_on_the_sphere(colourful_sphere):
    cam = Camera((0, 0, 5), (0, 0, 0), width=64, height=64, ortho=2.4)
    res = render(colourful_sphere, cam, method="raycast", shading="none")
    o, _ = cam.rays()
    x, y = o[..., 0], o[..., 1]
    inner = x * x + y * y < 0.95**2
    assert res.coverage[inner].all()
    assert not res.coverage[x * x + y * y > 1.05**2].any()
    z = np.sqrt(np.clip(1 - x * x - y * y, 0, None))
    assert np.abs(res.depth - (5 - z))[inner].max() < 0.01
    ang = np.degrees(np.arccos(np.clip(np.sum(res.normal * np.stack([x, y, z], -1), -1), -1, 1)))
    assert ang[inner].mean() < 1.0
    assert np.all(res.normal[~res.coverage] == 0) and np.all(np.isinf(res.depth[~res.coverage]))


def test_splat_and_raycast_images_agree(colourful_sphere):
    cam = Camera((0.6, 0.8, 3.2), (0, 0, 0), width=96, height=96, fov=45)
    a = render(colourful_sphere, cam, method="splat")
    b = render(colourful_sphere, cam, method="raycast")
    both = a.coverage & b.coverage
    iou = both.sum() / (a.coverage | b.coverage).sum()
    mad = float(np.abs(a.color - b.color)[both].mean())
    print(f"splat vs ray-cast: mean absolute colour difference {mad:.4f} (IoU {iou:.4f})")
    from scipy.ndimage import binary_dilation

    # silhouettes agree to within two pixels (splats are ~1 px wider: tangent discs + screen filter)
    assert not (a.coverage & ~binary_dilation(b.coverage, iterations=2)).any()
    assert not (b.coverage & ~binary_dilation(a.coverage, iterations=2)).any()
    assert mad < 0.02
    assert np.abs(a.depth[both] - b.depth[both]).mean() < 0.005


def test_raycast_mixed_with_opaque_and_empty():
    from unmesh import Particles

    plane = SurfelCloud([[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0], [0.3, 0.3, 0]], [[0, 0, 1]] * 4, radii=[0.3] * 4,
                        colors=[[0, 1.0, 0]] * 4)
    ball = Particles([[0.15, 0.15, 0.3]], radii=[0.05])
    cam = Camera((0.15, 0.15, 3), (0.15, 0.15, 0), width=32, height=32, ortho=1.0)
    res = render([plane, ball], cam, method="raycast", shading="none")
    assert np.allclose(res.color[16, 16], [0.22, 0.52, 0.85])  # the particle occludes the surface
    assert np.allclose(res.color[16, 22], [0, 1, 0], atol=1e-9)
    empty = SurfelCloud(np.zeros((0, 3)), np.zeros((0, 3)), radii=np.zeros(0))
    assert not render(empty, cam, method="raycast").coverage.any()
