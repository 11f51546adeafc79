"""Packing triangular patches into 2^n x 2^n atlas pages (thesis 6.3, Algorithm 6.1).

Each patch is a triangle with its longest (base) edge along x and the apex above it, plus the
texels a bilinear lookup needs (its *footprint*, :mod:`unmesh.convert._patch_kernels`). Rows of
similar height are filled one after the other (Algorithm 6.1): the row height is the tallest
remaining patch, candidates are the patches at most ``dh`` lower; the next patch is the one
whose base angle is closest to the free base angle beta of the last patch of the row, flipped
horizontally when its right base angle fits better, every second one flipped vertically (apex
down, aligned with the top of the row), and pushed as far left as the row's per-scanline right
profile allows (``insert``). A patch that does not fit is left for a later row. When the
candidates are used up and the row still has room, it goes on with the tallest remaining
patches (an extension: Algorithm 6.1 would start a new row, which wastes most of the rows when
few patches share a height); when the tallest remaining patch no longer fits below the last
row, the rows go on with the patches that do.

Extensions (on by default, :func:`pack`): placed patches *slide* up and left into the gaps
of the rows above; patches of at least a quarter of the page edge go first, and the patches
left over when the rows are done go into the remaining holes, both by a bottom-left first fit
on the page's texel grid (:func:`unmesh.convert._packing_kernels.first_fit`).

Pages: a chain of full pages, each of the largest power-of-two edge (at most ``page_size``, at
least :data:`MIN_FULL_PAGE`) the remaining footprints can fill; at every link the smallest page
that would take all the rest is a candidate end of the atlas. The candidates are packed in the
order of their total page area and the first that takes all its patches ends the atlas (one that
does not is followed by a page of twice the edge, or by itself full plus a page for the rest), so
the atlas has the smallest total area among these ends. Then the smallest page of that atlas
(edge e) is replaced by three pages of e/2 (:func:`pack`, ``split_tail``): the other pages are
packed smallest first, then the three; taken when every patch fits. Fill is reported per page.

Example
-------
>>> import numpy as np
>>> masks = [np.ones((3, 4), bool)] * 10
>>> base = np.array([[1.0, 0.0]] * 10)  # base angles (left, right) in radians
>>> pl = pack(masks, np.full((10, 2), 1.0), page_size=64)
>>> len(pl.pages), bool((pl.x >= 0).all())
(1, True)
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass

import numpy as np

from unmesh.convert._packing_kernels import SCAN, pack_page
from unmesh.errors import InputError

__all__ = ["Placement", "base_angles", "fill_bound", "first_fit_reference", "pack", "pack_page_reference"]

#: Smallest edge of a page packed full before the rest goes on to further pages (the last page
#: may be smaller): the quick gallery atlas (600 triangles) gets 6 pages instead of 9 at the
#: same fill (0.77); 128 or 256 give 1-2 pages but fills of 0.35-0.44.
MIN_FULL_PAGE = 64

#: The tail split (:func:`pack`) is tried only when it would save at least this share of the
#: atlas area: a failed plan costs up to three packings of all the pages (Igea-like 11,340
#: patches: packing 6.0 -> 15.2 s CPU for a fill of 0.9389 -> 0.9398; Igea at the defaults
#: saves 0.96 %).
SPLIT_MIN_GAIN = 0.005


@dataclass
class Placement:
    """Where every patch went.

    Attributes
    ----------
    page, x, y : (P,) int64
        Page index and top-left texel of the patch's (flipped) mask in the page.
    flip_h, flip_v : (P,) bool
        Mirrored left-right / top-bottom.
    pages : list of int
        Edge of every page (powers of two).
    fill : list of float
        Footprint texels / page texels, per page.
    """

    page: np.ndarray
    x: np.ndarray
    y: np.ndarray
    flip_h: np.ndarray
    flip_v: np.ndarray
    pages: list[int]
    fill: list[float]


def base_angles(length: np.ndarray, apex: np.ndarray) -> np.ndarray:
    """Base angles (P, 2) (left, right) in radians of triangles with base ``length`` and apex (x, y)."""
    left = np.arctan2(apex[:, 1], apex[:, 0])
    right = np.arctan2(apex[:, 1], length - apex[:, 0])
    return np.stack([left, right], axis=1)


def _profiles(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last used column per mask row (empty rows: l = width, r = -1)."""
    w = mask.shape[1]
    any_ = mask.any(axis=1)
    left = np.where(any_, mask.argmax(axis=1), w)
    right = np.where(any_, w - 1 - mask[:, ::-1].argmax(axis=1), -1)
    return left, right


