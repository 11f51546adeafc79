"""Moving-least-squares surfaces of surfel clouds (thesis section 3.1).

* :func:`project` — orthogonal projection onto the MLS surface (3.1–3.8): the
  simplified weighted-average plane fit of Adamson and Alexa (3.5–3.7) with the
  Hermite (3.8) or covariance (3.5) normal, followed by default by Levin's second
  step with a quadratic height field (3.3–3.4), which removes the curvature bias of
  the plane fit (``σ²/(2R)`` inside a sphere of radius R).
* :func:`inside` — inside/outside test (3.9, sign corrected).
* :func:`intersect` — first ray–surface intersection (Algorithm 3.1) for many rays,
  with normals, for ray-cast rendering.
* :func:`interpolate` — MLS-weighted interpolation of any per-surfel attribute
  (colours, scalars) at arbitrary points, with the weights of the local fit.
* :class:`MLSSurface` — the kernel options plus prepared search grids; build one for
  repeated queries on the same cloud.

Weights are ``w_i(x) = φ(‖x − x_i‖/σ_i)`` with the clipped Gaussian (3.11) or
Wendland C² (3.12) kernel of :mod:`unmesh.kernels`, per-sample widths
``σ_i = sigma_factor·r_i`` (default 2 surfel radii) or an explicit ``sigma``, and
support ``cutoff·σ_i`` (default 3). Neighbours come from cell grids of
:mod:`unmesh.spatial`, one per power-of-two band of the supports, so clouds whose
radii vary (mesh samplings, scans) cost what their local kernels need.

Example
-------
>>> import numpy as np
>>> from unmesh import mls
>>> from unmesh.surfels import SurfelCloud
>>> rng = np.random.default_rng(0)
>>> n = rng.normal(size=(4000, 3)); n /= np.linalg.norm(n, axis=1, keepdims=True)
>>> sphere = SurfelCloud(n, n, radii=np.full(len(n), 0.06))
>>> p, nrm = mls.project(sphere, [[0.0, 0.0, 1.1]])
>>> bool(abs(np.linalg.norm(p) - 1) < 2e-3)
True
>>> mls.inside(sphere, [[0, 0, 0.95], [0, 0, 1.05]]).tolist()
[True, False]
>>> t, hit = mls.intersect(sphere, [0, 0, 3.0], [0, 0, -1.0])
>>> bool(hit[0]), bool(abs(t[0] - 2) < 2e-3)
(True, True)
>>> mls.interpolate(sphere, [[0.0, 0.0, 1.0]], n[:, 2]).round(2).tolist()  # the height z
[0.99]
"""

from unmesh.mls.operators import inside, interpolate, intersect, project
from unmesh.mls.surface import DEFAULT_SIGMA_FACTOR, MLSSurface, as_surface

__all__ = ["DEFAULT_SIGMA_FACTOR", "MLSSurface", "as_surface", "inside", "interpolate", "intersect", "project"]
