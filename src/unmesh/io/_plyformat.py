"""The PLY container format: header, element tables, ASCII and binary bodies.

This layer knows nothing about surfels or meshes. :func:`read_ply` returns, for
each element, its properties as numpy columns: scalar properties as (count,) arrays
in the file's type (native byte order), list properties as :class:`ListColumn`
(CSR: ``offsets`` (count+1,) int64 and flat ``values``). :func:`encode_ply` builds
a file from such columns.

Both directions are vectorised: binary elements are decoded with structured
dtypes (elements whose list properties all have the same length in every row,
such as triangle faces or a single ``tristrips`` row, in one ``frombuffer``;
variable-length lists with one pass over the rows to find the lengths), ASCII
elements with ``numpy.loadtxt``, falling back to a line-by-line parser that
reports the exact row and property of a problem. The ``plyfile`` package reads
and writes the same files (the tests check both directions) but parses ASCII
bodies and binary list properties row by row in Python, 20-100x slower.

Every problem raises :class:`unmesh.errors.FormatError` naming the file and the
element: malformed headers, unknown types, truncated bodies (``file ends after 120
of 3000 rows``), values that do not parse or do not fit their type, negative list
lengths, lines with missing or extra values, and data after the last element.

Sizes announced by the header are checked before anything is allocated for them:
first against the file's length (each row needs at least its fixed bytes, or in
ASCII one character and a separator per value), then the decoded arrays against
the memory budget (:mod:`unmesh.io.budget`). Binary rows decode to about their own
size, so a binary file is bounded by its length already; the budget refuses only
decoded arrays that are both over the budget and larger than the file (ASCII
bodies, whose ``"0 "`` tokens become 8-byte values, or zero-length lists whose
offsets are 8 bytes each), naming the element and the estimate.
"""

from __future__ import annotations

import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from unmesh.io._common import PLY_NAME, PLY_TYPES, fail, format_rows
from unmesh.io.budget import budget_problem, format_bytes

__all__ = ["Element", "Header", "ListColumn", "Prop", "encode_ply", "parse_header", "read_ply"]

_FORMATS = {"ascii": "=", "binary_little_endian": "<", "binary_big_endian": ">"}
_END = re.compile(rb"end_header[ \t]*(\r\n|\n|\r)")
_STRUCT = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I"}


@dataclass
class Prop:
    """One property: ``code`` is the numpy type code of the values, ``count_code`` of a list's length."""

    name: str
    code: str
    count_code: str | None = None

    @property
    def is_list(self) -> bool:
        return self.count_code is not None


@dataclass
class Element:
    """One element declaration of the header."""

    name: str
    count: int
    props: list[Prop] = field(default_factory=list)


@dataclass
class Header:
    """A parsed PLY header; ``body_start`` is the byte offset of the first data byte."""

    format: str
    elements: list[Element]
    comments: list[str]
    obj_info: list[str]
    body_start: int

    def element(self, name: str) -> Element | None:
        for el in self.elements:
            if el.name == name:
                return el
        return None


@dataclass
class ListColumn:
    """A list property in CSR form: row ``i`` is ``values[offsets[i]:offsets[i+1]]``."""

    offsets: np.ndarray
    values: np.ndarray

    def lengths(self) -> np.ndarray:
        return np.diff(self.offsets)

    def __len__(self) -> int:
        return len(self.offsets) - 1


Column = np.ndarray | ListColumn


