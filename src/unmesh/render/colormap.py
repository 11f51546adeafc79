"""Colormaps, attribute colouring and colour-bar legends.

The maps are 17-point samples of the well-known matplotlib maps (viridis, magma, plasma,
inferno, cividis, coolwarm, turbo) plus ``gray``, interpolated linearly; no plotting library is
needed. :func:`attribute_values` turns any per-element attribute into one scalar per element
(vectors by their length), :func:`map_colors` maps scalars through a colormap and
:func:`draw_legend` paints a labelled colour bar into an image.

Example
-------
>>> colormap("viridis")(np.array([0.0, 1.0])).round(3).tolist()
[[0.267, 0.004, 0.329], [0.992, 0.906, 0.145]]
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from unmesh.errors import InputError

__all__ = ["COLORMAPS", "attribute_values", "colormap", "draw_legend", "map_colors", "value_range"]

_TABLES = {
    "viridis": "44015448186a472d7b4240863b528b33638d2c728e26828e21918c1fa08828ae803fbc735ec96284d44baddc30d8e219fde725",
    "magma": "0000040a08221d114736106b51127c6a1c818326819c2e7fb73779d0416fe75263f56b5cfc8961fea772fec488fde2a3fcfdbf",
    "plasma": "0d08873105974c02a16600a77e03a89511a1aa2395bc3587cc4778da5a6ae66c5cf0804ef89540fdac33fdc527f8df25f0f921",
    "inferno": "0000040b0724210c4a3d096557106e71196e8a226aa32c61bc3754d24644e45a31f1731df98e09fcac11f9cb35f2ea69fcffa4",
    "coolwarm": "3b4cc04e68d86282ea779af78db0fea3c2feb9d0f9ccd9eddddcdcecd3c5f5c4acf7b093f4987aeb7d62dd5f4bca3b37b40426",
    "turbo": "30123b4040a2466be34294ff28bceb18ddc232f2986dfe62a4fc3ccdec34eecf3afdac34fb7e21eb500ed02f05a916017a0403",
    "cividis": "00224e002e6a1a386f32436d434e6c535a6d61656f6f70737d7c788c88789b9476aba072bcae6ccdbb63dec958f0d846fee838",
    "gray": "000000ffffff",
}


def _table(code: str) -> np.ndarray:
    raw = bytes.fromhex(code)
    return np.frombuffer(raw, dtype=np.uint8).reshape(-1, 3).astype(np.float64) / 255.0


#: Names of the available colormaps.
COLORMAPS: tuple[str, ...] = tuple(_TABLES)


def colormap(name: str = "viridis") -> Callable[[np.ndarray], np.ndarray]:
    """A function mapping values in [0, 1] (any shape) to RGB (shape + (3,)); NaN maps to grey.

    Example
    -------
    >>> colormap("gray")(np.array([0.5]))
    array([[0.5, 0.5, 0.5]])
    """
    key = str(name).lower()
    reverse = key.endswith("_r")
    key = key[:-2] if reverse else key
    if key not in _TABLES:
        raise InputError(f"colormap: expected one of {', '.join(COLORMAPS)} (optionally with '_r'), got {name!r}")
    table = _table(_TABLES[key])
    if reverse:
        table = table[::-1]
    knots = np.linspace(0.0, 1.0, len(table))

    def apply(values: np.ndarray) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64)
        bad = ~np.isfinite(v)
        vc = np.clip(np.where(bad, 0.0, v), 0.0, 1.0)
        out = np.stack([np.interp(vc, knots, table[:, k]) for k in range(3)], axis=-1)
        out[bad] = 0.5
        return out

    return apply


def attribute_values(obj: Any, name: str) -> np.ndarray:
    """One float per element of ``obj`` from attribute ``name``.

    ``obj`` is a SurfelCloud, Particles or TriangleMesh (per-vertex attributes); vector
    attributes (N, k) become their Euclidean length. ``radius``/``radii`` and ``x``/``y``/``z``
    (coordinates) are also accepted.

    Raises
    ------
    unmesh.errors.InputError
        When the attribute does not exist; the message lists the available names.

    Example
    -------
    >>> from unmesh import Particles
    >>> attribute_values(Particles([[0, 0, 0]], attributes={"velocity": [[3.0, 4.0, 0.0]]}), "velocity")
    array([5.])
    """
    attrs = dict(getattr(obj, "attributes", {}) or {})
    pts = getattr(obj, "positions", None)
    if pts is None:
        pts = getattr(obj, "vertices", None)
    if name in attrs:
        arr = np.asarray(attrs[name])
    elif name in ("x", "y", "z") and pts is not None:
        arr = np.asarray(pts)[:, "xyz".index(name)]
    elif name in ("radius", "radii") and getattr(obj, "radii", None) is not None:
        arr = np.asarray(obj.radii)
    else:
        avail = sorted(attrs) + (["x", "y", "z"] if pts is not None else [])
        if getattr(obj, "radii", None) is not None:
            avail.append("radius")
        raise InputError(f"color_by: no attribute {name!r} on {type(obj).__name__}; available: {', '.join(avail) or 'none'}")
    if arr.dtype == bool:
        arr = arr.astype(np.float64)
    if not np.issubdtype(arr.dtype, np.number):
        raise InputError(f"color_by: attribute {name!r} is not numeric (dtype {arr.dtype})")
    arr = arr.astype(np.float64)
    if arr.ndim > 1:
        arr = np.linalg.norm(arr.reshape(len(arr), -1), axis=1)
    return arr


def value_range(arrays: Sequence[np.ndarray], given: Sequence[float] | None = None) -> tuple[float, float]:
    """The ``(lo, hi)`` colour range: ``given``, else the finite min and max over ``arrays``.

    A constant attribute gets a symmetric range around its value so that it maps to mid-colour.

    Example
    -------
    >>> value_range([np.array([1.0, 3.0]), np.array([2.0])])
    (1.0, 3.0)
    """
    if given is not None:
        lo, hi = (float(v) for v in given)
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise InputError(f"color_range: expected two finite numbers lo < hi, got {given!r}")
        return lo, hi
    vals = [a[np.isfinite(a)] for a in arrays if a.size]
    vals = [v for v in vals if v.size]
    if not vals:
        return 0.0, 1.0
    lo = float(min(v.min() for v in vals))
    hi = float(max(v.max() for v in vals))
    if hi <= lo:
        pad = max(abs(lo) * 0.5, 0.5)
        return lo - pad, hi + pad
    return lo, hi


def map_colors(values: np.ndarray, lo: float, hi: float, cmap: str = "viridis") -> np.ndarray:
    """RGB (N,3) for scalar ``values`` (N,) linearly mapped from ``[lo, hi]`` through ``cmap``.

    Example
    -------
    >>> map_colors(np.array([0.0, 10.0]), 0.0, 10.0, "gray")
    array([[0., 0., 0.],
           [1., 1., 1.]])
    """
    return colormap(cmap)((np.asarray(values, dtype=np.float64) - lo) / (hi - lo))


def _format(v: float) -> str:
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1e4 or a < 1e-3:
        return f"{v:.2e}"
    return f"{v:.4g}"


def draw_legend(image: np.ndarray, lo: float, hi: float, cmap: str = "viridis", label: str = "",
                corner: str = "right") -> np.ndarray:
    """Paint a vertical colour bar with ``lo``/``hi`` tick labels and a title into ``image``.

    Parameters
    ----------
    image : (H, W, 3) float array in [0, 1]
    lo, hi : float
        Range of the bar (``hi`` at the top).
    cmap : str
    label : str
        Title drawn above the bar (e.g. the attribute name).
    corner : {"right", "left"}
        Side of the image the bar is drawn on.

    Returns
    -------
    numpy.ndarray
        A new (H, W, 3) float64 image.

    Example
    -------
    >>> img = draw_legend(np.ones((120, 160, 3)), 0.0, 1.0, label="density")
    >>> img.shape, bool((img < 1).any())
    ((120, 160, 3), True)
    """
    from PIL import Image, ImageDraw, ImageFont

    img = np.asarray(image, dtype=np.float64)
    h, w = img.shape[:2]
    if h < 24 or w < 24:
        return img.copy()
    size = max(8, min(h, w) // 28)
    try:
        font: Any = ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType sizes
        font = ImageFont.load_default()
    pil = Image.fromarray((np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8))
    draw = ImageDraw.Draw(pil)
    bar_h = int(h * 0.45)
    bar_w = max(4, w // 40)
    top = int(h * 0.1) + size + 4
    texts = [_format(hi), _format(lo)]
    text_w = max(draw.textlength(t, font=font) for t in texts)
    margin = max(4, w // 50)
    if corner == "left":
        x0 = margin
    else:
        x0 = int(w - margin - bar_w - 4 - text_w)
    x0 = max(0, x0)
    bar = colormap(cmap)(np.linspace(1.0, 0.0, bar_h))
    arr = np.asarray(pil).copy()
    bottom = min(h, top + bar_h)
    arr[top:bottom, x0:x0 + bar_w] = (bar[: bottom - top, None, :] * 255 + 0.5).astype(np.uint8)
    pil = Image.fromarray(arr)
    draw = ImageDraw.Draw(pil)
    ink = (20, 20, 20) if img[top:bottom, x0:].mean() > 0.5 else (235, 235, 235)
    draw.rectangle([x0 - 1, top - 1, x0 + bar_w, bottom], outline=ink)
    draw.text((x0 + bar_w + 4, top - size // 2), texts[0], fill=ink, font=font)
    draw.text((x0 + bar_w + 4, bottom - size // 2 - 1), texts[1], fill=ink, font=font)
    if label:
        lw = draw.textlength(label, font=font)
        lx = min(max(0, x0 + bar_w // 2 - lw / 2), w - lw - 1)
        draw.text((lx, top - size - 6), label, fill=ink, font=font)
    return np.asarray(pil).astype(np.float64) / 255.0
