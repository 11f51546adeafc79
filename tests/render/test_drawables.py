"""The renderer's contract: the drawable registry, RenderOptions, DrawList, RenderResult and the
discontinuity surfels that reach the splatter as clip information (issue 16)."""

from __future__ import annotations

import ast
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import unmesh.render
from unmesh import Particles, SurfelCloud, TriangleMesh
from unmesh.errors import InputError
from unmesh.render import (
    Camera,
    ClipSurfels,
    DrawList,
    RenderOptions,
    RenderResult,
    SplatOptions,
    collect,
    drawable_kinds,
    register_drawable,
    render,
    unregister_drawable,
)
from unmesh.render.drawables import draw_order

from .conftest import fibonacci_sphere

CAM = Camera((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), width=48, height=40, ortho=3.0)


@dataclass(frozen=True)
class Card:
    """A camera-facing rectangle at camera depth ``z``; ``box = (r0, r1, c0, c1)`` are row and
    column fractions of the image (so it is resolution-independent, as supersampling needs)."""

    box: tuple[float, float, float, float]
    z: float
    color: tuple[float, float, float] = (0.0, 0.0, 1.0)

    def bounds(self) -> np.ndarray:
        return np.zeros((2, 3))


def draw_cards(gbuffer, cards, context):
    """A z-buffered draw function of the new kind, written against the public G-buffer only."""
    h, w = gbuffer.depth.shape
    for card in cards:
        r0, r1, c0, c1 = (round(f * n) for f, n in zip(card.box, (h, h, w, w), strict=True))
        win = (slice(r0, r1), slice(c0, c1))
        nearer = gbuffer.depth[win] > card.z
        gbuffer.depth[win][nearer] = card.z
        gbuffer.albedo[win][nearer] = card.color
        gbuffer.normal[win][nearer] = -context.camera.forward
        gbuffer.coverage[win][nearer] = True
        gbuffer.weight[win][nearer] = 1.0


@pytest.fixture
def card_kind():
    kind = register_drawable("cards", Card, draw_cards, stage="opaque", order=5)
    try:
        yield kind
    finally:
        unregister_drawable("cards")


def test_builtin_kinds_and_draw_order():
    names = [k.name for k in drawable_kinds()]
    assert names[:3] == ["surfels", "meshes", "particles"]
    order = [k.name for k in draw_order()]
    assert order.index("meshes") < order.index("particles") < order.index("surfels")
    assert {k.name: k.stage for k in drawable_kinds()}["surfels"] == "splat"


def test_a_registered_kind_renders_mixed_with_surfels(card_kind):
    """A kind registered from outside the renderer occludes splats per pixel like a mesh, and
    leaves every other pixel of the surfel image unchanged bit for bit."""
    sphere = fibonacci_sphere(3000)
    alone = render(sphere, CAM, shading="none")
    front = Card((5 / 40, 20 / 40, 8 / 48, 30 / 48), z=2.5)  # in front of the unit sphere (camera depth >= 3)
    behind = Card((22 / 40, 38 / 40, 20 / 48, 44 / 48), z=4.5, color=(1.0, 0.0, 0.0))  # behind it
    mixed = render([sphere, [front, behind]], CAM, shading="none")
    assert len(collect([sphere, front, behind]).of_kind("cards")) == 2
    mask_f = np.zeros(CAM.shape, bool)
    mask_f[5:20, 8:30] = True
    mask_b = np.zeros(CAM.shape, bool)
    mask_b[22:38, 20:44] = True
    outside = ~(mask_f | mask_b)
    np.testing.assert_array_equal(mixed.color[outside], alone.color[outside])
    np.testing.assert_array_equal(mixed.depth[outside], alone.depth[outside])
    assert np.all(mixed.color[mask_f] == [0.0, 0.0, 1.0]) and np.all(mixed.depth[mask_f] == 2.5)
    # behind the sphere: the card shows only where the sphere does not cover the pixel
    seen = mask_b & ~alone.coverage
    hidden = mask_b & alone.coverage
    assert seen.sum() > 20 and hidden.sum() > 20
    assert np.all(mixed.color[seen] == [1.0, 0.0, 0.0]) and np.all(mixed.depth[seen] == 4.5)
    np.testing.assert_array_equal(mixed.color[hidden & ~mask_f], alone.color[hidden & ~mask_f])
    # and with the built-in opaque kinds and supersampling
    mesh = TriangleMesh([[-2, -2, -1], [2, -2, -1], [0, 2, -1]], [[0, 1, 2]])
    res = render([mesh, front, Particles([[0.0, 0.0, 1.2]], radii=[0.1])], CAM, supersample=2)
    assert np.all(res.depth[mask_f] == 2.5) and res.depth[30, 24] == 5.0 and 2.7 < res.depth[20, 24] < 2.95