def parse_header(data: bytes, path: str | os.PathLike[str]) -> Header:
    """Parse the header of a PLY file given as bytes.

    Raises
    ------
    FormatError
        Naming the file, the header line and, inside an element, the element.
    """
    if not data.startswith(b"ply"):
        raise fail(path, None, "not a PLY file (it does not start with 'ply')")
    m = _END.search(data)
    if m is None:
        raise fail(path, None, "header: no 'end_header' line (truncated or not a PLY file)")
    text = data[:m.start()].decode("utf-8", errors="replace")
    lines = re.split(r"\r\n|\n|\r", text)
    if lines[0].strip() != "ply":
        raise fail(path, None, f"header line 1: expected 'ply', got {lines[0][:40]!r}")
    fmt = None
    elements: list[Element] = []
    comments: list[str] = []
    obj_info: list[str] = []

    def bad(lineno: int, msg: str) -> Exception:
        el = elements[-1].name if elements else None
        return fail(path, el, f"header line {lineno}: {msg}")

    for lineno, raw in enumerate(lines[1:], start=2):
        line = raw.strip()
        if not line:
            continue
        key, _, rest = line.partition(" ")
        fields = rest.split()
        if key == "comment":
            comments.append(rest.strip())
        elif key == "obj_info":
            obj_info.append(rest.strip())
        elif key == "format":
            if fmt is not None or elements:
                raise bad(lineno, "'format' must come once, before the elements")
            if len(fields) != 2 or fields[0] not in _FORMATS:
                raise bad(lineno, f"expected 'format ascii|binary_little_endian|binary_big_endian 1.0', got {line!r}")
            if fields[1] not in ("1.0", "1"):
                raise bad(lineno, f"unsupported PLY version {fields[1]!r}")
            fmt = fields[0]
        elif key == "element":
            if fmt is None:
                raise bad(lineno, "'element' before 'format'")
            if len(fields) != 2:
                raise bad(lineno, f"expected 'element NAME COUNT', got {line!r}")
            try:
                count = int(fields[1])
            except ValueError:
                raise bad(lineno, f"element {fields[0]!r}: count {fields[1]!r} is not an integer") from None
            if count < 0:
                raise bad(lineno, f"element {fields[0]!r}: negative count {count}")
            if any(e.name == fields[0] for e in elements):
                raise bad(lineno, f"element {fields[0]!r} declared twice")
            elements.append(Element(fields[0], count))
        elif key == "property":
            if not elements:
                raise bad(lineno, "'property' before any 'element'")
            el = elements[-1]
            if fields and fields[0] == "list":
                if len(fields) != 4:
                    raise bad(lineno, f"expected 'property list COUNT_TYPE VALUE_TYPE NAME', got {line!r}")
                ctype, vtype, name = fields[1:]
                if ctype not in PLY_TYPES or PLY_TYPES[ctype][0] == "f":
                    raise bad(lineno, f"property {name!r}: list length type must be an integer type, got {ctype!r}")
                if vtype not in PLY_TYPES:
                    raise bad(lineno, f"property {name!r}: unknown type {vtype!r}")
                prop = Prop(name, PLY_TYPES[vtype], PLY_TYPES[ctype])
            else:
                if len(fields) != 2:
                    raise bad(lineno, f"expected 'property TYPE NAME', got {line!r}")
                if fields[0] not in PLY_TYPES:
                    raise bad(lineno, f"property {fields[1]!r}: unknown type {fields[0]!r}")
                prop = Prop(fields[1], PLY_TYPES[fields[0]])
            if any(p.name == prop.name for p in el.props):
                raise bad(lineno, f"property {prop.name!r} declared twice")
            el.props.append(prop)
        else:
            raise bad(lineno, f"unexpected header line {line[:60]!r}")
    if fmt is None:
        raise fail(path, None, "header: no 'format' line")
    return Header(fmt, elements, comments, obj_info, m.end())


def read_ply(path: str | os.PathLike[str]) -> tuple[Header, dict[str, dict[str, Column]]]:
    """Read a whole PLY file.

    Returns
    -------
    header : Header
    tables : dict
        ``tables[element][property]`` -> (count,) array or :class:`ListColumn`.

    Raises
    ------
    FormatError
        On any malformed, truncated or inconsistent content.
    """
    data = Path(path).read_bytes()
    header = parse_header(data, path)
    _check_sizes(data, header, path)
    if header.format == "ascii":
        tables = _read_ascii(data, header, path)
    else:
        tables = _read_binary(data, header, path)
    return header, tables


