"""Figure helpers shared by the gallery examples.

Example
-------
>>> import numpy as np
>>> tile([np.zeros((2, 3, 3)), np.zeros((2, 3, 3))], columns=2, pad=1).shape
(4, 9, 3)
"""

from __future__ import annotations

import numpy as np

__all__ = ["tile"]


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
