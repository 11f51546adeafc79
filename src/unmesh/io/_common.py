"""Helpers shared by the format modules: error messages, attribute packing, images.

Attribute convention (PLY vertex properties)
--------------------------------------------
A per-element attribute of shape (N,) is one property named like the attribute.
An (N, k) attribute is stored as the k consecutive properties ``name_0 ... name_{k-1}``
and regrouped on load: every maximal run of consecutive properties ``base_0,
base_1, ..., base_{k-1}`` (same type, numbered from 0 without gaps) becomes one
(N, k) attribute ``base``. Writing refuses attribute names that would not come back
unchanged under this rule (e.g. a scalar attribute called ``w_0``).

PLY has no bool and no 64-bit integers. Their values are stored as ``uchar`` and
``int`` / ``uint`` (refused when out of range) and the original dtype is recorded in
a header comment ``comment unmesh dtype NAME DTYPE`` that other programs ignore and
that :func:`unmesh.io.load` uses to restore the dtype.
"""

from __future__ import annotations

import keyword
import os
import re
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import FormatError, InputError

__all__ = [
    "PLY_TYPES",
    "RECORDED_DTYPES",
    "fail",
    "float32_exact",
    "format_rows",
    "is_file",
    "pack_attributes",
    "ply_type_for",
    "read_image",
    "regroup_attributes",
    "safe_attribute_name",
    "to_uchar_colors",
    "write_png",
]

#: PLY scalar type names (both spellings) -> numpy dtype character codes.
PLY_TYPES: dict[str, str] = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
#: Canonical (classic) PLY name for each numpy code, used when writing.
PLY_NAME: dict[str, str] = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort",
                            "i4": "int", "u4": "uint", "f4": "float", "f8": "double"}

_GROUP = re.compile(r"^(.+)_(\d+)$")

#: The dtypes ``comment unmesh dtype NAME DTYPE`` may restore (those PLY cannot hold).
RECORDED_DTYPES = frozenset({"bool", "int64", "uint64", "float16"})


