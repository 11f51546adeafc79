"""The paintable surface (thesis 5.3, Fig. 5.2) with per-surfel paint attributes (5.6).

The original surfels sit in a static :class:`unmesh.spatial.KDTree` (collision detection and
the lower bound of downsampling). Resampling appends *child* surfels, each attached to the
closest original (its *father*); children replace their father for rendering and paint
transfer. Originals are disabled (``active = False``), never deleted; deleted children are
removed (``alive = False``; their rows are not reused, so row indices are stable for undo and
for the renderer's update lists).

Rows are columns of named arrays (:data:`FIELDS`); every change goes through :meth:`set` or
:meth:`append`, which journal the previous values (undo/redo per stroke, exact) and collect the
rows whose appearance changed (the update lists of differential rendering, 5.7).

Example
-------
>>> from unmesh import SurfelCloud
>>> s = PaintSurface(SurfelCloud([[0, 0, 0], [1, 0, 0]], [[0, 0, 1]] * 2, radii=[0.7, 0.7]))
>>> s.n, s.n_original, int(s.active.sum())
(2, 2, 2)
"""

from __future__ import annotations

import mmap
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from unmesh._threads import serial_if_small
from unmesh.errors import InputError
from unmesh.paint._children_kernels import gather_children, link_rows, relink_all, unlink_rows
from unmesh.paint._paint_kernels import visible_colors_rows
from unmesh.spatial import KDTree
from unmesh.surfels import SurfelCloud

__all__ = ["FIELDS", "VISUAL_FIELDS", "PaintSurface", "fresh_zeros", "state_colors", "visible_colors"]

#: Per-surfel fields: trailing shape and dtype. Paint attributes of 5.6: wet/dry colour and
#: volume, optical density ``rho`` (1/length: alpha = min(rho * V_w / area, 1), eq. 5.8),
#: drying rate ``kappa`` (5.12), diffusion coefficient ``diff`` (5.15), appearance
#: (reflectivity, shininess, metallic); ``area`` is the surface area a surfel stands for, ``lift`` its offset along the
#: normal above its father's surface (impasto, 5.6.3),
#: ``updates`` the per-surfel update counter of 5.7.
FIELDS: dict[str, tuple[tuple[int, ...], Any]] = {
    "pos": ((3,), np.float64), "nrm": ((3,), np.float64), "rad": ((), np.float64),
    "father": ((), np.int64), "active": ((), np.bool_), "alive": ((), np.bool_),
    "base": ((3,), np.float64), "wet": ((3,), np.float64), "dry": ((3,), np.float64),
    "vw": ((), np.float64), "vd": ((), np.float64), "area": ((), np.float64),
    "rho": ((), np.float64), "kappa": ((), np.float64), "diff": ((), np.float64),
    "refl": ((), np.float64), "shin": ((), np.float64), "metal": ((), np.float64),
    "lift": ((), np.float64), "updates": ((), np.int64),
}

#: Fields whose change changes the image.
VISUAL_FIELDS = frozenset({"pos", "nrm", "rad", "active", "alive", "base", "wet", "dry", "vw", "vd", "rho", "refl",
                           "metal", "area"})

#: Original surfels stand for ``AREA_FACTOR * pi * r^2`` of surface (splats overlap).
AREA_FACTOR = 0.5
#: Row capacity reserved at the start, in original surfels. Painting appends children (a stroke
#: across a 500k-surfel model appends ~60k rows; rows are never reused), so the capacity is
#: reserved generously: the arrays come from :func:`fresh_zeros` (fresh pages from the system),
#: so rows never written cost no memory, and growing (a copy of every field) is rare.
RESERVE = 4.0
#: :meth:`PaintSurface.reserve_ahead` grows the capacity (by :data:`GROWTH`) once fewer rows than
#: this fraction of the original surfels are free, so that a stroke never stops for a copy.
AHEAD = 1.0
#: Capacity growth factor.
GROWTH = 2.0