def pack_page_reference(items: list[int], masks: list[np.ndarray], angles: np.ndarray, edge: int, dh_frac: float,
                        out: Placement, page: int) -> list[int]:
    """Algorithm 6.1 on one page (plain numpy reference of the kernel's ``best_fit=0`` mode);
    returns the items that did not fit."""
    heights = np.array([masks[i].shape[0] for i in items], np.int64)
    item_angles = angles[np.asarray(items, dtype=np.int64)]
    remaining = np.ones(len(items), bool)
    ymin = 0
    while remaining.any():
        fits = remaining & (heights <= edge - ymin)  # at the bottom of the page: the lower patches
        if not fits.any():
            break
        hbar = int(heights[fits].max())
        dh = max(1, int(dh_frac * hbar))
        cand = np.flatnonzero(fits & (heights > hbar - dh))
        right_prof = np.zeros(hbar, np.int64)  # first free column per scanline of the row
        beta = np.pi / 2
        mirror = False
        failures = 0
        while failures < 8:
            if not len(cand):
                # the row still has room: go on with the tallest remaining patches (an extension
                # of Algorithm 6.1, which would leave the rest of the row empty)
                lower = remaining & (heights <= hbar)
                if not lower.any():
                    break
                h2 = int(heights[lower].max())
                cand = np.flatnonzero(lower & (heights > h2 - max(1, int(dh_frac * h2))))
            al = item_angles[cand[:SCAN]]  # the first SCAN candidates, as the kernel
            dl = np.abs(al[:, 0] - beta)
            dr = np.abs(al[:, 1] - beta)
            best = int(np.argmin(np.minimum(dl, dr)))
            ci = cand[best]
            i = items[ci]
            flip_h = bool(dl[best] > dr[best])
            mask = masks[i][:, ::-1] if flip_h else masks[i]
            new_beta = al[best, 0] if flip_h else al[best, 1]
            if mirror:
                mask = mask[::-1]
            h, w = mask.shape
            rows = np.arange(h) if mirror else np.arange(hbar - h, hbar)
            lft, rgt = _profiles(mask)
            used = rgt >= 0
            x0 = int(max(0, (right_prof[rows[used]] - lft[used]).max())) if used.any() else 0
            cand = np.delete(cand, best)
            if x0 + w > edge:
                failures += 1
                if not len(cand):
                    break
                continue
            right_prof[rows[used]] = x0 + rgt[used] + 1
            out.page[i], out.x[i], out.y[i] = page, x0, ymin + (0 if mirror else hbar - h)
            out.flip_h[i], out.flip_v[i] = flip_h, mirror
            remaining[ci] = False
            beta = new_beta
            mirror = not mirror
        ymin += hbar
    return [items[k] for k in np.flatnonzero(remaining)]


def first_fit_reference(items: list[int], masks: list[np.ndarray], grid: np.ndarray, out: Placement,
                        page: int) -> list[int]:
    """Bottom-left first fit (plain numpy reference of
    :func:`unmesh.convert._packing_kernels.first_fit` over all sizes): every item in order goes
    to the first free position in raster order in the first of its orientations (unflipped,
    flipped horizontally, vertically, both) that fits, skipping the positions that failed for
    an earlier patch of the same size. ``grid`` (E, E) bool is updated; returns the items that
    did not fit."""
    edge = grid.shape[0]
    cursor: dict[tuple[int, int], int] = {}
    rest = []
    for i in items:
        h, w = masks[i].shape
        orient = [masks[i], masks[i][:, ::-1], masks[i][::-1], masks[i][::-1, ::-1]]
        pos = cursor.get((h, w), 0)
        found = -1
        while h <= edge and w <= edge and pos <= (edge - h) * edge + edge - w:
            y, x = divmod(pos, edge)
            if x + w > edge:
                pos = (y + 1) * edge
                continue
            window = grid[y:y + h, x:x + w]
            found = next((o for o, m in enumerate(orient) if not (window & m).any()), -1)
            if found >= 0:
                break
            pos += 1
        cursor[(h, w)] = pos
        if found < 0:
            rest.append(i)
            continue
        grid[y:y + h, x:x + w] |= orient[found]
        out.page[i], out.x[i], out.y[i] = page, x, y
        out.flip_h[i], out.flip_v[i] = found in (1, 3), found >= 2
    return rest


