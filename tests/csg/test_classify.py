"""Inside/outside classification (4.1.1, Algorithm 4.3) against exact implicit functions."""

import numpy as np

from unmesh import SurfelCloud
from unmesh.csg import inside, inside_patch
from unmesh.csg.classify import tri_and, tri_or

from .analytic import Prim, evaluate


def test_three_valued_logic_4_9_4_10():
    u = np.int8(-1)
    vals = np.array([1, 0, -1], dtype=np.int8)
    for b in vals:
        assert tri_or(np.array([b]), np.array([u]))[0] == b
        assert tri_and(np.array([b]), np.array([u]))[0] == b
    assert tri_or(np.array([1]), np.array([0]))[0] == 1 and tri_and(np.array([1]), np.array([0]))[0] == 0


def test_inside_matches_exact_csg_of_spheres_and_halfspaces():
    s1 = Prim("S", (0, 0, 0), 0.8, "s1")
    s2 = Prim("S", (0.5, 0.2, 0), 0.5, "s2")
    h = Prim("H", (0, 0, 0.3), (0, 0.3, 1), "h")
    tree = ("|", ("-", s1, s2), ("&", h, Prim("S", (-0.6, 0, 0), 0.5, "s3")))
    model = evaluate(tree, lambda p: p.patch(0.04))
    rng = np.random.default_rng(1)
    x = rng.uniform(-1.2, 1.2, (4000, 3))
    # points at least 0.03 from every boundary (tangent-plane error of 0.04 sampling is ~1e-3)
    far = np.min([np.abs(p.value(x)) for p in (s1, s2, h, Prim("S", (-0.6, 0, 0), 0.5, "s3"))], axis=0) > 0.03
    x = x[far]
    exact = evaluate(tree, lambda p: p.value(x) < 0)
    assert np.array_equal(inside(model, x), exact)
    assert np.array_equal(inside(model, x, rule="closest"), exact)


def fig41_corner(h1=0.05, h2=0.08, off1=0.01, off2=0.06):
    """Figure 4.1: a right-angled convex edge of one patch, {x < 0} n {z < 0}, whose two faces
    are sampled differently (spacings ``h1``, ``h2``, first rows ``off1``, ``off2`` from the edge)."""
    y1 = np.arange(-0.6, 0.6, h1)
    top = np.array([[-a, y, 0.0] for a in np.arange(0, 1, h1) + off1 for y in y1])
    y2 = np.arange(-0.6, 0.6, h2)
    side = np.array([[0.0, y, -a] for a in np.arange(0, 1, h2) + off2 for y in y2])
    pos = np.concatenate([top, side])
    nrm = np.concatenate([np.tile([0, 0, 1.0], (len(top), 1)), np.tile([1.0, 0, 0], (len(side), 1))])
    return SurfelCloud(pos, nrm, radii=np.full(len(pos), 0.1))


def test_two_surfel_rule_beats_closest_surfel_at_a_differently_sampled_edge_fig_4_1():
    cloud = fig41_corner()
    rng = np.random.default_rng(0)
    x = rng.uniform([-0.3, -0.4, -0.3], [0.3, 0.4, 0.3], (20000, 3))
    exact = (x[:, 0] < 0) & (x[:, 2] < 0)
    wrong1 = int((inside_patch(cloud, x, "closest") != exact).sum())
    wrong2 = int((inside_patch(cloud, x, "two") != exact).sum())
    print(f"Fig 4.1 edge, misclassified of 20000: closest surfel {wrong1}, two surfels {wrong2}")
    assert wrong1 > 100 and wrong2 < 0.6 * wrong1
    # the concave edge (the complement, normals inwards) is the mirror case of the rule
    inv = cloud.replace(normals=-cloud.normals)
    assert int((inside_patch(inv, x, "two") == exact).sum()) == wrong2
