"""Deferred shading: numba kernel vs numpy reference; lights; two-sided; no shading."""

from __future__ import annotations

import numpy as np
import pytest

from unmesh.errors import InputError
from unmesh.render import Camera, GBuffer, Light, Shading, shade
from unmesh.render._reference import shade_reference
from unmesh.render.shading import RenderResult, background_color


@pytest.mark.parametrize("shininess", [20, 7.5])  # integral exponents by repeated squaring, others by pow
@pytest.mark.parametrize("ortho", [False, True])
def test_kernel_matches_reference(rng, ortho, shininess):
    h, w = 20, 30
    cam = Camera((0.5, 1, 3), (0, 0, 0), width=w, height=h, fov=None if ortho else 50, ortho=2.0 if ortho else None)
    n = rng.normal(size=(h, w, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    g = GBuffer(rng.random((h, w, 3)), n, rng.uniform(1, 4, (h, w)), rng.random((h, w)) < 0.8, np.ones((h, w)))
    lights = (Light((-1, 1, -1)), Light((0.2, -1, 0.3), color=(1, 0.5, 0.2), intensity=0.4, space="world"))
    sh = Shading("phong", lights, ambient=0.2, specular=0.3, shininess=shininess)
    out = shade(g, cam, sh, background=(0.1, 0.2, 0.3))
    dirs = np.array([li.world_direction(cam) for li in lights])
    cols = np.array([li.color * li.intensity for li in lights])
    ref = shade_reference(g.albedo, g.normal, g.coverage, cam, dirs, cols, 0.2, 0.3, shininess, np.array([0.1, 0.2, 0.3]))
    assert np.abs(out - ref).max() < 1e-12


def test_result_in_place_clears_the_background_like_the_copy(rng):
    """``from_gbuffer(copy=False)`` (a kernel) against ``copy=True`` (numpy) on a G-buffer with
    stray values where it is not covered."""
    h, w = 17, 23
    cam = Camera((0, 0, 3), (0, 0, 0), width=w, height=h)
    g = GBuffer(rng.random((h, w, 3)), rng.normal(size=(h, w, 3)), rng.uniform(1, 4, (h, w)), rng.random((h, w)) < 0.6,
                rng.random((h, w)))
    color = rng.random((h, w, 3))
    ref = RenderResult.from_gbuffer(g, cam, color)
    got = RenderResult.from_gbuffer(g.copy(), cam, color, copy=False)
    for key in ("depth", "normal", "weight", "coverage", "albedo"):
        assert np.array_equal(getattr(ref, key), getattr(got, key)), key


def test_two_sided_and_lambert():
    cam = Camera((0, 0, 5), (0, 0, 0), width=2, height=1, ortho=1.0)
    n = np.array([[[0, 0, 1.0], [0, 0, -1.0]]])  # facing the viewer / facing away
    g = GBuffer(np.full((1, 2, 3), 0.5), n, np.full((1, 2), 5.0), np.ones((1, 2), bool), np.ones((1, 2)))
    sh = Shading("phong", (Light((0, 0, -1)),), ambient=0.0, specular=0.0)  # headlight
    out = shade(g, cam, sh)
    assert np.allclose(out, 0.5)  # both sides lit fully
    side = Shading("phong", (Light((1, 0, -1)),), ambient=0.1, specular=0.0)
    assert np.allclose(shade(g, cam, side)[0, 0], 0.5 * (0.1 + np.cos(np.pi / 4)))


def test_no_shading_returns_albedo_and_background():
    cam = Camera((0, 0, 5), (0, 0, 0), width=2, height=1)
    g = GBuffer(np.array([[[0.1, 0.2, 0.3], [0.9, 0.9, 0.9]]]), np.zeros((1, 2, 3)), np.array([[1.0, np.inf]]),
                np.array([[True, False]]), np.ones((1, 2)))
    out = shade(g, cam, "none", background="#000000")
    assert np.allclose(out, [[[0.1, 0.2, 0.3], [0, 0, 0]]])


def test_bad_shading_arguments():
    with pytest.raises(InputError):
        Shading("toon")
    with pytest.raises(InputError):
        Light((0, 0, 0))
    with pytest.raises(InputError):
        background_color("#12")
    with pytest.raises(InputError):
        background_color((2, 0, 0))
    assert background_color(0.5).tolist() == [0.5, 0.5, 0.5]


def test_shade_into_out_equals_a_new_array(rng):
    h, w = 9, 11
    cam = Camera((0, 0, 3), (0, 0, 0), width=w, height=h)
    n = rng.normal(size=(h, w, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    g = GBuffer(rng.random((h, w, 3)), n, rng.uniform(1, 4, (h, w)), rng.random((h, w)) < 0.7, np.ones((h, w)))
    for model in ("phong", "none"):
        out = np.empty((3, 4, 3))
        res = shade(g, cam, model, window=(2, 5, 3, 7), out=out)
        assert res is out
        assert np.array_equal(out, shade(g, cam, model, window=(2, 5, 3, 7)))
    with pytest.raises(InputError, match="out"):
        shade(g, cam, out=np.empty((h, w, 2)))
