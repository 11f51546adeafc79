"""CSG on point-sampled surfaces (thesis chapter 4, Appendix A).

A model is a tree of smooth surfel *patches* combined by union and intersection (difference
and complement are rewritten with the inversions at the leaves, 4.3). It is rendered by
clipped splatting: per frame the clipping partners of every surfel are found (4.2.1), surfels
are classified as surface, edge or outside (4.1.2), and the fragments of edge surfels are kept
or discarded by Algorithm 4.2 with the two-surfel inside test (4.4) in three-valued logic
(4.9/4.10). Edges stay sharp at any magnification, patches may be sampled at any density, and
patches may move between frames (dynamic CSG).

Main API
--------
``Patch(cloud, name=None, transform=None)``, ``Patch.halfspace(point, normal, extent, spacing)``,
``Patch.from_shape(shape, spacing)``, ``Patch.load(path)``; ``a | b``, ``a & b``, ``a - b``, ``~a``.
``inside(model, points, rule="two") -> (M,) bool``.
``prepare(model) -> CSGFrame`` (classes, partners, clip tree of one frame).
``find_partners(positions, radii, patch, normals, method)``.
``unmesh.render.render(model, camera)`` draws models (drawable kind ``"csg"``) with anything else.

Example
-------
>>> from unmesh.shapes import Sphere
>>> box = Patch.halfspace((0, 0, 0.5), (0, 0, 1), 2.0, 0.1) & Patch.halfspace((0, 0, -0.5), (0, 0, -1), 2.0, 0.1)
>>> carved = box - Patch.from_shape(Sphere(radius=0.3), 0.05)
>>> inside(carved, [[0, 0, 0], [0.6, 0, 0]]).tolist()
[False, True]
"""

from unmesh.csg import draw as _draw  # noqa: F401  (registers the drawable kind "csg")
from unmesh.csg.classify import inside, inside_patch
from unmesh.csg.frame import EDGE, OUTSIDE, SURFACE, CSGFrame, prepare
from unmesh.csg.model import Complement, Intersection, Node, Patch, Union, flatten, normalize
from unmesh.csg.partners import find_partners

__all__ = ["EDGE", "OUTSIDE", "SURFACE", "CSGFrame", "Complement", "Intersection", "Node", "Patch", "Union",
           "find_partners", "flatten", "inside", "inside_patch", "normalize", "prepare"]
