"""Penalty collisions between objects (thesis section 8.2.6, eq. 8.37).

Particles of different objects do not share a lattice, so no elastic forces act
between them. Their SPH interaction force is restricted to its repulsive part:

    F'_ij = ((x̂_ji · F_ij) x̂_ji   if (x_j − x_i)·F_ij > 0,   0 otherwise,

with ``F_ij`` the force particle ``i`` exerts on ``j`` (so "repulsive" = pushing
``j`` away from ``i``). The pressure and viscosity pair forces of the fluid
model are central (along ``x_ij``), so the projection is the identity and the
rule keeps or drops the whole pair force; the decision is symmetric in ``i`` and
``j``, so momentum stays conserved. Fluid–fluid pairs interact fully (fluids of
different objects mix); the rule applies when at least one particle is solid. The
force pass applies it inline (:func:`unmesh.sph._kernels.force_pass`); this module
holds the reference.

Example
-------
>>> import numpy as np
>>> xij = np.array([[1.0, 0, 0], [1.0, 0, 0]])      # x_i - x_j
>>> f_on_i = np.array([[2.0, 1.0, 0], [-2.0, 0, 0]])  # repulsive, attractive
>>> penalty_projection(xij, f_on_i).tolist()
[[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from unmesh._validate import as_array

__all__ = ["penalty_projection"]


def penalty_projection(xij: Any, f_on_i: Any) -> np.ndarray:
    """Eq. (8.37) for forces on ``i`` from ``j``: keep the component along ``x_i − x_j`` if it pushes ``i`` away.

    Parameters
    ----------
    xij : array_like, shape (P, 3)
        ``x_i − x_j`` per pair.
    f_on_i : array_like, shape (P, 3)
        Interaction force on ``i`` (``= −F_ij`` in the thesis' notation).

    Returns
    -------
    ndarray, shape (P, 3)

    Example
    -------
    >>> penalty_projection([[0.0, 1.0, 0.0]], [[0.5, 2.0, 0.0]]).tolist()
    [[0.0, 2.0, 0.0]]
    """
    d = as_array(xij, "xij", (None, 3))
    f = as_array(f_on_i, "f_on_i", (None, 3), length=len(d))
    n = d / np.linalg.norm(d, axis=1, keepdims=True)
    along = np.einsum("ij,ij->i", n, f)
    return np.where(along[:, None] > 0, along[:, None] * n, 0.0)