#: Arrays at least this large (bytes) come from :func:`fresh_zeros`' own mapping.
FRESH_MIN_BYTES = 1 << 22


def fresh_zeros(shape: tuple[int, ...], dtype: Any) -> np.ndarray:
    """A zeroed C-contiguous array whose memory the system supplies page by page on first write,
    in small pages (``MADV_NOHUGEPAGE`` where the system has it).

    For arrays with reserved capacity (rows written a few thousand at a time, paint event by paint
    event). ``np.zeros`` asks for transparent huge pages for arrays of 4 MiB and more; where the
    system honours that (Linux's default ``madvise`` mode), the first write into each 2 MiB page
    stops for the page to be zeroed and, with the default ``defrag`` setting, for memory to be
    compacted, which made appending one event's children to the 20 fields cost about 1 ms
    instead of 0.2 ms (docs/performance.md, stop 36). Small arrays come from ``np.zeros``.

    Example
    -------
    >>> a = fresh_zeros((1 << 20, 3), np.float64)
    >>> a.shape, a.dtype.name, a.flags.c_contiguous, a.flags.writeable, float(a.sum())
    ((1048576, 3), 'float64', True, True, 0.0)
    """
    dt = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
    if nbytes < FRESH_MIN_BYTES:
        return np.zeros(shape, dt)
    if hasattr(mmap, "MAP_PRIVATE") and hasattr(mmap, "MAP_ANONYMOUS"):  # private, as malloc's (copied on fork)
        buf = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    else:
        buf = mmap.mmap(-1, nbytes)  # anonymous: zero pages, mapped on first write
    if hasattr(mmap, "MADV_NOHUGEPAGE"):
        buf.madvise(mmap.MADV_NOHUGEPAGE)
    return np.frombuffer(buf, dt).reshape(shape)


def visible_colors(wet: np.ndarray, dry: np.ndarray, vw: np.ndarray, rho: np.ndarray, area: np.ndarray,
                   vd: np.ndarray | None = None, base: np.ndarray | None = None) -> np.ndarray:
    """Visible colour (5.8): ``C = alpha C_w + (1 - alpha) C_d``, ``alpha = min(rho V_w / area, 1)``.

    Dry paint is opaque once it forms a layer: with ``vd`` and ``base`` given, ``C_d`` is the dry
    colour over the bare surface colour ``base`` with coverage ``beta = min(rho V_d / area, 1)``
    (so a trace of paint spread by diffusion does not colour a surfel completely).

    Parameters
    ----------
    wet, dry : (N, 3) float64
    vw, rho, area : (N,) float64
    vd : (N,) float64, optional
    base : (N, 3) float64, optional

    Example
    -------
    >>> visible_colors(np.array([[1.0, 0, 0]]), np.array([[0, 0, 1.0]]), np.array([0.5]), np.array([1.0]),
    ...                np.array([1.0])).tolist()
    [[0.5, 0.0, 0.5]]
    """
    alpha = np.minimum(rho * vw / area, 1.0)[:, None]
    if vd is not None and base is not None:
        beta = np.minimum(rho * vd / area, 1.0)[:, None]
        dry = beta * dry + (1.0 - beta) * base
    return np.clip(alpha * wet + (1.0 - alpha) * dry, 0.0, 1.0)


def state_colors(fields: Mapping[str, np.ndarray]) -> np.ndarray:
    """Visible colour (5.8) of every row of a surface's fields (the rows of
    :meth:`PaintSurface.state`, or a copy of them), (N, 3): :meth:`PaintSurface.colors` of those rows."""
    n = len(fields["wet"])
    out = np.empty((n, 3))
    c = {k: np.ascontiguousarray(fields[k]) for k in ("wet", "dry", "vw", "rho", "area", "vd", "base")}
    with serial_if_small(n):
        visible_colors_rows(np.arange(n, dtype=np.int64), c["wet"], c["dry"], c["vw"], c["rho"], c["area"], c["vd"],
                            c["base"], out)
    return out