def _decoded_row_bytes(el: Element, ascii: bool) -> tuple[int, int]:
    """(fewest decoded bytes of one row, fewest ASCII values in it), from the header alone.

    ASCII rows are parsed into a float64 table (8 bytes per value) plus a line object
    (about 56 bytes); a list contributes its length value and an int64 offset.
    """
    nvalues = len(el.props)
    out = sum(8 if p.is_list else np.dtype(p.code).itemsize for p in el.props)
    if ascii:
        out += 8 * nvalues + 56
    return out, nvalues


def _check_sizes(data: bytes, header: Header, path: str | os.PathLike[str]) -> None:
    """The decoded arrays of the rows the file can hold against the memory budget, before allocating.

    Counts beyond what the file's length can hold are left to the readers, which report
    exactly where the file ends; only the rows that fit (each needs its fixed bytes, or
    in ASCII a character and a separator per value) are counted here.
    """
    ascii = header.format == "ascii"
    left = len(data) - header.body_start + (1 if ascii else 0)  # the last ASCII newline may be missing
    decoded = 0
    for el in header.elements:
        row, nvalues = _decoded_row_bytes(el, ascii)
        if ascii:
            minrow = max(2 * nvalues, 1)
        else:
            minrow = sum(np.dtype(p.count_code if p.is_list else p.code).itemsize for p in el.props)
        rows = el.count if minrow == 0 else min(el.count, max(left, 0) // minrow)
        left -= rows * minrow
        decoded += rows * row
        if decoded > len(data):
            problem = budget_problem(decoded, f"the decoded rows up to element {el.name!r} ({el.count} rows)")
            if problem is not None:
                raise fail(path, el.name, problem)


# -- binary ---------------------------------------------------------------------------------
def _read_binary(data: bytes, header: Header, path: str | os.PathLike[str]) -> dict[str, dict[str, Column]]:
    bo = _FORMATS[header.format]
    pos = header.body_start
    tables: dict[str, dict[str, Column]] = {}
    for el in header.elements:
        tables[el.name], pos = _binary_element(data, pos, el, bo, path)
    rest = data[pos:]
    if rest.strip(b" \t\r\n\0"):
        last = header.elements[-1].name if header.elements else None
        raise fail(path, last, f"{len(rest)} bytes of unexpected data after the last row (wrong count in the header?)")
    return tables


def _binary_element(data: bytes, pos: int, el: Element, bo: str,
                    path: str | os.PathLike[str]) -> tuple[dict[str, Column], int]:
    if not el.props:
        return {}, pos
    if el.count == 0:
        return {p.name: (ListColumn(np.zeros(1, np.int64), np.empty(0, p.code)) if p.is_list
                         else np.empty(0, p.code)) for p in el.props}, pos
    avail = len(data) - pos
    minrow = sum(np.dtype(p.count_code if p.is_list else p.code).itemsize for p in el.props)
    if el.count * minrow > avail:  # checked before allocating anything for the rows
        exact = not any(p.is_list for p in el.props)
        raise fail(path, el.name, f"file ends after {'' if exact else 'at most '}{avail // minrow} of "
                                  f"{el.count} rows (the header announces {format_bytes(el.count * minrow)}"
                                  f"{'' if exact else ' or more'}, {format_bytes(avail)} follow)")
    # Layout of the first row fixes the list lengths of the fast path.
    off = pos
    lengths: dict[int, int] = {}
    for i, p in enumerate(el.props):
        if p.is_list:
            csz = np.dtype(p.count_code).itemsize
            if off + csz > len(data):
                raise fail(path, el.name, f"file ends after 0 of {el.count} rows")
            n = int(np.frombuffer(data, bo + p.count_code, 1, offset=off)[0])
            if n < 0:
                raise fail(path, el.name, f"row 0: property {p.name!r}: negative list length {n}")
            lengths[i] = n
            off += csz + n * np.dtype(p.code).itemsize
            if off > len(data):
                raise fail(path, el.name, f"row 0: property {p.name!r}: a list of {n} values runs past "
                                          "the end of the file")
        else:
            off += np.dtype(p.code).itemsize
    fields: list[tuple] = []
    for i, p in enumerate(el.props):
        if p.is_list:
            fields.append((f"c{i}", bo + p.count_code))
            fields.append((f"p{i}", bo + p.code, (lengths[i],)))
        else:
            fields.append((f"p{i}", bo + p.code))
    dtype = np.dtype(fields)
    if el.count * dtype.itemsize <= avail:
        arr = np.frombuffer(data, dtype, el.count, offset=pos)
        if all(np.all(arr[f"c{i}"] == n) for i, n in lengths.items()):
            out: dict[str, Column] = {}
            for i, p in enumerate(el.props):
                values = arr[f"p{i}"].astype(p.code)
                if p.is_list:
                    k = lengths[i]
                    out[p.name] = ListColumn(np.arange(el.count + 1, dtype=np.int64) * k, values.reshape(-1))
                else:
                    out[p.name] = values
            return out, pos + el.count * dtype.itemsize
    if not lengths:
        rows = avail // dtype.itemsize
        raise fail(path, el.name, f"file ends after {rows} of {el.count} rows")
    return _binary_ragged(data, pos, el, bo, path)


def _binary_ragged(data: bytes, pos: int, el: Element, bo: str,
                   path: str | os.PathLike[str]) -> tuple[dict[str, Column], int]:
    """Variable-length lists: one pass over the rows for the lengths, then vectorised gathers."""
    steps = []
    for i, p in enumerate(el.props):
        if p.is_list:
            cdt = np.dtype(p.count_code)
            steps.append((i, _STRUCT[p.count_code], cdt.itemsize, np.dtype(p.code).itemsize))
        else:
            steps.append((i, None, np.dtype(p.code).itemsize, 0))
    counts = {i: np.empty(el.count, np.int64) for i, p in enumerate(el.props) if p.is_list}
    starts = np.empty(el.count + 1, np.int64)
    size = len(data)
    unpack = struct.unpack_from
    off = pos
    prefix = "<" if bo == "<" else ">"
    fmts = {i: prefix + f for i, f, _, _ in steps if f is not None}
    for r in range(el.count):
        starts[r] = off
        for i, f, csz, vsz in steps:
            if f is None:
                off += csz
                continue
            if off + csz > size:
                raise fail(path, el.name, f"file ends after {r} of {el.count} rows")
            n = unpack(fmts[i], data, off)[0]
            if n < 0:
                raise fail(path, el.name, f"row {r}: property {el.props[i].name!r}: negative list length {n}")
            counts[i][r] = n
            off += csz + n * vsz
        if off > size:
            raise fail(path, el.name, f"file ends after {r} of {el.count} rows")
    starts[el.count] = off
    buf = np.frombuffer(data, np.uint8)
    running = starts[:-1].copy()
    out: dict[str, Column] = {}
    for i, p in enumerate(el.props):
        vdt = np.dtype(bo + p.code)
        if not p.is_list:
            idx = running[:, None] + np.arange(vdt.itemsize)
            out[p.name] = buf[idx].reshape(-1).view(vdt).astype(p.code)
            running += vdt.itemsize
        else:
            csz = np.dtype(p.count_code).itemsize
            n = counts[i]
            offsets = np.zeros(el.count + 1, np.int64)
            np.cumsum(n, out=offsets[1:])
            total = int(offsets[-1])
            first = np.repeat(running + csz - offsets[:-1] * vdt.itemsize, n)
            elem = first + np.arange(total, dtype=np.int64) * vdt.itemsize
            idx = elem[:, None] + np.arange(vdt.itemsize)
            values = buf[idx].reshape(-1).view(vdt).astype(p.code) if total else np.empty(0, p.code)
            out[p.name] = ListColumn(offsets, values)
            running += csz + n * vdt.itemsize
    return out, off


# -- ascii ----------------------------------------------------------------------------------
def _read_ascii(data: bytes, header: Header, path: str | os.PathLike[str]) -> dict[str, dict[str, Column]]:
    lines = data[header.body_start:].decode("latin-1").splitlines()
    end = len(lines)
    while end and not lines[end - 1].strip():
        end -= 1
    lines = lines[:end]
    pos = 0
    tables: dict[str, dict[str, Column]] = {}
    for el in header.elements:
        rows = lines[pos:pos + el.count]
        if len(rows) < el.count:
            raise fail(path, el.name, f"file ends after {len(rows)} of {el.count} rows")
        tables[el.name] = _ascii_element(rows, el, path)
        pos += el.count
    if pos < len(lines):
        last = header.elements[-1].name if header.elements else None
        raise fail(path, last, f"{len(lines) - pos} unexpected lines after the last row (wrong count in the header?)")
    return tables


def _convert(values: np.ndarray, code: str) -> np.ndarray | None:
    """float64 values -> ``code``; None if they do not fit (not integral or out of range)."""
    if code[0] == "f":
        return values.astype(code)
    with np.errstate(invalid="ignore", over="ignore"):
        ok = np.isfinite(values).all() and (values == np.trunc(values)).all()
        if not ok:
            return None
        info = np.iinfo(code)
        if values.size and (values.min() < info.min or values.max() > info.max):
            return None
        return values.astype(code)


def _ascii_element(rows: list[str], el: Element, path: str | os.PathLike[str]) -> dict[str, Column]:
    if not el.props:
        for r, line in enumerate(rows):
            if line.strip():
                raise fail(path, el.name, f"row {r}: values given for an element without properties")
        return {}
    if el.count == 0:
        return {p.name: (ListColumn(np.zeros(1, np.int64), np.empty(0, p.code)) if p.is_list
                         else np.empty(0, p.code)) for p in el.props}
    try:
        table = np.loadtxt(rows, dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        table = None
    if table is not None and table.shape[0] == el.count:
        out: dict[str, Column] = {}
        c = 0
        ncol = table.shape[1]
        for p in el.props:
            if c >= ncol:
                out = {}
                break
            if p.is_list:
                lens = table[:, c]
                k = int(lens[0]) if np.isfinite(lens[0]) and 0 <= lens[0] <= ncol and lens[0] == int(lens[0]) else -1
                if k < 0 or not np.all(lens == k) or c + 1 + k > ncol:
                    out = {}
                    break
                vals = _convert(table[:, c + 1:c + 1 + k].reshape(-1), p.code)
                if vals is None:
                    out = {}
                    break
                out[p.name] = ListColumn(np.arange(el.count + 1, dtype=np.int64) * k, vals)
                c += 1 + k
            else:
                vals = _convert(table[:, c], p.code)
                if vals is None:
                    out = {}
                    break
                out[p.name] = vals
                c += 1
        if out and c == ncol:
            return out
    return _ascii_ragged(rows, el, path)


def _ascii_ragged(rows: list[str], el: Element, path: str | os.PathLike[str]) -> dict[str, Column]:
    """Line-by-line parser: handles variable-length lists and pinpoints errors."""
    tokens: list[list[str]] = [[] for _ in el.props]
    counts: list[list[int]] = [[] for _ in el.props]
    for r, line in enumerate(rows):
        toks = line.split()
        k = 0
        for j, p in enumerate(el.props):
            if k >= len(toks):
                raise fail(path, el.name, f"row {r}: property {p.name!r}: line ends early "
                                          f"({len(toks)} values)")
            if p.is_list:
                try:
                    n = int(toks[k])
                except ValueError:
                    raise fail(path, el.name, f"row {r}: property {p.name!r}: list length {toks[k]!r} "
                                              "is not an integer") from None
                if n < 0:
                    raise fail(path, el.name, f"row {r}: property {p.name!r}: negative list length {n}")
                if k + 1 + n > len(toks):
                    raise fail(path, el.name, f"row {r}: property {p.name!r}: list of {n} values but only "
                                              f"{len(toks) - k - 1} on the line")
                counts[j].append(n)
                tokens[j].extend(toks[k + 1:k + 1 + n])
                k += 1 + n
            else:
                tokens[j].append(toks[k])
                k += 1
        if k != len(toks):
            raise fail(path, el.name, f"row {r}: {len(toks) - k} extra values at the end of the line")
    out: dict[str, Column] = {}
    for j, p in enumerate(el.props):
        try:
            vals = np.array(tokens[j], dtype=np.float64)
        except ValueError:
            vals = None
        conv = None if vals is None else _convert(vals, p.code)
        if conv is None:
            # find the offending token for the message
            for t_index, tok in enumerate(tokens[j]):
                try:
                    v = float(tok)
                    if _convert(np.array([v]), p.code) is not None:
                        continue
                except ValueError:
                    pass
                if p.is_list:
                    ends = np.cumsum(counts[j])
                    row = int(np.searchsorted(ends, t_index, side="right"))
                else:
                    row = t_index
                raise fail(path, el.name, f"row {row}: property {p.name!r}: value {tok!r} is not a valid "
                                          f"{PLY_NAME[p.code]}")
        if p.is_list:
            offsets = np.zeros(el.count + 1, np.int64)
            np.cumsum(np.asarray(counts[j], dtype=np.int64), out=offsets[1:])
            out[p.name] = ListColumn(offsets, conv)
        else:
            out[p.name] = conv
    return out


# -- writing --------------------------------------------------------------------------------
#: A property to write: (name, values, code, count_code). Scalars: values (N,);
#: lists: values (N, k) with count_code set (every row has k entries).
WriteProp = tuple[str, np.ndarray, str, str | None]


def encode_ply(elements: list[tuple[str, int, list[WriteProp]]], comments: list[str] = (),  # type: ignore[assignment]
               binary: bool = True, byte_order: str = "<") -> bytes:
    """Encode elements as a complete PLY file.

    Parameters
    ----------
    elements : list of (name, count, properties)
        ``properties`` are ``(name, values, code, count_code)``: scalar values (N,)
        with ``count_code=None``, or (N, k) list values with the length type code.
    comments : list of str
    binary : bool
        Binary (default) or ASCII body.
    byte_order : {'<', '>'}
        Byte order of binary bodies.

    Returns
    -------
    bytes
    """
    fmt = "ascii" if not binary else ("binary_little_endian" if byte_order == "<" else "binary_big_endian")
    head = ["ply", f"format {fmt} 1.0"]
    head += [f"comment {c}" for c in comments]
    for name, count, props in elements:
        head.append(f"element {name} {count}")
        for pname, _, code, ccode in props:
            if ccode is None:
                head.append(f"property {PLY_NAME[code]} {pname}")
            else:
                head.append(f"property list {PLY_NAME[ccode]} {PLY_NAME[code]} {pname}")
    head.append("end_header")
    parts = [("\n".join(head) + "\n").encode("ascii")]
    for _, count, props in elements:
        if not props or count == 0:
            continue
        if binary:
            fields: list[tuple] = []
            for i, (_, values, code, ccode) in enumerate(props):
                if ccode is None:
                    fields.append((f"p{i}", byte_order + code))
                else:
                    fields.append((f"c{i}", byte_order + ccode))
                    fields.append((f"p{i}", byte_order + code, (values.shape[1],)))
            arr = np.empty(count, np.dtype(fields))
            for i, (_, values, _, ccode) in enumerate(props):
                if ccode is not None:
                    arr[f"c{i}"] = values.shape[1]
                arr[f"p{i}"] = values
            parts.append(arr.tobytes())
        else:
            cols: list = []
            for _, values, code, ccode in props:
                vals = np.asarray(values).astype(code, copy=False)
                if ccode is None:
                    cols.append(vals)
                else:
                    cols.append(str(vals.shape[1]))
                    cols.extend(vals[:, j] for j in range(vals.shape[1]))
            parts.append(("\n".join(format_rows(cols, count=count)) + "\n").encode("ascii"))
    return b"".join(parts)
