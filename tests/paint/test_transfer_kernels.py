"""The paint event's fused kernels (_transfer_kernels) against their numpy references in
unmesh.paint.transfer: bit for bit, but for the plane projections of near_rows and
hidden_fathers (round-off: numpy's matrix products round differently), and a whole stroke with
every kernel swapped for its reference (the same surface and brush, bit for bit)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import unmesh.paint.transfer as transfer_module
from tests.paint.conftest import line
from unmesh.paint import Brush, Paint, PaintOptions, Session
from unmesh.paint import _transfer_kernels as tk
from unmesh.paint.session import FIELDS
from unmesh.paint.transfer import (
    blend_props_reference,
    brush_pixels_reference,
    brush_write_back_reference,
    child_frames,
    child_frames_reference,
    hidden_fathers,
    hidden_fathers_reference,
    merge_orphans,
    near_rows,
    near_rows_reference,
    pixel_state,
    pixel_state_reference,
    pixels_near_reference,
    plane_frame,
    replaced_pixels_reference,
)


def _plane(rng):
    N = rng.normal(size=3)
    N /= np.linalg.norm(N)
    t1, t2 = plane_frame(N)
    return rng.normal(size=3) * 0.1, N, t1, t2


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_near_rows_equal_the_reference_to_round_off():
    rng = np.random.default_rng(5)
    for n in (0, 1, 7, 3000):
        pos, nrm, rad = rng.normal(size=(4000, 3)), _unit(rng, 4000), rng.random(4000)
        rows = np.sort(rng.choice(4000, n, replace=False)).astype(np.int64)
        o, N, t1, t2 = _plane(rng)
        got = near_rows(rows, pos, nrm, rad, o, N, t1, t2, 0.8)
        want = near_rows_reference(rows, pos, nrm, rad, o, N, t1, t2, 0.8)
        for g, w in zip(got[:4], want[:4], strict=True):
            np.testing.assert_array_equal(g, w)
        np.testing.assert_allclose(got[4], want[4], rtol=0, atol=1e-15 * 8)
        assert got[4].shape == (len(got[0]), 2)


def test_hidden_fathers_equal_the_reference_to_round_off():
    rng = np.random.default_rng(6)
    no = 3000
    pos, nrm = rng.normal(size=(5000, 3)), _unit(rng, 5000)
    for n_rep in (0, 1, 500):
        active = rng.random(5000) < 0.7
        fathers = rng.choice(no, 1200, replace=False).astype(np.int64)  # unsorted, like a ball query
        replaced = rng.choice(5000, n_rep, replace=False).astype(np.int64)  # originals and children
        o, N, t1, t2 = _plane(rng)
        fi, fu = hidden_fathers(fathers, replaced, no, active, pos, nrm, o, N, t1, t2)
        ri, ru = hidden_fathers_reference(fathers, replaced, no, active, pos, nrm, o, N, t1, t2)
        np.testing.assert_array_equal(fi, ri)
        np.testing.assert_allclose(fu, ru, rtol=0, atol=1e-15 * 8)


def _buffer_case(rng, R=600, W=37, H=29, h=0.05):
    lo0, lo1 = -0.5 * W * h + 0.013, -0.5 * H * h - 0.021
    ou = np.stack([rng.uniform(lo0 - 0.3, lo0 + W * h + 0.3, R), rng.uniform(lo1 - 0.3, lo1 + H * h + 0.3, R)], axis=1)
    rad_r = rng.uniform(0.2, 2.0, R) * h
    own = rng.integers(0, R, W * H).astype(np.int64)
    pen = rng.random(W * H) < 0.3
    covered = pen | (rng.random(W * H) < 0.6)
    return own, pen, covered, ou, rad_r, lo0, lo1, W, H, h


def test_replaced_pixels_equal_the_reference_bit_for_bit():
    rng = np.random.default_rng(7)
    for _ in range(4):
        case = _buffer_case(rng)
        for g, w in zip(tk.replaced_pixels(*case), replaced_pixels_reference(*case), strict=True):
            assert g.dtype == w.dtype
            np.testing.assert_array_equal(g, w)


def test_pixels_near_equals_the_reference():
    rng = np.random.default_rng(11)
    for _ in range(4):
        *_, ou, rad_r, lo0, lo1, W, H, h = _buffer_case(rng)
        cu = ((np.arange(W) + 0.5) - 0.5 * W) * h + (lo0 + 0.5 * W * h)
        cv = (0.5 * H - (np.arange(H) + 0.5)) * h + (lo1 + 0.5 * H * h)
        U, V = np.meshgrid(cu, cv)
        pix = np.stack([U.ravel(), V.ravel()], axis=1)
        sel = np.sort(rng.choice(len(rad_r), 80, replace=False)).astype(np.int64)
        # rows whose disc passes exactly through pixel centres
        rad_r[sel[:5]] = np.hypot(pix[7, 0] - ou[sel[:5], 0], pix[7, 1] - ou[sel[:5], 1])
        skip = rng.random(W * H) < 0.4
        args = (ou, rad_r, sel, pix, skip, lo0, lo1, W, H, h)
        got = tk.pixels_near(*args)
        np.testing.assert_array_equal(got, pixels_near_reference(*args))
        assert 7 in got or skip[7]


def test_pixel_state_equals_the_reference_bit_for_bit(plane_cloud):
    rng = np.random.default_rng(8)
    s = Session(plane_cloud, PaintOptions(haptics=False)).surface
    n = s.n
    for name in ("wet", "dry", "vw", "vd", "rho", "kappa", "diff", "refl", "shin", "metal"):
        s._data[name][:n] = rng.random(s._data[name][:n].shape)
    own, pen, covered, ou, rad_r, lo0, lo1, W, H, h = _buffer_case(rng)
    rows = np.sort(rng.choice(n, len(rad_r), replace=False)).astype(np.int64)
    _, _, Q, npix = replaced_pixels_reference(own, pen, covered, ou, rad_r, lo0, lo1, W, H, h)
    pix = rng.normal(size=(W * H, 2))
    for g, w in zip(pixel_state(s, Q, own, rows, npix, pix), pixel_state_reference(s, Q, own, rows, npix, pix),
                    strict=True):
        assert g.dtype == w.dtype and g.shape == w.shape
        np.testing.assert_array_equal(g, w)


def test_child_frames_equal_the_reference_bit_for_bit(plane_cloud):
    rng = np.random.default_rng(10)
    s = Session(plane_cloud, PaintOptions(haptics=False)).surface
    n = s.n
    s._data["lift"][:n] = rng.random(n) * 0.01
    s._data["father"][:n] = rng.integers(0, n, n)
    rq = rng.integers(0, n, 700).astype(np.int64)
    pu = rng.normal(size=(700, 2))
    o, _, t1, t2 = _plane(rng)
    for g, w in zip(child_frames(s, rq, pu, o, t1, t2), child_frames_reference(s, rq, pu, o, t1, t2), strict=True):
        assert g.shape == w.shape
        np.testing.assert_array_equal(g, w)


def test_brush_kernels_equal_the_references_bit_for_bit():
    rng = np.random.default_rng(9)
    nb, npx = 300, 900
    sel = np.sort(rng.choice(nb, 120, replace=False)).astype(np.int64)
    Q = np.sort(rng.choice(npx, 400, replace=False)).astype(np.int64)
    P = rng.random(len(Q)) < 0.6
    bown = rng.integers(0, len(sel), npx).astype(np.int64)
    depth = rng.normal(size=npx) * 0.02
    wet, vw = rng.random((nb, 3)), rng.random(nb)
    args = (Q, P, bown, depth, sel, wet, vw, 0.7, 0.015)
    got, want = tk.brush_pixels(*args), brush_pixels_reference(*args)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)
    bsel = got[0]
    vb2 = rng.random(len(bsel))
    vb2[bsel == bsel[0]] = 0.0  # a brush surfel left empty keeps its colour
    cb2 = rng.random((len(bsel), 3))
    w1, v1, w2, v2 = wet.copy(), vw.copy(), wet.copy(), vw.copy()
    tk.brush_write_back(bsel, vb2, cb2, w1, v1)
    brush_write_back_reference(bsel, vb2, cb2, w2, v2)
    np.testing.assert_array_equal(w1, w2)
    np.testing.assert_array_equal(v1, v2)
    props = rng.random((6, len(Q)))
    Pi, fb, values = np.flatnonzero(P), rng.random(int(P.sum())), rng.random(6)
    p1, p2 = props.copy(), props.copy()
    tk.blend_props(p1, Pi, fb, values)
    blend_props_reference(p2, Pi, fb, values)
    np.testing.assert_array_equal(p1, p2)


def _paint(plane_cloud):
    s = Session(plane_cloud, PaintOptions(haptics=False))
    for brush, paint in ((Brush("round", 0.04), Paint("oil", (0.9, 0.1, 0.1))),
                         (Brush("flat", 0.03), Paint("watercolor", (0.1, 0.2, 0.9))),
                         (Brush("round", 0.04), Paint("metallic", (0.9, 0.7, 0.2)))):
        sid = s.begin_stroke(brush, paint)
        s.add_samples(sid, line(n=6, pressure=0.9))
        s.end_stroke(sid)
    return s


def test_paint_event_with_the_references_paints_the_same(plane_cloud, monkeypatch):
    got = _paint(plane_cloud)
    monkeypatch.setattr(transfer_module, "near_rows", near_rows_reference)
    monkeypatch.setattr(transfer_module, "hidden_fathers", hidden_fathers_reference)
    monkeypatch.setattr(transfer_module, "pixel_state", pixel_state_reference)
    monkeypatch.setattr(transfer_module, "child_frames", child_frames_reference)
    monkeypatch.setattr(transfer_module, "merge_orphan_rows", lambda s, ks, rr, cw, vw, dc, vd, props: merge_orphans(
        s, ks, rr, cw, vw, dc, vd, dict(zip(transfer_module._PROPS, props, strict=True))))
    # ownership of every pixel (not only where the brush covers the buffer, then around the
    # replaced surfels): the pixels left out own nothing that is used
    monkeypatch.setattr(transfer_module, "tk", SimpleNamespace(
        replaced_pixels=replaced_pixels_reference, brush_pixels=brush_pixels_reference,
        brush_write_back=brush_write_back_reference, blend_props=blend_props_reference,
        pixels_near=lambda ou, rad_r, sel, pix, skip, *a: np.flatnonzero(~skip)))
    want = _paint(plane_cloud)
    assert got.surface.n == want.surface.n > got.surface.n_original
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(got.surface, name), getattr(want.surface, name), err_msg=name)


@pytest.mark.parametrize("k", [0, 5])
def test_near_rows_of_an_empty_or_far_plane(k):
    pos = np.zeros((10, 3))
    nrm = np.tile([0.0, 0.0, 1.0], (10, 1))
    rows = np.arange(k, dtype=np.int64)
    o, N = np.array([0.0, 0.0, 5.0]), np.array([0.0, 0.0, 1.0])
    t1, t2 = plane_frame(N)
    got = near_rows(rows, pos, nrm, np.ones(10), o, N, t1, t2, 1.0)
    assert all(len(a) == 0 for a in got)