def test_registered_kinds_follow_their_order():
    """Opaque kinds draw in increasing ``order``: an overlay without depth test covers the cards
    when it draws after them and is z-tested away by them when it draws first."""
    a = Card((0, 1, 0, 1), z=3.0, color=(1.0, 0.0, 0.0))

    @dataclass(frozen=True)
    class Overlay(Card):
        pass

    def draw_overlay(gbuffer, objs, context):  # no depth test: whatever is drawn later wins
        for o in objs:
            gbuffer.albedo[:] = o.color
            gbuffer.depth[:] = o.z
            gbuffer.coverage[:] = True

    overlay = Overlay((0, 1, 0, 1), 3.5, (0.0, 1.0, 0.0))
    register_drawable("overlay", Overlay, draw_overlay, order=-1)
    register_drawable("cards", Card, draw_cards, order=5)
    try:
        # other capabilities (convert, csg) may have registered kinds of their own in this process
        mine = {"overlay", "meshes", "cards", "particles"}
        assert [k.name for k in draw_order() if k.name in mine] == ["overlay", "meshes", "cards", "particles"]
        res = render([a, overlay], CAM, shading="none")
        assert np.all(res.color == [1.0, 0.0, 0.0]) and np.all(res.depth == 3.0)  # cards drew last, nearer
        register_drawable("overlay", Overlay, draw_overlay, order=10, replace=True)
        res = render([a, overlay], CAM, shading="none")
        assert np.all(res.color == [0.0, 1.0, 0.0]) and np.all(res.depth == 3.5)  # the overlay drew last
    finally:
        unregister_drawable("overlay")
        unregister_drawable("cards")


def test_register_drawable_errors(card_kind):
    with pytest.raises(InputError, match="already registered"):
        register_drawable("cards", Card, draw_cards)
    with pytest.raises(InputError, match="stage: expected one of opaque, splat"):
        register_drawable("x", Card, draw_cards, stage="late")
    with pytest.raises(InputError, match="draw: expected a callable"):
        register_drawable("x", Card, None)
    with pytest.raises(InputError, match="no drawable kind"):
        unregister_drawable("x")
    with pytest.raises(InputError, match=r"objects\[1\]: expected a SurfelCloud, TriangleMesh, Particles .*cards"):
        collect([Card((0, 1, 0, 1), 1.0), {"not": "drawable"}])


