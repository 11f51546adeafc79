"""Figure helpers shared by the gallery examples.

Example
-------
>>> import numpy as np
>>> tile([np.zeros((2, 3, 3)), np.zeros((2, 3, 3))], columns=2, pad=1).shape
(4, 9, 3)
>>> nice_step(1.3)
0.2
"""

from __future__ import annotations

import numpy as np

__all__ = ["floor_under", "nice_step", "tile"]


def tile(images: list[np.ndarray], columns: int, pad: int = 4) -> np.ndarray:
    """Images (H,W,3) float of equal size on a white grid of ``columns`` columns, ``pad`` pixels apart.

    Returns
    -------
    ndarray, shape (rows*H + (rows+1)*pad, columns*W + (columns+1)*pad, 3), float64
    """
    h, w = images[0].shape[:2]
    rows = -(-len(images) // columns)
    out = np.ones((rows * h + (rows + 1) * pad, columns * w + (columns + 1) * pad, 3))
    for k, img in enumerate(images):
        r, c = divmod(k, columns)
        out[pad + r * (h + pad):pad + r * (h + pad) + h, pad + c * (w + pad):pad + c * (w + pad) + w] = img
    return out


def nice_step(length: float, lines: int = 8) -> float:
    """A round grid spacing (1, 2 or 5 times a power of ten) giving about ``lines`` lines over ``length``."""
    raw = max(float(length), 1e-12) / lines
    p = 10.0 ** np.floor(np.log10(raw))
    return float(round(min((m * p for m in (1.0, 2.0, 5.0, 10.0)), key=lambda s: abs(np.log(s / raw))), 12))


def floor_under(points: np.ndarray, height: float = 0.0, extent: float = 6.0, **kw: object) -> object:
    """A :class:`unmesh.render.Floor` at ``y = height`` centred under ``points`` (N,3), ``extent``
    times their horizontal size wide, with a round grid spacing; keywords go to ``Floor``."""
    from unmesh.render import Floor

    lo, hi = points.min(axis=0), points.max(axis=0)
    size = float(max(hi[0] - lo[0], hi[2] - lo[2], hi[1] - lo[1], 1e-9))
    centre = 0.5 * (lo + hi)
    kw.setdefault("grid", nice_step(size, 5))
    kw.setdefault("shadow_radius", 0.04 * size)
    kw.setdefault("shadow_falloff", 0.5 * size)
    return Floor(point=(centre[0], height, centre[2]), extent=extent * size, **kw)
