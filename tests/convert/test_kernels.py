"""The patch kernels against their numpy references."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh.convert._patch_kernels import bilinear, bilinear_reference, footprint_reference, footprints


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.0, 12.0), min_size=6, max_size=6), st.integers(2, 14), st.integers(2, 14))
def test_footprints_match_reference(coords, w, h):
    corners = np.array(coords).reshape(1, 3, 2)
    offs = np.array([0, w * h])
    out = np.zeros(w * h, bool)
    footprints(corners, np.array([w]), np.array([h]), offs, out)
    assert (out.reshape(h, w) == footprint_reference(corners[0], w, h)).all()


def test_footprint_is_the_triangle_dilated_by_one_texel():
    # a right triangle with legs 4 on texel corners (1,1)-(5,1)-(1,5) in (col,row)
    corners = np.array([[1.0, 5.0], [5.0, 5.0], [1.0, 1.0]])
    m = footprint_reference(corners, 7, 7)
    # every texel a bilinear lookup inside the triangle reads is in the mask
    rng = np.random.default_rng(0)
    b = rng.dirichlet(np.ones(3), 2000)
    pts = b @ corners
    for x, y in pts:
        i0, j0 = int(np.floor(x - 0.5)), int(np.floor(y - 0.5))
        for i in (i0, i0 + 1):
            for j in (j0, j0 + 1):
                if 0 <= i < 7 and 0 <= j < 7:
                    assert m[j, i]
    # and texels farther than one texel from the triangle are not
    assert not m[0, 6] and m.sum() < 7 * 7


def test_bilinear_matches_reference():
    rng = np.random.default_rng(1)
    img = rng.random((9, 13, 3))
    cols = rng.uniform(-1, 14, 500)
    rows = rng.uniform(-1, 10, 500)
    out = np.empty((500, 3))
    bilinear(img, cols, rows, out)
    assert np.allclose(out, bilinear_reference(img, cols, rows))
    # texel centres are exact
    out1 = np.empty((1, 3))
    bilinear(img, np.array([3.5]), np.array([2.5]), out1)
    assert np.allclose(out1[0], img[2, 3])


def test_candidate_pairs_and_pair_frames_match_references():
    from unmesh.convert._patch_kernels import candidate_pairs, candidate_pairs_reference, pair_frames
    from unmesh.shapes import Sphere

    mesh = Sphere().mesh(0.5)
    rng = np.random.default_rng(4)
    pos = rng.normal(size=(300, 3))
    nrm = rng.normal(size=(300, 3))
    nearest = rng.integers(0, len(mesh.faces), 300)
    fn = mesh.face_normals()
    pt, ps = candidate_pairs(mesh.faces, len(mesh.vertices), nearest, nrm, fn)
    assert sorted(zip(pt.tolist(), ps.tolist(), strict=True)) == candidate_pairs_reference(mesh.faces, len(mesh.vertices), nearest, nrm, fn)
    rot = np.linalg.qr(rng.normal(size=(len(mesh.faces), 3, 3)))[0]
    origin = rng.normal(size=(len(mesh.faces), 3))
    loc = np.empty((len(pt), 3))
    ln = np.empty((len(pt), 3))
    pair_frames(pt, ps, origin, rot, pos, nrm, loc, ln)
    assert np.allclose(loc, np.einsum("pij,pj->pi", rot[pt], pos[ps] - origin[pt]))
    assert np.allclose(ln, np.einsum("pij,pj->pi", rot[pt], nrm[ps]))
