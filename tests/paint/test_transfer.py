"""Paint transfer and resampling (5.5): conservation, density, holes, sharp edges."""

import numpy as np

from tests.paint.conftest import RED, ROUND, line
from unmesh.paint import Brush, Paint, PaintOptions, Sample, Session
from unmesh.paint.model import mix, transfer
from unmesh.render import Camera


def _total(s, sid=None):
    v = s.surface.total_volume()
    if sid is not None:
        v += s._open[sid].state.volume()
    return v


def test_transfer_formula_conserves_and_matches_5_11():
    rng = np.random.default_rng(1)
    cs, cb = rng.random((50, 3)), rng.random((50, 3))
    vs, vb = rng.random(50), rng.random(50)
    p = rng.random(50)
    cs2, vs2, cb2, vb2, _ = transfer(cs, vs, cb, vb, 3.0, 5.0, p, 0.1)
    np.testing.assert_allclose(vs2 + vb2, vs + vb, rtol=1e-14)
    ds = (1 - np.exp(-3.0 * p * 0.1)) * vs
    db = (1 - np.exp(-5.0 * p * 0.1)) * vb
    want = ((vs - ds)[:, None] * cs + db[:, None] * cb) / (vs - ds + db)[:, None]  # corrected (5.11)
    np.testing.assert_allclose(cs2, want, rtol=1e-13)
    # pigment amounts (volume x colour) are conserved too
    np.testing.assert_allclose(vs2[:, None] * cs2 + vb2[:, None] * cb2, vs[:, None] * cs + vb[:, None] * cb, rtol=1e-12)
    # no back-transfer: the brush colour stays
    _, _, cb3, _, _ = transfer(cs, vs, cb, vb, 0.0, 5.0, p, 0.1)
    np.testing.assert_allclose(cb3, cb, rtol=1e-14)


def test_kubelka_munk_mix_keeps_pure_and_darkens():
    c, v = mix(np.array([[0.9, 0.9, 0.1]]), np.array([1.0]), np.array([[0.1, 0.1, 0.9]]), np.array([1.0]), km=True)
    rgb, _ = mix(np.array([[0.9, 0.9, 0.1]]), np.array([1.0]), np.array([[0.1, 0.1, 0.9]]), np.array([1.0]))
    assert v[0] == 2.0 and (c[0] < rgb[0]).all()  # subtractive mixing is darker than averaging
    same, _ = mix(np.array([[0.3, 0.6, 0.2]]), np.array([1.0]), np.array([[0.3, 0.6, 0.2]]), np.array([2.0]), km=True)
    np.testing.assert_allclose(same, [[0.3, 0.6, 0.2]], rtol=1e-12)


def test_stroke_conserves_volume_brush_plus_surface(session):
    for paint in (RED, Paint("watercolor", (0.1, 0.2, 0.9)), Paint("metallic", (0.9, 0.7, 0.2))):
        sid = session.begin_stroke(ROUND, paint)
        v0 = _total(session, sid)
        for smp in line(n=4, pressure=0.9):
            session.add_samples(sid, [smp])
            v = _total(session, sid)
            assert abs(v - v0) <= 1e-12 * v0
        session.end_stroke(sid)
    # painting through wet paint with back-transfer also conserves
    sid = session.begin_stroke(Brush("flat", 0.03), Paint("oil", (0.1, 0.8, 0.1)))
    v0 = _total(session, sid)
    session.add_samples(sid, [Sample(0.05 * i, (0.0, 0.0, -0.1 + 0.05 * i), 1.0) for i in range(5)])
    assert abs(_total(session, sid) - v0) <= 1e-12 * v0


def test_density_rises_only_where_painted(session):
    s = session
    before = s.surface.visible_rows()
    pos0 = s.surface.pos[before].copy()
    s.stroke(line(n=10, x0=-0.25, x1=0.25), brush=ROUND, paint=RED)
    rows = s.surface.visible_rows()
    kids = rows[rows >= s.surface.n_original]
    assert len(kids) > 2 * len(before) - len(rows) - len(kids) or len(kids) > 100
    # children only near the stroke (within a brush radius plus two original spacings)
    kp = s.surface.pos[kids]
    assert np.abs(kp[:, 2]).max() < 0.04 + 2 * 0.04 * 1.5
    assert kp[:, 0].min() > -0.25 - 0.12 and kp[:, 0].max() < 0.25 + 0.12
    # far from the stroke the originals are untouched and still active
    far = np.abs(pos0[:, 2]) > 0.2
    assert s.surface.active[before[far]].all()
    # where paint landed, the sampling is denser than the originals
    painted = kids[s.surface.vw[kids] > 0]
    assert len(painted) > 0
    assert s.surface.rad[painted].max() < 0.5 * s.surface.rad[:s.surface.n_original].min()


def test_painted_region_has_no_holes_at_8x(session):
    s = session
    s.stroke(line(n=10, x0=-0.2, x1=0.2), brush=ROUND, paint=RED)
    # 8x magnification: pixels 8 times smaller than the original spacing (0.04 / 8)
    px = 0.04 / 8
    cam = Camera((0, 1.0, 0), (0, 0, 0), up=(0, 0, -1), width=int(0.5 / px), height=int(0.16 / px), ortho=0.16)
    r = s.render(cam, brush=False, full=True)
    assert r.coverage.all()


