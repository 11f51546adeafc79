"""Point-sampled surfaces: the surfel data model and operators on it (thesis ch. 3).

- :class:`SurfelCloud`: the data model (section 3.2).
- Sampling (section 3.3, chapter 6): :func:`sample_mesh` (LDC sampling of triangle
  meshes), :func:`from_points` (raw points to surfels).
- Estimation: :func:`estimate_normals` (PCA + MST orientation, Hoppe et al. 1992),
  :func:`estimate_radii` (covering splat radii).
- Simplification: :func:`cluster`, :func:`simplify`, :func:`representatives`
  (hierarchical clustering, Pauly et al. 2002).
"""

from unmesh.surfels.cloud import DEFAULT_COLOR, SurfelCloud, tangent_frame
from unmesh.surfels.normals import estimate_normals, orient_normals, pca_normals
from unmesh.surfels.radii import estimate_radii
from unmesh.surfels.sampling import from_points, sample_mesh
from unmesh.surfels.simplify import cluster, representatives, simplify

__all__ = [
    "DEFAULT_COLOR",
    "SurfelCloud",
    "cluster",
    "estimate_normals",
    "estimate_radii",
    "from_points",
    "orient_normals",
    "pca_normals",
    "representatives",
    "sample_mesh",
    "simplify",
    "tangent_frame",
]