def is_file(path: Path) -> bool:
    """``path.is_file()``, but False (not OSError) for names the OS refuses (e.g. too long)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def fail(path: str | os.PathLike[str], element: str | None, message: str) -> FormatError:
    """A :class:`FormatError` naming the file and the element.

    Example
    -------
    >>> str(fail("bunny.ply", "vertex", "file ends after 120 of 3000 rows"))
    "bunny.ply: element 'vertex': file ends after 120 of 3000 rows"
    """
    where = f"{os.fspath(path)}: "
    if element is not None:
        where += f"element {element!r}: "
    return FormatError(where + message)


def float32_exact(*arrays: np.ndarray) -> bool:
    """True when every value of the float64 arrays is exactly representable as float32.

    Used to pick ``float`` (4 bytes) or ``double`` for geometry so that what is
    written reads back bit for bit.

    Example
    -------
    >>> float32_exact(np.array([0.5, 0.25])), float32_exact(np.array([0.1]))
    (True, False)
    """
    for a in arrays:
        if a is None or a.size == 0:
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            back = a.astype(np.float32).astype(np.float64)
        if not np.array_equal(back, a, equal_nan=True):
            return False
    return True


def _spec(dtype: np.dtype) -> str:
    if dtype.kind == "f":
        # float32: 9 significant digits read back exactly; float64: Python's shortest repr
        return "%r" if dtype.itemsize == 8 else "%.9g"
    return "%d"


def format_rows(columns: list, prefix: str = "", count: int | None = None) -> list[str]:
    """Text rows ``prefix + "c0 c1 ..."`` of equally long columns; every value reads back exactly.

    float32 columns print with 9 significant digits, float64 columns as Python's
    shortest repr, integers and bools as integers. A column may also be a plain
    string (a constant, e.g. the list length ``"3"``).

    Example
    -------
    >>> format_rows([np.array([0.5, 0.1]), np.array([1, 2], dtype=np.uint8)], prefix="v ")
    ['v 0.5 1', 'v 0.1 2']
    """
    specs: list[str] = []
    lists: list[list] = []
    for col in columns:
        if isinstance(col, str):
            specs.append(col.replace("%", "%%"))
            continue
        arr = np.asarray(col)
        if arr.dtype == bool:
            arr = arr.astype(np.uint8)
        specs.append(_spec(arr.dtype))
        lists.append(arr.tolist())
    fmt = prefix.replace("%", "%%") + " ".join(specs)
    if not lists:
        return [fmt] * (count or 0)
    return [fmt % row for row in zip(*lists, strict=True)]


def ply_type_for(name: str, arr: np.ndarray) -> tuple[str, np.ndarray, str | None]:
    """PLY type code for an attribute array, the values to write and the dtype to record.

    Returns ``(code, values, original)``; ``original`` is the dtype name to record in a
    header comment when PLY cannot hold it natively (bool, int64, uint64, float16).
    """
    dt = arr.dtype
    if dt.kind == "b":
        return "u1", arr.astype(np.uint8), "bool"
    if dt.kind in "iu" and dt.itemsize <= 4:
        return dt.str[1:], arr, None
    if dt.kind in "iu":
        for code, lo, hi in (("i4", -(2**31), 2**31 - 1), ("u4", 0, 2**32 - 1)):
            if arr.size == 0 or (int(arr.min()) >= lo and int(arr.max()) <= hi):
                return code, arr.astype(code), dt.name
        raise InputError(f"attributes[{name!r}]: {dt.name} values outside the 32-bit range cannot be stored in PLY")
    if dt == np.float16:
        return "f4", arr.astype(np.float32), "float16"
    if dt in (np.float32, np.float64):
        return dt.str[1:], arr, None
    raise InputError(f"attributes[{name!r}]: expected a numeric or bool array for PLY, got dtype {dt}")


def pack_attributes(attributes: Mapping[str, np.ndarray], taken: Iterable[str],
                    what: str = "attributes") -> tuple[list[tuple[str, np.ndarray, str]], list[str]]:
    """Flatten attributes to PLY scalar properties following the module convention.

    Parameters
    ----------
    attributes : mapping of str to ndarray (N,) or (N, k)
    taken : iterable of str
        Property names already used by the geometry (refused as attribute names).

    Returns
    -------
    properties : list of (name, values (N,), code)
    comments : list of str
        ``unmesh dtype NAME DTYPE`` comments for dtypes PLY cannot hold.

    Raises
    ------
    InputError
        For names that are not valid PLY property names, clash with the geometry,
        or would not read back unchanged; shapes other than (N,) and (N, k); and
        dtypes PLY cannot store.
    """
    used = set(taken)
    props: list[tuple[str, np.ndarray, str]] = []
    comments: list[str] = []
    layout: list[tuple[str, int | None]] = []
    for name, value in attributes.items():
        arr = np.asarray(value)
        if not name or not name.isascii() or any(c.isspace() for c in name):
            raise InputError(f"{what}[{name!r}]: PLY property names must be non-empty ASCII without spaces")
        if arr.ndim == 1:
            names = [name]
            cols = [arr]
            layout.append((name, None))
        elif arr.ndim == 2 and arr.shape[1] > 0:
            names = [f"{name}_{i}" for i in range(arr.shape[1])]
            cols = [arr[:, i] for i in range(arr.shape[1])]
            layout.append((name, arr.shape[1]))
        else:
            raise InputError(f"{what}[{name!r}]: PLY stores arrays of shape (N,) or (N, k) with k >= 1, got {arr.shape}")
        original = None
        for pname, col in zip(names, cols, strict=True):
            if pname in used:
                raise InputError(f"{what}[{name!r}]: property name {pname!r} is already used by the geometry or another attribute")
            used.add(pname)
            code, values, original = ply_type_for(name, np.ascontiguousarray(col))
            props.append((pname, values, code))
        if original is not None:
            comments.append(f"unmesh dtype {name} {original}")
    # check the round trip of the names under the regrouping rule
    back = _group_names([(p, c) for p, _, c in props])
    if back != layout:
        for (n1, k1), (n2, k2) in zip(back + [("", None)] * len(layout), layout, strict=False):
            if (n1, k1) != (n2, k2):
                raise InputError(f"{what}[{n2!r}]: name would read back as {n1!r}"
                                 f"{'' if k1 is None else f' with {k1} columns'}; rename it "
                                 "(names ending in _<digits> are reserved for (N, k) attributes)")
    return props, comments


def _group_names(props: list[tuple[str, str]]) -> list[tuple[str, int | None]]:
    """Regrouping rule on (name, type code) pairs -> [(attribute, k or None)]."""
    out: list[tuple[str, int | None]] = []
    i = 0
    while i < len(props):
        m = _GROUP.match(props[i][0])
        if m and int(m.group(2)) == 0 and m.group(2) == "0":
            base, code = m.group(1), props[i][1]
            j = i + 1
            while j < len(props) and props[j][0] == f"{base}_{j - i}" and props[j][1] == code:
                j += 1
            out.append((base, j - i))
            i = j
        else:
            out.append((props[i][0], None))
            i += 1
    return out


def regroup_attributes(columns: list[tuple[str, np.ndarray]], dtypes: Mapping[str, str],
                       path: str | os.PathLike[str], element: str,
                       identifiers: bool = False) -> dict[str, np.ndarray]:
    """Inverse of :func:`pack_attributes` on the columns read from a file.

    ``dtypes`` maps attribute names to dtypes recorded in ``unmesh dtype`` comments.
    With ``identifiers=True`` (surfel attributes must be identifiers) names that are
    not Python identifiers (or are keywords) are made valid with
    :func:`safe_attribute_name` and a warning.
    """
    layout = _group_names([(n, c.dtype.str[1:]) for n, c in columns])
    out: dict[str, np.ndarray] = {}
    i = 0
    for name, k in layout:
        if k is None:
            arr = np.ascontiguousarray(columns[i][1])
            i += 1
        else:
            arr = np.ascontiguousarray(np.stack([c for _, c in columns[i:i + k]], axis=1))
            i += k
        want = dtypes.get(name)
        if want is not None:
            if want not in RECORDED_DTYPES:
                raise fail(path, element, f"comment 'unmesh dtype {name} {want}': expected one of "
                                          f"{', '.join(sorted(RECORDED_DTYPES))}, got {want!r}")
            arr = arr.astype(np.dtype(want))
        key = safe_attribute_name(name) if identifiers else name
        if key != name:
            warnings.warn(f"{os.fspath(path)}: element {element!r}: property {name!r} renamed to attribute {key!r}",
                          stacklevel=4)
        while key in out:
            key += "_"
        out[key] = arr
    return out


def safe_attribute_name(name: str) -> str:
    """A Python identifier close to ``name`` (``class`` -> ``class_``, ``1a`` -> ``_1a``).

    Example
    -------
    >>> safe_attribute_name("class"), safe_attribute_name("scalar-Intensity")
    ('class_', 'scalar_Intensity')
    """
    s = re.sub(r"\W", "_", name, flags=re.ASCII)
    if not s or s[0].isdigit():
        s = "_" + s
    if keyword.iskeyword(s):
        s += "_"
    return s


def to_uchar_colors(colors: np.ndarray) -> np.ndarray:
    """RGB floats in [0, 1] (N,3) -> uint8 (N,3), rounded to nearest (k/255 maps to k)."""
    return np.clip(np.rint(np.asarray(colors, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)


def colors_from_file(values: np.ndarray) -> np.ndarray:
    """Colour values read from a file -> float64 in [0, 1].

    Integer types are divided by their maximum for uint8 (255) or uint16 (65535);
    float values above 1 are taken as 0-255 values.
    """
    if values.dtype.kind in "iu":
        scale = 65535.0 if values.dtype.itemsize == 2 and values.size and values.max() > 255 else 255.0
        return np.clip(values.astype(np.float64) / scale, 0.0, 1.0)
    v = values.astype(np.float64)
    if v.size and np.nanmax(v) > 1.0:
        v = v / 255.0
    return np.clip(v, 0.0, 1.0)


def read_image(path: Path, owner: str | os.PathLike[str], what: str) -> np.ndarray | None:
    """Read an RGB image as uint8 (H,W,3); a missing or unreadable file gives a warning and None."""
    if not is_file(path):
        warnings.warn(f"{os.fspath(owner)}: {what} file {os.fspath(path)[:200]!r} not found; loading without it",
                      stacklevel=4)
        return None
    from PIL import Image

    try:
        with Image.open(path) as im:
            im.load()
            if im.mode not in ("RGB", "L"):
                im = im.convert("RGB")
            arr = np.asarray(im)
    except Exception as exc:  # pillow raises many types for bad images
        warnings.warn(f"{os.fspath(owner)}: {what} file {os.fspath(path)!r} could not be read ({exc}); "
                      "loading without it", stacklevel=4)
        return None
    if arr.dtype != np.uint8:
        arr = (arr.astype(np.float64) / max(float(arr.max()), 1.0) * 255).astype(np.uint8)
    return arr


def write_png(path: Path, image: np.ndarray) -> None:
    """Write a float (H,W,3) image in [0, 1] as an 8-bit PNG to ``path`` (not atomic)."""
    from PIL import Image

    data = np.clip(np.rint(np.asarray(image) * 255.0), 0, 255).astype(np.uint8)
    Image.fromarray(data, mode="RGB").save(path, format="PNG")


def check_finite(path: str | os.PathLike[str], element: str, name: str, values: np.ndarray) -> None:
    """Raise a FormatError naming the first row with NaN or infinity."""
    if values.size and values.dtype.kind == "f":
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.flatnonzero(bad.reshape(len(values), -1).any(axis=1))[0])
            raise fail(path, element, f"row {row}: {name} is NaN or infinite")


def as_path(path: Any, name: str = "path") -> Path:
    """Convert a str or PathLike argument to a Path (InputError otherwise)."""
    if isinstance(path, str | os.PathLike):
        return Path(path)
    raise InputError(f"{name}: expected a file path (str or os.PathLike), got {type(path).__name__}")