def test_render_options_fold_the_keywords():
    sphere = fibonacci_sphere(800)
    parts = Particles([[0.5, 0.5, 1.2], [-0.4, 0.2, 1.1]], attributes={"speed": [1.0, 2.0]})
    kw = dict(method="splat", shading="phong", background="#102030", color_by="speed", colormap="plasma",
              splat=SplatOptions(kappa=3.0), particle_style="disc", supersample=2)
    opts = RenderOptions.from_keywords(**kw)
    assert opts.color.by == "speed" and opts.color.show_legend and opts.particles.style == "disc"
    assert opts.single_sample().supersample == 1 and opts.single_sample().color.legend is False
    a = render([sphere, parts], CAM, **kw)
    b = render([sphere, parts], CAM, options=opts)
    for name in ("color", "depth", "normal", "coverage", "weight", "albedo"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.color_range == b.color_range
    with pytest.raises(InputError, match=r"either a RenderOptions or keywords, got both .*color_by"):
        render(sphere, CAM, options=opts, color_by="speed")
    with pytest.raises(InputError, match="options: expected RenderOptions"):
        render(sphere, CAM, options={"method": "splat"})
    with pytest.raises(InputError, match="supersample"):
        RenderOptions(supersample=0)
    with pytest.raises(InputError, match="method"):
        render(sphere, CAM, method="trace")
    with pytest.raises(AttributeError):
        opts.method = "raycast"  # frozen


def test_supersampling_passes_one_options_object(monkeypatch):
    """The supersampled render calls ``render`` again with the options object only."""
    import unmesh.render.pipeline as pipeline

    calls = []
    original = pipeline.render

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return original(*args, **kwargs)

    monkeypatch.setattr(pipeline, "render", spy)
    original(fibonacci_sphere(300), CAM, supersample=2, color_by="height")
    assert len(calls) == 1 and set(calls[0]) == {"options"}
    assert calls[0]["options"].supersample == 1 and calls[0]["options"].color.by == "height"


def test_draw_list_and_deprecated_scene_alias():
    d = collect([fibonacci_sphere(10), [Particles([[0.0, 0, 0]])], TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])])
    assert isinstance(d, DrawList) and len(d) == 3 and len(d.clouds) == len(d.meshes) == len(d.particles) == 1
    assert [type(o).__name__ for o in d.all()] == ["SurfelCloud", "TriangleMesh", "Particles"]
    assert len(collect([d, d])) == 6
    for module in (unmesh.render, unmesh.render.pipeline):
        with pytest.warns(DeprecationWarning, match="DrawList"):
            alias = module.Scene
        assert alias is DrawList
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from unmesh.render import DrawList as _  # noqa: F401  (no warning for the new name)


def test_render_result_has_one_home_and_no_import_cycle():
    import unmesh.render.pipeline as pipeline
    import unmesh.render.shading as shading

    assert RenderResult is shading.RenderResult is pipeline.RenderResult
    src = Path(unmesh.render.__file__).parent
    for module in ("splat", "shading", "options", "drawables", "raycast", "raster", "particles"):
        tree = ast.parse((src / f"{module}.py").read_text())
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        assert "unmesh.render.pipeline" not in imported, module
    g = unmesh.render.GBuffer.empty(3, 4)
    g.coverage[1, 2] = True
    g.depth[1, 2] = 2.0
    g.normal[1, 2] = (0, 0, 1)
    g.normal[0, 0] = (1, 0, 0)  # stale data outside the coverage is cleared
    r = RenderResult.from_gbuffer(g, CAM.resized(4, 3), np.zeros((3, 4, 3)), (0.0, 1.0))
    assert r.depth[1, 2] == 2.0 and np.isinf(r.depth[0, 0]) and r.normal[0, 0].tolist() == [0, 0, 0]
    assert r.coverage is not g.coverage and r.color_range == (0.0, 1.0)


