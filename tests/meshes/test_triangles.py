import numpy as np
import pytest

from unmesh import TriangleMesh
from unmesh.errors import InputError


def tetra():
    v = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    f = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
    return TriangleMesh(v, f)


def test_tetra_volume_area_normals():
    m = tetra()
    assert m.volume() == pytest.approx(1 / 6)
    assert m.area() == pytest.approx(1.5 + np.sqrt(3) / 2)
    fn = m.face_normals()
    np.testing.assert_allclose(fn[0], [0, 0, -1])
    np.testing.assert_allclose(fn[3], np.ones(3) / np.sqrt(3))
    assert len(m.edges()) == 6 and len(m.boundary_edges()) == 0
    vn = m.computed_vertex_normals()
    np.testing.assert_allclose(np.linalg.norm(vn, axis=1), 1)


def test_transform_with_reflection_keeps_outward_orientation():
    m = tetra().transformed(np.diag([-1.0, 1.0, 1.0]))
    assert m.volume() == pytest.approx(1 / 6)


def test_validation_messages():
    with pytest.raises(InputError, match=r"faces: expected indices in \[0, 3\)"):
        TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    with pytest.raises(InputError, match="uv: expected 3 rows"):
        TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], uv=np.zeros((2, 2)))
    with pytest.raises(InputError, match="texture: expected values in"):
        TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], texture=np.full((2, 2, 3), 2.0))
    with pytest.raises(InputError, match="vertex_normals: expected non-zero"):
        TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], vertex_normals=np.zeros((3, 3)))


def test_texture_uint8_and_open_boundary():
    m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], texture=np.zeros((4, 4, 4), dtype=np.uint8))
    assert m.texture.shape == (4, 4, 3) and m.texture.dtype == np.float64
    assert len(m.boundary_edges()) == 3