class PaintSurface:
    """Originals in a static kd-tree, children attached to fathers, paint attributes per row.

    Parameters
    ----------
    cloud : SurfelCloud
        The model (circular surfels are used; elliptical ones by their larger semi-axis).

    Attributes
    ----------
    n : int
        Rows in use (originals first, then children in creation order).
    n_original : int
    tree : KDTree
        Static kd-tree of the originals.
    """

    def __init__(self, cloud: SurfelCloud, *, _state: dict[str, np.ndarray] | None = None) -> None:
        if not isinstance(cloud, SurfelCloud):
            raise InputError(f"cloud: expected a SurfelCloud, got {type(cloud).__name__}")
        if len(cloud) == 0:
            raise InputError("cloud: expected a non-empty surfel cloud, got 0 surfels")
        cloud = cloud.visible()
        n0 = len(cloud)
        self.n_original = n0
        self._data: dict[str, np.ndarray] = {}
        cap = max(16, int(n0 * RESERVE))
        for name, (tail, dt) in FIELDS.items():
            self._data[name] = fresh_zeros((cap, *tail), dt)
        self.n = n0
        if _state is not None:
            n = len(_state["pos"])
            self._reserve(n)
            for name in FIELDS:
                self._data[name][:n] = _state[name]
            self.n = n
            self.n_original = int(np.count_nonzero(self._data["father"][:n] == np.arange(n)))
        else:
            d = self._data
            d["pos"][:n0] = cloud.positions
            d["nrm"][:n0] = cloud.normals
            d["rad"][:n0] = cloud.radii
            d["father"][:n0] = np.arange(n0)
            d["active"][:n0] = True
            d["alive"][:n0] = True
            d["base"][:n0] = cloud.colors
            d["wet"][:n0] = cloud.colors
            d["dry"][:n0] = cloud.colors
            d["area"][:n0] = AREA_FACTOR * np.pi * cloud.radii ** 2
            d["shin"][:n0] = 20.0
        no = self.n_original
        self.tree = KDTree(self._data["pos"][:no])
        self._head = np.full(no, -1, np.int64)
        self._tail = np.full(no, -1, np.int64)
        self._links = {"nxt": np.full(len(self._data["pos"]), -1, np.int64),
                       "prv": np.full(len(self._data["pos"]), -1, np.int64),
                       "linked": np.zeros(len(self._data["pos"]), np.bool_)}
        self.rebuild_children()
        self.journal: list[tuple[str, np.ndarray, np.ndarray]] | None = None
        self.journal_n0 = self.n
        self._saved: dict[str, np.ndarray] = {}
        self.dirty: set[int] = set()
        self.mean_radius = float(np.mean(self._data["rad"][:no]))

    # -- access ----------------------------------------------------------------------------
    def __getattr__(self, name: str) -> np.ndarray:
        data = self.__dict__.get("_data")
        if data is not None and name in data:
            return data[name][:self.__dict__["n"]]
        raise AttributeError(name)

    def state(self) -> dict[str, np.ndarray]:
        """Copies of all fields of the rows in use."""
        return {k: v[:self.n].copy() for k, v in self._data.items()}

    @property
    def capacity(self) -> int:
        """Rows the arrays hold before they must grow (rows past :attr:`n` are zero)."""
        return len(self._data["pos"])

    def _reserve(self, n: int) -> None:
        cap = len(self._data["pos"])
        if n <= cap:
            return
        new = max(n, int(cap * GROWTH))
        used = self.n
        for name, arr in self._data.items():
            grown = fresh_zeros((new, *arr.shape[1:]), arr.dtype)
            grown[:used] = arr[:used]  # rows past n are zero (never written, or zeroed by _truncate)
            self._data[name] = grown
        links = self.__dict__.get("_links")
        if links is not None:
            for name, arr in links.items():
                grown = np.full(new, -1 if arr.dtype == np.int64 else False, dtype=arr.dtype)
                grown[:cap] = arr
                links[name] = grown

    def reserve_ahead(self) -> bool:
        """Grow the capacity now if fewer than :data:`AHEAD` times the original surfels' rows are
        free (between strokes, where a copy of every field is no hitch in a stroke); True when
        it grew."""
        if self.capacity - self.n >= AHEAD * self.n_original:
            return False
        self._reserve(self.n + int(np.ceil(AHEAD * self.n_original)))
        return True

    def rows_of(self, fathers: np.ndarray) -> np.ndarray:
        """The visible rows (active and alive) among ``fathers`` and their children, ascending.

        Example
        -------
        >>> s = PaintSurface(SurfelCloud([[0, 0, 0], [1, 0, 0]], [[0, 0, 1]] * 2, radii=[0.7, 0.7]))
        >>> s.rows_of(np.array([1])).tolist()
        [1]
        """
        fathers = np.ascontiguousarray(fathers, np.int64)
        if len(fathers) > 1 and not (fathers[1:] > fathers[:-1]).all():
            fathers = np.unique(fathers)
        kids = gather_children(fathers, self._head, self._links["nxt"])
        kids.sort()  # children rows are distinct and follow every original row
        rows = np.concatenate([fathers, kids])
        return rows[self.active[rows] & self.alive[rows]]

    @property
    def children(self) -> Children:
        """The father -> alive children lists (read-only mapping of original row -> list of rows)."""
        return Children(self._head, self._links["nxt"])

    def rebuild_children(self) -> None:
        """The father -> alive children lists, from the arrays."""
        L = self._links
        relink_all(self.n, self._data["father"], self._data["alive"], self._head, self._tail, L["nxt"], L["prv"],
                   L["linked"])

    def delete(self, rows: np.ndarray) -> None:
        """Replace rows: originals are disabled, children deleted (5.5)."""
        rows = np.asarray(rows, np.int64)
        self.set("active", rows, False)
        kids = rows[rows >= self.n_original]
        if len(kids):
            self.set("alive", kids, False)
            L = self._links
            unlink_rows(kids, self._data["father"], self._head, self._tail, L["nxt"], L["prv"], L["linked"])

    # -- journalled changes -----------------------------------------------------------------
    def set(self, name: str, idx: np.ndarray, values: Any) -> None:
        """Set ``field[idx] = values`` (journalled; visual fields mark the rows dirty)."""
        idx = np.asarray(idx, dtype=np.int64)
        if idx.size == 0:
            return
        arr = self._data[name]
        if self.journal is not None:
            # the first old value of each row of this record (rows appended by it need none)
            saved = self._saved.get(name)
            if saved is None or len(saved) < len(arr):
                grown = np.zeros(len(arr), bool)
                if saved is not None:
                    grown[:len(saved)] = saved
                saved = self._saved[name] = grown
            new = np.unique(idx[(idx < self.journal_n0)])
            new = new[~saved[new]]
            if len(new):
                saved[new] = True
                self.journal.append((name, new, arr[new].copy()))
        arr[idx] = values
        if name in VISUAL_FIELDS:
            self.dirty.update(idx.tolist())

    def append(self, values: dict[str, np.ndarray]) -> np.ndarray:
        """Append rows (children); returns their indices. Missing fields are zero."""
        m = len(values["pos"])
        n = self.n
        self._reserve(n + m)
        for name, arr in self._data.items():
            if name in values:
                arr[n:n + m] = values[name]
            else:
                arr[n:n + m] = 0
        self.n = n + m
        idx = np.arange(n, n + m, dtype=np.int64)
        L = self._links
        link_rows(idx, self._data["father"], self._head, self._tail, L["nxt"], L["prv"], L["linked"])
        self.dirty.update(range(n, n + m))
        return idx

    def begin_record(self) -> None:
        """Start journalling (one undo record)."""
        self.journal = []
        self.journal_n0 = self.n
        self._saved: dict[str, np.ndarray] = {}

    def end_record(self) -> dict[str, Any]:
        """Stop journalling; returns the record for :meth:`revert`."""
        rec = {"n0": self.journal_n0, "changes": self.journal or []}
        self.journal = None
        self._saved = {}
        return rec

    def revert(self, rec: dict[str, Any]) -> dict[str, Any]:
        """Restore the state before ``rec``; returns the record that re-applies it (redo)."""
        n0 = rec["n0"]
        appended = {k: v[n0:self.n].copy() for k, v in self._data.items()}
        redo_changes = []
        for name, idx, old in reversed(rec["changes"]):
            arr = self._data[name]
            redo_changes.append((name, idx, arr[idx].copy()))
            arr[idx] = old
            if name in VISUAL_FIELDS:
                self.dirty.update(idx.tolist())
        self.dirty.update(range(n0, self.n))
        self._truncate(n0)
        self.rebuild_children()
        return {"n0": n0, "appended": appended, "redo": list(reversed(redo_changes))}

    def reapply(self, red: dict[str, Any]) -> dict[str, Any]:
        """Re-apply a record returned by :meth:`revert`; returns the undo record again."""
        changes = []
        for name, idx, new in red["redo"]:
            arr = self._data[name]
            changes.append((name, idx, arr[idx].copy()))
            arr[idx] = new
            if name in VISUAL_FIELDS:
                self.dirty.update(idx.tolist())
        n0 = red["n0"]
        if len(red["appended"]["pos"]):
            self.append(red["appended"])
        self.rebuild_children()
        return {"n0": n0, "changes": changes}

    def _truncate(self, n0: int) -> None:
        for arr in self._data.values():
            arr[n0:self.n] = 0
        self.n = n0

    # -- derived -----------------------------------------------------------------------------
    def visible_rows(self) -> np.ndarray:
        """Indices of the rows rendered and painted (active, alive)."""
        return np.flatnonzero(self.active & self.alive)

    def colors(self, idx: np.ndarray | None = None) -> np.ndarray:
        """Visible colour (5.8) of rows ``idx`` (default all rows), (K, 3)."""
        d = self._data
        idx = np.arange(self.n) if idx is None else np.ascontiguousarray(idx, dtype=np.int64)
        out = np.empty((len(idx), 3))
        with serial_if_small(len(idx)):
            visible_colors_rows(idx, d["wet"], d["dry"], d["vw"], d["rho"], d["area"], d["vd"], d["base"], out)
        return out

    def total_volume(self) -> float:
        """Wet + dry paint volume on the visible surface."""
        idx = self.visible_rows()
        return float(np.sum(self.vw[idx]) + np.sum(self.vd[idx]))

    def cloud(self) -> SurfelCloud:
        """The visible surfels with their visible colours (paint attributes as attributes)."""
        idx = self.visible_rows()
        return SurfelCloud(self.pos[idx], self.nrm[idx], radii=self.rad[idx], colors=self.colors(idx),
                           attributes={"wet_volume": self.vw[idx].copy(), "dry_volume": self.vd[idx].copy(),
                                       "father": self.father[idx].copy()})


class Children(Mapping[int, list[int]]):
    """Read-only view of a surface's father -> children lists (each ascending)."""

    def __init__(self, head: np.ndarray, nxt: np.ndarray) -> None:
        self._head = head
        self._nxt = nxt

    def __getitem__(self, father: int) -> list[int]:
        f = int(father)
        if not (0 <= f < len(self._head)) or self._head[f] < 0:
            raise KeyError(father)
        return gather_children(np.array([f], np.int64), self._head, self._nxt).tolist()

    def __iter__(self) -> Iterator[int]:
        return iter(np.flatnonzero(self._head >= 0).tolist())

    def __len__(self) -> int:
        return int(np.count_nonzero(self._head >= 0))

    def __contains__(self, father: object) -> bool:
        try:
            f = int(father)  # type: ignore[call-overload]
        except (TypeError, ValueError):
            return False
        return 0 <= f < len(self._head) and bool(self._head[f] >= 0)