def test_discontinuity_surfels_reach_the_splatter_as_clip_surfels(monkeypatch):
    """Discontinuity surfels (4.3) are separated from the surface samples and handed to the
    splatter as ClipSurfels; they draw no colour of their own. Lying on the sphere and facing
    outwards (and the marker off the surface), they cut nothing away here, so the image equals
    the render of the surface samples alone (clipping by them: tests/csg)."""
    import unmesh.render.pipeline as pipeline

    sphere = fibonacci_sphere(2000)
    n = len(sphere)
    flags = np.zeros(n, dtype=np.uint8)
    flags[::9] = 1
    flags[4::9] = 2
    shell = sphere.replace(attributes={"discontinuity": flags})
    marker = SurfelCloud([[0.0, 0.0, 1.5]], [[0.0, 0.0, 1.0]], radii=[0.4], colors=[[1.0, 0.0, 0.0]],
                         attributes={"discontinuity": [1]})
    d = collect([shell, marker])
    assert [len(c) for c in d.clouds] == [int((flags == 0).sum()), 0]
    clip = d.clip_surfels()
    assert isinstance(clip, ClipSurfels) and len(clip) == int((flags != 0).sum()) + 1
    assert clip.kind.tolist() == [*flags[flags != 0].tolist(), 1]
    np.testing.assert_array_equal(clip.positions[-1], [0.0, 0.0, 1.5])

    seen = []
    original = pipeline.SplatRenderer

    class Recording(original):
        def render(self, clouds, opaque=None, clip=None, clip_surfels=None):
            seen.append(clip_surfels)
            return super().render(clouds, opaque=opaque, clip=clip, clip_surfels=clip_surfels)

    monkeypatch.setattr(pipeline, "SplatRenderer", Recording)
    res = render([shell, marker], CAM)
    assert len(seen) == 1 and len(seen[0]) == len(clip)
    np.testing.assert_array_equal(seen[0].normals, clip.normals)
    ref = render(sphere.subset(flags == 0), CAM)
    np.testing.assert_array_equal(res.color, ref.color)
    np.testing.assert_array_equal(res.depth, ref.depth)
    # no discontinuity surfels: no clip information
    seen.clear()
    render(sphere, CAM)
    assert seen == [None]


def test_clip_surfels_validation():
    c = ClipSurfels(np.zeros((1, 3)), [[0, 0, 1]], np.zeros((1, 2, 3)), [2])
    assert c.kind.dtype == np.int8 and len(c) == 1
    with pytest.raises(InputError, match="kind: expected 1 or 2, got 0 at index 0"):
        ClipSurfels(np.zeros((1, 3)), [[0, 0, 1]], np.zeros((1, 2, 3)), [0])
    with pytest.raises(InputError, match="kind: expected shape"):
        ClipSurfels(np.zeros((1, 3)), [[0, 0, 1]], np.zeros((1, 2, 3)), [1, 1])
    assert len(ClipSurfels.from_clouds(fibonacci_sphere(5))) == 0


def test_raycast_joins_clouds_with_different_attributes():
    """Ray casting joins clouds by SurfelCloud.concatenate; their attributes play no part."""
    from unmesh.render.raycast import draw_mls
    from unmesh.render.shading import GBuffer

    g = np.stack(np.meshgrid(np.arange(-8, 9), np.arange(-8, 9)), -1).reshape(-1, 2) * 0.1
    pts = np.c_[g, np.zeros(len(g))]
    nrm = np.tile([0, 0, 1.0], (len(g), 1))
    left, right = pts[:, 0] < 0, pts[:, 0] >= 0
    a = SurfelCloud(pts[left], nrm[left], radii=np.full(left.sum(), 0.1), attributes={"t": np.ones(left.sum())})
    b = SurfelCloud(pts[right], nrm[right], radii=np.full(right.sum(), 0.1), colors=np.tile([1.0, 0, 0], (right.sum(), 1)))
    cam = Camera((0, 0, 2), (0, 0, 0), width=10, height=8, ortho=1.2)
    one, two = GBuffer.empty(8, 10), GBuffer.empty(8, 10)
    draw_mls(one, [a, b], cam)
    draw_mls(two, [SurfelCloud.concatenate([a, b], attributes="none")], cam)
    assert one.coverage.all()
    for name in ("albedo", "normal", "depth", "coverage", "weight"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name))
    assert one.albedo[4, 9, 1] < 0.5 < one.albedo[4, 0, 1]  # red on the right, grey on the left