def _copy(p: Placement) -> Placement:
    return Placement(p.page.copy(), p.x.copy(), p.y.copy(), p.flip_h.copy(), p.flip_v.copy(), [], [])


def _profile_arrays(masks: list[np.ndarray]) -> tuple[np.ndarray, ...]:
    """Heights, widths and the concatenated scanline profiles (first/last used column, -1: empty
    row) of the masks."""
    heights = np.array([m.shape[0] for m in masks], np.int64)
    widths = np.array([m.shape[1] for m in masks], np.int64)
    off = np.zeros(len(masks) + 1, np.int64)
    np.cumsum(heights, out=off[1:])
    nrow = int(off[-1])
    row_w = np.repeat(widths, heights)
    flat = np.concatenate([m.ravel() for m in masks])
    row = np.repeat(np.arange(nrow), row_w)
    start = np.zeros(nrow, np.int64)
    np.cumsum(row_w[:-1], out=start[1:])
    col = np.arange(len(flat)) - start[row]
    lft = row_w.copy()
    rgt = np.full(nrow, -1, np.int64)
    np.minimum.at(lft, row[flat], col[flat])
    np.maximum.at(rgt, row[flat], col[flat])
    return heights, widths, lft, rgt, off


def fill_bound(masks: list[np.ndarray], smallest: int = 16) -> float:
    """The largest atlas fill any packing into square power-of-two pages could reach.

    A patch of ``h x w`` texels needs a page of edge at least ``e = 2^ceil(log2 max(h, w))``
    (and ``smallest``); so for every edge e the pages of edge >= e hold at least the footprint
    texels of the patches needing e or more. Going down from the largest e, whole pages of
    edge e are added while that area is short; the bound is the footprint texels over the total
    area of these pages (exact packing of the areas assumed: an upper bound, not a layout).

    Example
    -------
    >>> import numpy as np
    >>> round(fill_bound([np.ones((65, 65), bool)]), 3)  # 65 x 65 needs a 128 page
    0.258
    """
    if not masks:
        return 1.0
    texels = np.array([int(m.sum()) for m in masks], np.int64)
    dim = np.array([max(m.shape) for m in masks], np.int64)
    need = np.maximum(smallest, 1 << np.ceil(np.log2(np.maximum(dim, 1))).astype(np.int64))
    total = 0
    for e in sorted(set(need.tolist()), reverse=True):
        short = int(texels[need >= e].sum()) - total
        if short > 0:
            total += -(-short // (e * e)) * e * e
    return float(texels.sum() / total)


def pack(masks: list[np.ndarray], angles: np.ndarray, page_size: int = 2048,
         dh_frac: float = 0.2, best_fit: int = 64, slide: bool = True, holes: bool = True,
         split_tail: bool = True) -> Placement:
    """Pack patch footprints (Algorithm 6.1) into power-of-two pages.

    The chain of full pages is built twice, with full pages down to :data:`MIN_FULL_PAGE` and
    to half of it, and the atlas of the smaller total page area wins (ties: fewer pages). On
    Igea at the defaults (dh_frac 0.05) the second gave pages 256 + 128 x 2 + 64 + 32 + 64 (fill 0.884)
    where the first ended with a 128 page filled 0.45 (0.828).

    Parameters
    ----------
    masks : list of (h, w) bool arrays
        Footprint of every patch, base edge at the bottom, apex up.
    angles : (P, 2) float64
        Base angles (left, right), :func:`base_angles`.
    page_size : int
        Largest page edge (a power of two).
    dh_frac : float
        Height tolerance of a row (fraction of its height, at least one texel). 0.2 (with
        ``best_fit=64``) instead of the former 0.05 (with 16): Igea's 1,690 patches 0.884 -> 0.892,
        1,500 random patches 0.917 -> 0.940, 3,000 Igea-like ones 0.899 -> 0.936 (docs/convert.md).
    best_fit : int
        0: Algorithm 6.1 as in the thesis (the next patch of a row by base angle). K > 0: the
        K candidates closest in angle are tried in all four orientations and the one leaving
        the fewest free texels wins (:mod:`unmesh.convert._packing_kernels`).
    slide, holes : bool
        Extensions of the kernel (:func:`unmesh.convert._packing_kernels.pack_page`).
    split_tail : bool
        Try an atlas of 3/4 of the smallest page's area less: that page replaced by three of
        half its edge, the larger pages packed smallest first (a small page filled around a
        large patch packs better than one of the small patches left at the end), with half the
        height tolerance, the given row settings, or four times ``best_fit``; kept when it
        places every patch (tried only when it saves at least :data:`SPLIT_MIN_GAIN` of the
        area). Igea at the defaults: pages 256 + 128 x 2 + 64 x 2 (fill 0.892) ->
        256 + 128 x 2 + 64 + 32 x 3 (0.901), packing 0.8 -> 1.1 s CPU (docs/convert.md).

    Returns
    -------
    Placement
    """
    tries = [_pack_chain(masks, angles, page_size, dh_frac, best_fit, slide, holes, min_full)
             for min_full in (MIN_FULL_PAGE, MIN_FULL_PAGE // 2)]
    best = min(tries, key=lambda pl: (sum(e * e for e in pl.pages), len(pl.pages)))
    if split_tail and len(masks):
        best = _split_tail(masks, angles, best, dh_frac, best_fit, slide, holes) or best
    return best


def _split_tail(masks: list[np.ndarray], angles: np.ndarray, chain: Placement, dh_frac: float, best_fit: int,
                slide: bool, holes: bool) -> Placement | None:
    """An atlas of smaller total area than ``chain``'s: its smallest page (edge e) replaced by
    three pages of e/2 (3/4 of the area), the pages of at least e packed smallest first (a
    large patch with small ones around it fills a small page better than the small patches
    left over at the end), then the new tail pages. Tried with half the height tolerance, with
    the given row settings and with four times the best-fit candidates; the first plan that
    places every patch wins (None: none does)."""
    pages = sorted(chain.pages)
    e = pages[0]
    if e < 32 or e * e / 4 < SPLIT_MIN_GAIN * sum(p * p for p in pages):
        return None
    plan = [*pages[1:], e // 2, e // 2, e // 2]
    heights, widths, lft, rgt, off = _profile_arrays(masks)
    area = np.array([m.sum() for m in masks], np.int64)
    if area.sum() > sum(p * p for p in plan):
        return None
    left_a = np.ascontiguousarray(angles[:, 0], dtype=np.float64)
    right_a = np.ascontiguousarray(angles[:, 1], dtype=np.float64)
    n = len(masks)
    for dh, bf in ((dh_frac / 2, best_fit), (dh_frac, best_fit), (dh_frac, 4 * best_fit)):
        out = Placement(np.zeros(n, np.int64), np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros(n, bool),
                        np.zeros(n, bool), [], [])
        left = np.argsort(-heights, kind="stable").astype(np.int64)
        for k, edge in enumerate(plan):
            fits = (heights[left] <= edge) & (widths[left] <= edge)
            items = left[fits]
            rest = pack_page(items, heights, widths, lft, rgt, off, left_a, right_a, edge, float(dh), int(bf),
                             out.page, out.x, out.y, out.flip_h, out.flip_v, k, slide,
                             max(1, edge // 4) if holes else 0, holes)
            left = np.concatenate([left[~fits], items[rest]])
            left = left[np.argsort(-heights[left], kind="stable")]
            if area[left].sum() > sum(p * p for p in plan[k + 1:]):
                break  # the rest cannot fit the pages to come
        if len(left) == 0:
            # pages largest first (stable), as the chain lists them
            order = sorted(range(len(plan)), key=lambda k: -plan[k])
            rank = np.empty(len(plan), np.int64)
            rank[order] = np.arange(len(plan))
            out.page = rank[out.page]
            out.pages = [plan[k] for k in order]
            per_page = np.bincount(out.page, weights=area, minlength=len(out.pages))
            out.fill = [float(a / p**2) for a, p in zip(per_page, out.pages, strict=True)]
            return out
    return None


def _pack_chain(masks: list[np.ndarray], angles: np.ndarray, page_size: int, dh_frac: float, best_fit: int,
                slide: bool, holes: bool, min_full: int) -> Placement:
    """:func:`pack` with full pages of at least ``min_full`` texels."""
    n = len(masks)
    for m in masks:
        if m.shape[1] > page_size or m.shape[0] > page_size:
            raise InputError(f"page_size: a patch of {m.shape[1]} x {m.shape[0]} texels does not fit pages of {page_size}")
    out = Placement(np.zeros(n, np.int64), np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.zeros(n, bool),
                    np.zeros(n, bool), [], [])
    if n == 0:
        return out
    heights, widths, lft, rgt, off = _profile_arrays(masks)
    left_a = np.ascontiguousarray(angles[:, 0], dtype=np.float64)
    right_a = np.ascontiguousarray(angles[:, 1], dtype=np.float64)
    area = np.array([m.sum() for m in masks], np.float64)
    left = np.argsort(-heights, kind="stable").astype(np.int64)

    def attempt(base: Placement, items: np.ndarray, edge: int, page: int) -> tuple[Placement, np.ndarray]:
        trial = _copy(base)
        rest = pack_page(items, heights, widths, lft, rgt, off, left_a, right_a, edge, float(dh_frac),
                         int(best_fit), trial.page, trial.x, trial.y, trial.flip_h, trial.flip_v, page, slide,
                         max(1, edge // 4) if holes else 0, holes)
        return trial, items[rest]

    # A chain of full pages (B: the largest edge the remaining patches can fill); at every link,
    # the smallest page that would take all the rest (A) is a candidate end of the atlas whose
    # total page area is known before packing it. The candidates are packed in the order of their
    # total area; the first one that takes all its patches wins (one that does not becomes two
    # new candidates: a page of twice the edge, and that page full with the rest on a further
    # page). The chain has no full pages smaller than MIN_FULL_PAGE: they would split small
    # atlases into many tiny pages.
    # heap entries: total area, tie-breaker, pages before, last edge, placement so far, patches left
    heap: list[tuple[int, int, tuple[int, ...], int, Placement, np.ndarray]] = []
    finished: tuple[int, tuple[int, ...], Placement] | None = None  # area, pages, placement
    chain: list[int] = []
    base, used = out, 0
    result = None
    tried: set[tuple[tuple[int, ...], int]] = set()  # candidate ends packed already
    counter = itertools.count()

    def end_edge(items: np.ndarray) -> int:
        """The smallest page that could take all ``items`` (at 95 % fill)."""
        need = area[items].sum()
        big = int(max(heights[items].max(), widths[items].max()))
        smallest = max(16, 1 << int(np.ceil(np.log2(big))))
        return min(page_size, max(smallest, 1 << int(np.ceil(np.log2(np.sqrt(need / 0.95))))))

    while result is None:  # again from the end of the chain when every candidate end failed
        while len(left):
            need = area[left].sum()
            big = int(max(heights[left].max(), widths[left].max()))
            smallest = max(16, 1 << int(np.ceil(np.log2(big))))
            edge_a = end_edge(left)
            edge_b = min(page_size, max(smallest, 1 << int(np.floor(np.log2(np.sqrt(need))))))
            if need <= edge_a**2 and (tuple(chain), edge_a) not in tried:
                heapq.heappush(heap, (used + edge_a**2, next(counter), tuple(chain), edge_a, base, left))
            if heap and (edge_a <= edge_b or edge_b < min(page_size, min_full) or used + edge_b**2 >= heap[0][0]):
                break  # B would be A's page again, a tiny page, or no better than a candidate end
            trial_b, rest_b = attempt(base, left, edge_b, len(chain))
            if len(rest_b) == len(left):
                if not heap:
                    raise InputError(f"page_size: {page_size} is too small for the patches")
                break
            if len(rest_b) == 0:
                finished = (used + edge_b**2, (*chain, edge_b), trial_b)
                break
            chain.append(edge_b)
            used += edge_b**2
            base, left = trial_b, rest_b
        result = finished
        while heap and (result is None or heap[0][0] < result[0]):
            total, _, before, edge, base_k, items = heapq.heappop(heap)
            tried.add((before, edge))
            trial, rest = attempt(base_k, items, edge, len(before))
            if len(rest) == 0:
                result = (total, (*before, edge), trial)
                continue
            # the candidate was too small: a page of twice the edge, or this page full and the
            # rest on a further page
            if edge < page_size:
                heapq.heappush(heap, (total - edge**2 + (2 * edge) ** 2, next(counter), before, 2 * edge, base_k, items))
            if len(rest) < len(items):
                e2 = end_edge(rest)
                if area[rest].sum() <= e2**2:
                    heapq.heappush(heap, (total + e2**2, next(counter), (*before, edge), e2, trial, rest))
        if result is None and not len(left):
            break
    if result is None:
        raise InputError(f"page_size: {page_size} is too small for the patches")
    _, pages, placed = result
    placed.pages = list(pages)
    per_page = np.bincount(placed.page, weights=area, minlength=len(placed.pages))
    placed.fill = [float(a / e**2) for a, e in zip(per_page, placed.pages, strict=True)]
    return placed
