"""Pen samples resampled on the surface at the engine's dab spacing.

The page sends pen samples evenly spaced on the screen (two fifths of the brush size at the
view's target); ray-cast onto a surface that slants away from the viewer, consecutive points lie
farther apart in the world, and ``Session.add_samples`` adds a paint event in between wherever
two samples are more than ``DAB_STEP * size`` apart (``unmesh.paint.session.DAB_STEP``), so a
sample just beyond the step costs two events at half the step. :class:`DabResampler` walks the
polyline of the ray-cast points and emits a sample every ``spacing`` of arc length (time,
pressure and tilt interpolated linearly, as the engine interpolates its in-between events):
with ``spacing`` just below the engine's step the engine paints exactly these samples, one
event each, whatever the slant, and the stroke is sampled as densely as its dab spacing
defines. The first point is emitted at once, the rest of the polyline beyond the last emitted
sample (less than ``spacing``) by :meth:`DabResampler.finish` at the end of the stroke.

A jump longer than ``max_gap`` (the pen crossed a hole or the silhouette, or the ray hit another
part of the surface) is not resampled: both its ends are emitted and the polyline starts again,
so the engine paints across it as before (its own in-between events), and no resampled point
lies in the air far from the surface (``add_samples`` refuses those). The studio also ends the
polyline where a sample misses the surface (:meth:`DabResampler.finish`).

The output depends only on the sequence of points, not on how they were split into ``push``
calls (the studio's messages and frames): the carried arc length is the only state.

Example
-------
>>> r = DabResampler(1.0)
>>> [s[1] for s in r.push((0.0, (0.0, 0.0, 0.0), 0.5, (0.0, 0.0)))]
[(0.0, 0.0, 0.0)]
>>> [s[1] for s in r.push((1.0, (2.5, 0.0, 0.0), 0.5, (0.0, 0.0)))]
[(1.0, 0.0, 0.0), (2.0, 0.0, 0.0)]
>>> [s[1] for s in r.finish()]
[(2.5, 0.0, 0.0)]
"""

from __future__ import annotations

import math

from unmesh.errors import InputError

__all__ = ["DabResampler", "Point"]

#: A pen sample on the surface: (t seconds, (x, y, z), pressure, (tilt_x, tilt_y)).
Point = tuple[float, tuple[float, float, float], float, tuple[float, float]]


class DabResampler:
    """Resamples a stream of surface points at a fixed arc-length ``spacing`` (see the module notes).

    Parameters
    ----------
    spacing : float
        Arc length between emitted samples (world units), > 0.
    max_gap : float, optional
        Longest segment that is resampled (default ``4 * spacing``); longer ones restart the polyline.
    """

    def __init__(self, spacing: float, max_gap: float | None = None) -> None:
        for key, v in (("spacing", spacing), ("max_gap", spacing if max_gap is None else max_gap)):
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
                raise InputError(f"{key}: expected a positive finite number, got {v!r}")
        self.spacing = float(spacing)
        self.max_gap = 4.0 * self.spacing if max_gap is None else float(max_gap)
        self._last: Point | None = None
        self._carry = 0.0  # arc length from the last emitted sample to self._last

    def push(self, p: Point) -> list[Point]:
        """The samples emitted when the polyline is extended to ``p`` (in order; possibly none)."""
        a = self._last
        self._last = p
        if a is None:
            return [p]
        seg = math.dist(a[1], p[1])
        if seg > self.max_gap:  # not across a gap: its ends, then a new polyline
            out = [a] if self._carry > 0.0 else []
            self._carry = 0.0
            return [*out, p]
        out: list[Point] = []
        d = self.spacing - self._carry  # arc length along this segment to the next sample
        while d <= seg:
            out.append(_lerp(a, p, d / seg))
            d += self.spacing
        self._carry = seg - (d - self.spacing)
        return out

    def finish(self) -> list[Point]:
        """The last point of the polyline when it lies beyond the last emitted sample (the
        stroke's end); the resampler then starts a new polyline."""
        last, carry = self._last, self._carry
        self._last, self._carry = None, 0.0
        return [last] if last is not None and carry > 0.0 else []


def _lerp(a: Point, b: Point, f: float) -> Point:
    if f == 1.0:
        return b
    return (a[0] + f * (b[0] - a[0]), tuple(u + f * (v - u) for u, v in zip(a[1], b[1], strict=True)),  # type: ignore[return-value]
            a[2] + f * (b[2] - a[2]), tuple(u + f * (v - u) for u, v in zip(a[3], b[3], strict=True)))
