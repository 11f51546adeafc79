"""Numba kernel of Algorithm 6.1 on one atlas page (thesis 6.3), with an optional best-fit choice.

Patches are given by their scanline profiles: for mask row r of patch i, ``lft[off[i] + r]`` is
the first and ``rgt[off[i] + r]`` the last used column (``-1``: empty row). :func:`pack_page`
fills rows of similar height left to right, every patch pushed as far left as the row's
per-scanline right profile allows. Two ways to choose the next patch of a row:

* ``best_fit = 0`` (Algorithm 6.1): the candidate whose left or right base angle is closest
  to the free angle beta of the last patch (flipped horizontally when the right one fits
  better), every second patch upside down. :func:`unmesh.convert.packing.pack_page_reference`
  is the plain numpy reference of this mode.
* ``best_fit = K > 0`` (an extension): the K candidates closest in angle are tried in all four
  orientations (flipped horizontally and/or upside down) and the placement that leaves the
  fewest free texels between the row's profile and the patch wins (ties: the closer angle).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["SCAN", "first_fit", "pack_page"]

#: Candidates of a row compared for the next patch: the first SCAN in the given order (rows of
#: thousands of equally tall tiny patches would otherwise cost a scan of all of them per patch).
SCAN = 512


@njit(cache=True, inline="always")
def _span(i, r, flip_h, flip_v, hbar, lft, rgt, off, h, w):
    """Row of the page, first and last used column of row ``r`` of patch i placed in a row of
    height ``hbar`` in the given orientation (row -1: the mask row is empty)."""
    src = h - 1 - r if flip_v else r
    if rgt[off[i] + src] < 0:
        return -1, 0, 0
    lo = lft[off[i] + src]
    hi = rgt[off[i] + src]
    if flip_h:
        lo, hi = w - 1 - hi, w - 1 - lft[off[i] + src]
    return (r if flip_v else hbar - h + r), lo, hi


@njit(cache=True)
def _fit(i, flip_h, mirror, hbar, lft, rgt, off, heights, widths, right_prof):
    """x0 and the free texels left of patch i in one orientation (x0 = -1: empty patch)."""
    h = heights[i]
    w = widths[i]
    x0 = 0
    for r in range(h):
        row, lo, _hi = _span(i, r, flip_h, mirror, hbar, lft, rgt, off, h, w)
        if row >= 0:
            x0 = max(x0, right_prof[row] - lo)
    waste = 0
    for r in range(h):
        row, lo, _hi = _span(i, r, flip_h, mirror, hbar, lft, rgt, off, h, w)
        if row >= 0:
            waste += x0 + lo - right_prof[row]
    return x0, waste


@njit(cache=True)
def _free(grid, i, flip_h, flip_v, y0, x0, lft, rgt, off, h, w):
    """True when patch i (in the given orientation) at top-left (y0, x0) of the page touches no
    used texel of ``grid`` and stays inside it."""
    edge = grid.shape[0]
    if y0 < 0 or x0 < 0 or y0 + h > edge or x0 + w > edge:
        return False
    for r in range(h):
        row, lo, hi = _span(i, r, flip_h, flip_v, h, lft, rgt, off, h, w)
        if row < 0:
            continue
        for c in range(x0 + lo, x0 + hi + 1):
            if grid[y0 + row, c]:
                return False
    return True


@njit(cache=True)
def _slide(grid, i, flip_h, flip_v, y0, x0, lft, rgt, off, h, w):
    """Slide a placed patch up, then left, as long as it stays free; repeated until it is stuck.
    Returns the new (y0, x0)."""
    moved = True
    while moved:
        moved = False
        while _free(grid, i, flip_h, flip_v, y0 - 1, x0, lft, rgt, off, h, w):
            y0 -= 1
            moved = True
        while _free(grid, i, flip_h, flip_v, y0, x0 - 1, lft, rgt, off, h, w):
            x0 -= 1
            moved = True
    return y0, x0


@njit(cache=True)
def _mark(grid, i, flip_h, flip_v, y0, x0, lft, rgt, off, h, w):
    """Mark the texels of patch i placed at (y0, x0) used."""
    for r in range(h):
        row, lo, hi = _span(i, r, flip_h, flip_v, h, lft, rgt, off, h, w)
        if row >= 0:
            for c in range(x0 + lo, x0 + hi + 1):
                grid[y0 + row, c] = True


@njit(cache=True)
def first_fit(items, remaining, lo_s, hi_s, heights, widths, lft, rgt, off, grid, page_of, xs, ys, flip_hs,
              flip_vs, page):
    """Bottom-left first fit on the texel grid of a page (an extension of Algorithm 6.1).

    Every unplaced item of size ``lo_s <= max(height, width) <= hi_s``, in the given order, goes to the first
    free position in raster order (row by row from the top, left to right) in any of its four
    orientations (unflipped, flipped horizontally, vertically, both; the first that fits). A
    position that did not fit a patch of a given (height, width) is not tried again for that
    size (the grid only fills up), so each size scans the page at most once.

    Parameters
    ----------
    items : (n,) int64
    remaining : (n,) bool
        Unplaced items; cleared for the placed ones.
    lo_s, hi_s : int
        Size range (the larger of height and width) of the items placed here.
    heights, widths, lft, rgt, off
        As in :func:`pack_page`.
    grid : (E, E) bool
        Used texels of the page; updated.
    page_of, xs, ys, flip_hs, flip_vs, page
        As in :func:`pack_page`.
    """
    edge = grid.shape[0]
    hmax = 1
    wmax = 1
    for k in range(len(items)):
        hmax = max(hmax, heights[items[k]])
        wmax = max(wmax, widths[items[k]])
    cursor = np.zeros((hmax + 1, wmax + 1), np.int64)
    for k in range(len(items)):
        i = items[k]
        h = heights[i]
        w = widths[i]
        if not remaining[k] or max(h, w) < lo_s or max(h, w) > hi_s or h > edge or w > edge:
            continue
        pos = cursor[h, w]
        last = (edge - h) * edge + edge - w
        found = -1
        while pos <= last:
            y = pos // edge
            x = pos - y * edge
            if x + w > edge:  # next row
                pos = (y + 1) * edge
                continue
            for o in range(4):
                if _free(grid, i, o == 1 or o == 3, o >= 2, y, x, lft, rgt, off, h, w):
                    found = o
                    break
            if found >= 0:
                break
            pos += 1
        cursor[h, w] = pos
        if found < 0:
            continue
        fh = found == 1 or found == 3
        fv = found >= 2
        _mark(grid, i, fh, fv, y, x, lft, rgt, off, h, w)
        page_of[i] = page
        xs[i] = x
        ys[i] = y
        flip_hs[i] = fh
        flip_vs[i] = fv
        remaining[k] = False


@njit(cache=True)
def pack_page(items, heights, widths, lft, rgt, off, left_angle, right_angle, edge, dh_frac, best_fit,
              page_of, xs, ys, flip_hs, flip_vs, page, slide=False, big=0, holes=False):
    """Algorithm 6.1 on one ``edge`` x ``edge`` page.

    Parameters
    ----------
    items : (n,) int64
        Patches to place, tallest first.
    heights, widths : (P,) int64
    lft, rgt, off : int64 arrays
        Scanline profiles (module notes); ``off`` (P + 1,).
    left_angle, right_angle : (P,) float64
        Base angles of the unflipped patches.
    edge : int
    dh_frac : float
        Height tolerance of a row.
    best_fit : int
        0: Algorithm 6.1; K > 0: best fit among the K candidates closest in angle.
    page_of, xs, ys : (P,) int64, flip_hs, flip_vs : (P,) bool
        Written for the placed patches.
    page : int
    slide : bool
        Extension: every placed patch slides up, then left, while it stays free (into the gaps
        of the rows above it), and the next row starts below the lowest texel of the row.
    big : int
        Extension: patches at least ``big`` texels tall or wide (0: none) are placed first by
        :func:`first_fit`, the rows of Algorithm 6.1 start below them.
    holes : bool
        Extension: when the rows are done, the patches left over go into the remaining holes by
        :func:`first_fit`.

    Returns
    -------
    (n,) bool
        Which of ``items`` are still unplaced.
    """
    n = len(items)
    remaining = np.ones(n, np.bool_)
    hs = np.empty(n, np.int64)
    for k in range(n):
        hs[k] = heights[items[k]]
    cand = np.empty(n, np.int64)
    right_prof = np.zeros(edge, np.int64)
    grid = np.zeros((edge, edge), np.bool_)
    top_k = np.empty(max(best_fit, 1), np.int64)
    top_d = np.empty(max(best_fit, 1))
    ymin = 0
    if big > 0:
        first_fit(items, remaining, big, edge, heights, widths, lft, rgt, off, grid, page_of, xs, ys, flip_hs,
                  flip_vs, page)
        for k in range(n):
            if not remaining[k]:
                ymin = max(ymin, ys[items[k]] + hs[k])
    while True:
        hbar = -1
        for k in range(n):
            if remaining[k] and hs[k] <= edge - ymin and hs[k] > hbar:
                hbar = hs[k]
        if hbar < 0:
            break
        dh = max(1, int(dh_frac * hbar))
        nc = 0
        for k in range(n):
            if remaining[k] and hs[k] <= edge - ymin and hs[k] > hbar - dh:
                cand[nc] = k
                nc += 1
        for r in range(hbar):
            right_prof[r] = 0
        beta = np.pi / 2
        mirror = False
        failures = 0
        row_end = ymin
        while failures < 8:
            if nc == 0:
                h2 = -1
                for k in range(n):
                    if remaining[k] and hs[k] <= hbar and hs[k] > h2:
                        h2 = hs[k]
                if h2 < 0:
                    break
                d2 = max(1, int(dh_frac * h2))
                for k in range(n):
                    if remaining[k] and hs[k] <= hbar and hs[k] > h2 - d2:
                        cand[nc] = k
                        nc += 1
            if best_fit == 0:
                best = 0
                bd = np.inf
                for c in range(min(nc, SCAN)):
                    i = items[cand[c]]
                    d = min(abs(left_angle[i] - beta), abs(right_angle[i] - beta))
                    if d < bd:
                        bd = d
                        best = c
                i = items[cand[best]]
                flip_h = abs(left_angle[i] - beta) > abs(right_angle[i] - beta)
                flip_v = mirror
                x0, _ = _fit(i, flip_h, flip_v, hbar, lft, rgt, off, heights, widths, right_prof)
            else:
                # the best_fit candidates closest in angle (insertion into a short sorted list)
                m = 0
                for c in range(min(nc, SCAN)):
                    i = items[cand[c]]
                    d = min(abs(left_angle[i] - beta), abs(right_angle[i] - beta))
                    if m < best_fit:
                        m += 1
                    elif d >= top_d[m - 1]:
                        continue
                    j = m - 1
                    while j > 0 and top_d[j - 1] > d:
                        top_d[j] = top_d[j - 1]
                        top_k[j] = top_k[j - 1]
                        j -= 1
                    top_d[j] = d
                    top_k[j] = c
                best = top_k[0]
                bw = -1
                x0 = 0
                flip_h = False
                flip_v = False
                for j in range(m):
                    i = items[cand[top_k[j]]]
                    for o in range(2):
                        fh = o == 1
                        fv = mirror
                        xo, wo = _fit(i, fh, fv, hbar, lft, rgt, off, heights, widths, right_prof)
                        if xo + widths[i] > edge:
                            continue
                        if bw < 0 or wo < bw:
                            bw = wo
                            best = top_k[j]
                            x0 = xo
                            flip_h = fh
                            flip_v = fv
                i = items[cand[best]]
                if bw < 0:
                    x0 = edge  # nothing fits: fail below
            ci = cand[best]
            for c in range(best, nc - 1):  # delete, keeping the order (ties go to the first)
                cand[c] = cand[c + 1]
            nc -= 1
            if x0 + widths[i] > edge:
                failures += 1
                if nc == 0:
                    break
                continue
            h = heights[i]
            w = widths[i]
            y0 = ymin + (0 if flip_v else hbar - h)
            if slide:
                y0, x0 = _slide(grid, i, flip_h, flip_v, y0, x0, lft, rgt, off, h, w)
            _mark(grid, i, flip_h, flip_v, y0, x0, lft, rgt, off, h, w)
            for r in range(h):
                row, _lo, hi = _span(i, r, flip_h, flip_v, h, lft, rgt, off, h, w)
                if row < 0:
                    continue
                if y0 + row >= ymin:
                    right_prof[y0 + row - ymin] = max(right_prof[y0 + row - ymin], x0 + hi + 1)
                row_end = max(row_end, y0 + row + 1)
            page_of[i] = page
            xs[i] = x0
            ys[i] = y0
            flip_hs[i] = flip_h
            flip_vs[i] = flip_v
            remaining[ci] = False
            beta = left_angle[i] if flip_h else right_angle[i]
            mirror = not flip_v
        ymin = row_end if slide and row_end > ymin else ymin + hbar
    if holes:
        first_fit(items, remaining, 0, edge, heights, widths, lft, rgt, off, grid, page_of, xs, ys, flip_hs,
                  flip_vs, page)
    return remaining