def test_sharp_edges_finer_than_the_sampling(plane_cloud):
    # a pencil line much narrower than the original spacing (0.04): colour across it falls
    # from painted to bare within a few paint-buffer pixels
    s = Session(plane_cloud, PaintOptions(haptics=False))
    pencil = Brush("pencil", 0.015)
    s.stroke([Sample(0.05 * i, (-0.06 + 0.04 * i, 0.0, 0.0), 1.0) for i in range(4)], brush=pencil,
             paint=Paint("oil", (0.0, 0.0, 0.0), density=20.0))
    s.advance(200.0)  # dry: opaque
    rows = s.surface.visible_rows()
    p = s.surface.pos[rows]
    c = s.surface.colors(rows)
    mid = np.abs(p[:, 0]) < 0.04
    dark = mid & (c.sum(axis=1) < 0.5)
    assert dark.sum() > 20
    width = p[dark, 2].max() - p[dark, 2].min()
    assert width < 0.04  # narrower than one original spacing
    zc = 0.5 * (p[dark, 2].max() + p[dark, 2].min())
    bare = mid & (np.abs(p[:, 2] - zc) > width / 2 + 0.01) & (np.abs(p[:, 2] - zc) < 0.05)
    assert bare.sum() > 10
    assert (c[bare].sum(axis=1) > 2.0).all()  # untouched light grey right next to it


def test_plane_frame_is_tangent_frame_bit_for_bit():
    from unmesh.paint.transfer import plane_frame
    from unmesh.surfels import tangent_frame

    rng = np.random.default_rng(7)
    n = rng.standard_normal((300, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[:3] = np.eye(3)
    for v in n:
        t1, t2 = plane_frame(v)
        r1, r2 = tangent_frame(v[None])
        assert np.array_equal(t1, r1[0]) and np.array_equal(t2, r2[0])


def test_orphan_merge_at_once_equals_one_after_the_other():
    """The surfels that own no pixel are merged into distinct pixels at once, with the arithmetic
    of merging them one by one (replays stay byte-identical)."""
    from unmesh import SurfelCloud
    from unmesh.paint.surface import PaintSurface
    from unmesh.paint.transfer import _PROPS, _merge_orphans, merge_orphan_rows, merge_orphans

    rng = np.random.default_rng(3)
    m = 40
    surf = PaintSurface(SurfelCloud(rng.random((m, 3)), np.tile([0.0, 0.0, 1.0], (m, 1)), radii=np.full(m, 0.1)))
    for f in ("vw", "vd", *_PROPS):
        getattr(surf, f)[:] = rng.random(m) * (rng.random(m) > 0.3)
    surf.wet[:] = rng.random((m, 3))
    surf.dry[:] = rng.random((m, 3))
    q = 25
    start = (rng.random((q, 3)), rng.random(q) * (rng.random(q) > 0.3), rng.random((q, 3)),
             rng.random(q) * (rng.random(q) > 0.3), {f: rng.random(q) for f in _PROPS})
    ks = rng.permutation(q)[:12]
    rr = rng.permutation(m)[:12]
    ks_dup = rng.integers(0, 5, 30)  # several rows per pixel
    rr_dup = rng.integers(0, m, 30)

    def state():
        cw, vw, dc, vd, props = start
        return cw.copy(), vw.copy(), dc.copy(), vd.copy(), {f: v.copy() for f, v in props.items()}

    a, b = state(), state()
    _merge_orphans(surf, ks, rr, *a)
    for j in range(len(ks)):
        _merge_orphans(surf, ks[j:j + 1], rr[j:j + 1], *b)
    for x, y in zip(a[:4], b[:4], strict=True):
        assert np.array_equal(x, y)
    for f in _PROPS:
        assert np.array_equal(a[4][f], b[4][f])
    # volume is conserved: the pixels gained exactly the rows' volumes
    np.testing.assert_allclose(a[1].sum() - start[1].sum(), surf.vw[rr].sum(), rtol=1e-12)
    # several rows per pixel: rounds of distinct pixels give the one-after-the-other result
    a, b = state(), state()
    merge_orphans(surf, ks_dup, rr_dup, *a)
    for j in range(len(ks_dup)):
        _merge_orphans(surf, ks_dup[j:j + 1], rr_dup[j:j + 1], *b)
    for x, y in zip(a[:4], b[:4], strict=True):
        assert np.array_equal(x, y)
    for f in _PROPS:
        assert np.array_equal(a[4][f], b[4][f])
    # the kernel merging one after the other (paint_event's) gives the same
    c = state()
    props = np.stack([c[4][f] for f in _PROPS])
    merge_orphan_rows(surf, ks_dup, rr_dup, c[0], c[1], c[2], c[3], props)
    for x, y in zip(a[:4], c[:4], strict=True):
        assert np.array_equal(x, y)
    for i, f in enumerate(_PROPS):
        assert np.array_equal(a[4][f], props[i])
