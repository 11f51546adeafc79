"""Partial normalisation and shading (5.7): ``SplatRenderer.resolve_window`` and
``shade(window=, origin=)`` equal the matching part of the whole-image calls."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh import SurfelCloud
from unmesh.errors import InputError
from unmesh.render import Camera, SplatRenderer, shade
from unmesh.render.cli import parse_size
from unmesh.render.shading import GBuffer

from .conftest import fibonacci_sphere

CAM = Camera((0.4, 0.3, 3), (0, 0, 0), width=40, height=32, fov=45)
WIN = (5, 21, 8, 30)


@pytest.fixture(scope="module")
def renderer():
    base = fibonacci_sphere(2000)
    colors = np.random.default_rng(3).random((len(base), 3))
    cloud = SurfelCloud(base.positions, base.normals, radii=base.radii, colors=colors)
    return SplatRenderer(CAM).render(cloud)


def test_resolve_window_equals_the_whole_image_inside_and_leaves_the_rest(renderer):
    full = renderer.gbuffer()
    g = GBuffer.empty(*CAM.shape)
    g.albedo[:] = 0.5
    out = renderer.resolve_window(g, WIN)
    assert out is g
    r0, r1, c0, c1 = WIN
    sl = (slice(r0, r1), slice(c0, c1))
    for name in ("albedo", "normal", "depth", "coverage", "weight"):
        np.testing.assert_array_equal(getattr(g, name)[sl], getattr(full, name)[sl], err_msg=name)
    outside = np.ones(CAM.shape, bool)
    outside[sl] = False
    assert np.all(g.albedo[outside] == 0.5) and not g.coverage[outside].any()
    whole = renderer.resolve_window(GBuffer.empty(*CAM.shape))
    np.testing.assert_array_equal(whole.albedo, full.albedo)


@pytest.mark.parametrize("shading", ["phong", "none"])
def test_shade_window_and_origin_equal_the_slice_of_the_whole_image(renderer, shading):
    g = renderer.gbuffer()
    whole = shade(g, CAM, shading, background=(0.1, 0.2, 0.3))
    r0, r1, c0, c1 = WIN
    part = shade(g, CAM, shading, background=(0.1, 0.2, 0.3), window=WIN)
    np.testing.assert_array_equal(part, whole[r0:r1, c0:c1])
    # a G-buffer cut out of the image at (r0, c0), shaded with its origin
    cut = GBuffer(*(np.ascontiguousarray(a[r0:r1, c0:c1]) for a in (g.albedo, g.normal, g.depth, g.coverage, g.weight)))
    moved = shade(cut, CAM, shading, background=(0.1, 0.2, 0.3), origin=(r0, c0))
    np.testing.assert_array_equal(moved, whole[r0:r1, c0:c1])


def test_bad_windows_and_sizes_raise(renderer):
    g = renderer.gbuffer()
    with pytest.raises(InputError, match="window"):
        shade(g, CAM, window=(0, 99, 0, 4))
    with pytest.raises(InputError, match="window"):
        renderer.resolve_window(GBuffer.empty(*CAM.shape), (3, 2, 0, 4))
    with pytest.raises(InputError, match="gbuffer"):
        renderer.resolve_window(GBuffer.empty(4, 4))
    assert parse_size("64x48") == (64, 48)
    with pytest.raises(InputError, match="--size"):
        parse_size("64by48")
