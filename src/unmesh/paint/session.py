"""A painting session (thesis chapter 5): strokes, undo/redo, background work, rendering, files.

Example
-------
>>> from unmesh.shapes import by_name
>>> from unmesh.paint import Brush, Paint, Sample, Session
>>> s = Session(by_name("plane", size=1.0).surfels(0.05), PaintOptions(haptics=False))
>>> r = s.stroke([Sample(0.0, (0, 0, 0), 0.8), Sample(0.1, (0.1, 0, 0), 0.8)],
...              brush=Brush("round", 0.04), paint=Paint("oil", (1, 0, 0)))
>>> r.added > 0
True
>>> s.undo(), s.undo()
(True, False)
"""

from __future__ import annotations

import functools
import json
import os
import threading
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from unmesh.errors import FormatError, InputError
from unmesh.paint import background
from unmesh.paint.brush import K_PENALTY, BrushState, cross3
from unmesh.paint.collide import force_shading
from unmesh.paint.haptic import HapticLoop, HapticProcess, haptic_force
from unmesh.paint.strokes import Brush, Paint, Sample, check_samples, parse_strokes, stroke_dict
from unmesh.paint.surface import FIELDS, PaintSurface, state_colors
from unmesh.paint.transfer import paint_event
from unmesh.paint.view import PaintView, unproject
from unmesh.render import Camera
from unmesh.render.shading import RenderResult
from unmesh.surfels import SurfelCloud

__all__ = ["DAB_STEP", "PaintOptions", "Session", "StrokeResult"]

_META = "unmesh-paint "
#: Interaction time of the first sample of a stroke (s).
FIRST_DT = 1.0 / 30.0
#: Largest distance between two paint events, in brush sizes: :meth:`Session.add_samples` adds
#: events in between wherever consecutive samples are farther apart (the dab spacing).
DAB_STEP = 0.5
_BRISTLE = np.array([0.86, 0.8, 0.66])


@dataclass(frozen=True)
class PaintOptions:
    """Session options.

    Parameters
    ----------
    mixing : {"rgb", "km"}
        RGB mixing by volume (5.11) or Kubelka-Munk.
    steps : int
        Verlet steps of the brush per paint event.
    haptics : bool or {"thread", "process"}
        Start the 1 kHz haptic loop at the first :meth:`Session.begin_stroke`: in a thread
        (``True`` or ``"thread"``) or in its own process (``"process"``: lower jitter while
        painting, as it never waits for the painting loop's interpreter lock).
    color_variance, normal_variance : float
        Downsampling thresholds (5.5.2): children merge into their father when the variance of
        their visible colours (sum over RGB) and ``1 - |mean normal|`` are below these.
    """

    mixing: str = "rgb"
    steps: int = 12
    haptics: bool | str = True
    color_variance: float = 2e-4
    normal_variance: float = 2e-3

    def __post_init__(self) -> None:
        if self.mixing not in ("rgb", "km"):
            raise InputError(f"options.mixing: expected 'rgb' or 'km', got {self.mixing!r}")
        if self.haptics not in (True, False, "thread", "process"):
            raise InputError(f"options.haptics: expected True, False, 'thread' or 'process', got {self.haptics!r}")
        if int(self.steps) != self.steps or self.steps < 1:
            raise InputError(f"options.steps: expected a positive integer, got {self.steps!r}")


@dataclass(frozen=True)
class StrokeResult:
    """What a stroke (or a batch of samples) did: rows removed and added, penetrated pixels."""

    changed: int
    added: int
    removed: int
    pixels: int
    events: int


def _locked(method: Any) -> Any:
    """Run a session method under the session's lock (a studio may paint, render and save from
    different threads)."""

    @functools.wraps(method)
    def wrapper(self: Session, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return method(self, *args, **kwargs)
    return wrapper


class _Open:
    def __init__(self, brush: Brush, paint: Paint) -> None:
        self.brush = brush
        self.paint = paint
        self.state = BrushState(brush)
        self.state.load(paint.color, paint.thickness)
        self.samples: list[Sample] = []
        self.last: Sample | None = None
        self.last_point: np.ndarray | None = None
        self.across: np.ndarray | None = None
        self.added = self.removed = self.pixels = 0


class Session:
    """Painting on a surfel model (see :mod:`unmesh.paint`).

    Parameters
    ----------
    cloud : SurfelCloud
    options : PaintOptions, optional
    """

    def __init__(self, cloud: SurfelCloud, options: PaintOptions | None = None, *,
                 _surface: PaintSurface | None = None) -> None:
        self.options = options if options is not None else PaintOptions()
        if not isinstance(self.options, PaintOptions):
            raise InputError(f"options: expected PaintOptions, got {type(self.options).__name__}")
        self._lock = threading.RLock()
        self.surface = _surface if _surface is not None else PaintSurface(cloud)
        self.time = 0.0
        self.view_axes = (np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
        self._strokes: list[dict[str, Any]] = []
        self._pre_advance: list[float] = []
        self._undo: list[tuple[list[dict[str, Any]], dict[str, Any]]] = []
        self._redo: list[tuple[list[dict[str, Any]], dict[str, Any]]] = []
        self._open: dict[int, _Open] = {}
        self._next_id = 1
        self._tail = False
        self._cursor = 0
        self._views: dict[tuple[int, int], PaintView] = {}
        self._view: PaintView | None = None
        self._last_brush: BrushState | None = None
        self._haptic = HapticProcess(K_PENALTY) if self.options.haptics == "process" else HapticLoop(K_PENALTY)
        b = self.surface.pos[:self.surface.n_original]
        self._diag = float(np.linalg.norm(b.max(axis=0) - b.min(axis=0)))

    # -- strokes -------------------------------------------------------------------------------
    def _close_tail(self) -> None:
        if self._tail:
            rec = self.surface.end_record()
            self._undo[-1][0].append(rec)
            self._tail = False

    @_locked
    def begin_stroke(self, brush: Brush, paint: Paint) -> int:
        """Start a stroke; returns its id for :meth:`add_samples` / :meth:`end_stroke`."""
        if not isinstance(brush, Brush):
            raise InputError(f"brush: expected a Brush, got {type(brush).__name__}")
        if not isinstance(paint, Paint):
            raise InputError(f"paint: expected a Paint, got {type(paint).__name__}")
        if self._open:
            raise InputError(f"begin_stroke: stroke {next(iter(self._open))} is still open (end_stroke it first)")
        if 2.0 * brush.size > self._diag:
            raise InputError(f"brush.size: expected a brush smaller than the model (diagonal {self._diag:.4g}), "
                             f"got size {brush.size:.4g}")
        self._close_tail()
        self.surface.begin_record()
        sid = self._next_id
        self._next_id += 1
        self._open[sid] = _Open(brush, paint)
        if self.options.haptics and not self._haptic.running:
            self._haptic.start()
        return sid

    def _get(self, sid: int) -> _Open:
        st = self._open.get(sid)
        if st is None:
            raise InputError(f"stroke: no open stroke with id {sid!r}")
        return st

    @_locked
    def add_samples(self, sid: int, samples: Any) -> StrokeResult:
        """Paint the samples of an open stroke (one paint event each)."""
        st = self._get(sid)
        base = len(st.samples)
        samples = check_samples(samples)
        s = self.surface
        no = s.n_original
        if samples:
            if st.last is not None and samples[0].t < st.last.t:
                raise InputError(f"samples[{base}].t: expected times that do not decrease, got {samples[0].t} "
                                 f"after {st.last.t}")
            pts = np.array([smp.point for smp in samples])
            dist, _ = s.tree.knn(pts, 1)
            limit = 2.0 * st.brush.size + 4.0 * s.mean_radius
            miss = np.flatnonzero(dist[:, 0] > limit)
            if len(miss):
                i = int(miss[0])
                raise InputError(f"samples[{base + i}].point: misses the model (distance {dist[i, 0]:.4g} from the "
                                 f"surface, at most {limit:.4g})")
        a0, r0, p0 = st.added, st.removed, st.pixels
        for smp in _subdivide(st.last, samples, DAB_STEP * st.brush.size):
            p = np.array(smp.point)
            # the brush's candidate ball of the last event answers exactly (or asks the tree)
            ball = st.state.ball if st.state.ball is not None and st.state.ball.tree is s.tree else s.tree
            d, N = force_shading(ball, s.pos[:no], s.nrm[:no], p[None])
            n = N[0]
            rx, ry = self.view_axes
            axis = _rotate(_rotate(n, rx, smp.tilt[0]), ry, smp.tilt[1])
            move = p - st.last_point if st.last_point is not None else np.zeros(3)
            across = _across(axis, move, st.across, rx)
            st.across = across
            R = np.stack([across, cross3(axis, across), axis], axis=1)
            b = st.state
            L = 3.0 * st.brush.size
            surface_pt = p + d[0] * n
            origin = surface_pt + axis * (b.sk.lower - smp.pressure * (b.sk.lower + 0.4 * L))
            b.simulate(s.tree, s.pos[:no], s.nrm[:no], origin, R, self.options.steps)
            dt = FIRST_DT if st.last is None else smp.t - st.last.t
            km = self.options.mixing == "km"
            if smp.pressure > 0 and dt > 0:
                if b.split:
                    results = [paint_event(s, b, st.paint, smp.pressure, dt, move, tip=b.x[k],
                                           body=b.transfer_body(k), km=km)
                               for k in range(len(b.x)) if b.colliding[k]]
                else:
                    results = [paint_event(s, b, st.paint, smp.pressure, dt, move, body=b.transfer_body(), km=km)]
                for r in results:
                    st.added += len(r.added)
                    st.removed += len(r.removed)
                    st.pixels += r.pixels
            self._haptic.publish(b.handle_depth, b.handle_normal, b.handle_velocity, st.brush.friction,
                                 b.spring_reaction)
            if not getattr(smp, "_between", False):
                st.samples.append(smp)
            st.last = smp
            st.last_point = p
        self._last_brush = st.state
        return StrokeResult(st.added - a0 + st.removed - r0, st.added - a0, st.removed - r0, st.pixels - p0,
                            len(samples))

    @_locked
    def end_stroke(self, sid: int) -> StrokeResult:
        """Finish a stroke (one undo step); returns its totals."""
        st = self._get(sid)
        del self._open[sid]
        rec = self.surface.end_record()
        self.surface.begin_record()  # the tail: background work until the next stroke belongs to this one
        self._tail = True
        d = stroke_dict(st.brush, st.paint, st.samples)
        d["view"] = [self.view_axes[0].tolist(), self.view_axes[1].tolist()]
        self._strokes.append(d)
        self._undo.append(([rec], d))
        self._redo.clear()
        self._last_brush = None
        # grow the row capacity between strokes when it runs low (never in the middle of one)
        if self.surface.reserve_ahead() and self._view is not None:
            self._view._grow(self.surface.n)
        return StrokeResult(st.added + st.removed, st.added, st.removed, st.pixels, len(st.samples))

    @_locked
    def stroke(self, samples: Any, brush: Brush | None = None, paint: Paint | None = None) -> StrokeResult:
        """Paint a whole stroke (validated completely before anything is painted)."""
        samples = check_samples(samples)
        if not samples:
            raise InputError("samples: expected at least one sample, got none")
        sid = self.begin_stroke(brush if brush is not None else Brush(), paint if paint is not None else Paint())
        try:
            self.add_samples(sid, samples)
        except Exception:
            del self._open[sid]
            rec = self.surface.end_record()
            self.surface.revert(rec)
            raise
        return self.end_stroke(sid)

    # -- undo / redo ------------------------------------------------------------------------------
    @_locked
    def undo(self) -> bool:
        """Undo the last stroke (and the background work after it); False when there is none."""
        if self._open or not self._undo:
            return False
        self._close_tail()
        recs, d = self._undo.pop()
        red = [self.surface.revert(r) for r in reversed(recs)]
        self._strokes.pop()
        self._redo.append((red, d))
        return True

    @_locked
    def redo(self) -> bool:
        """Redo the last undone stroke; False when there is none."""
        if self._open or not self._redo:
            return False
        self._close_tail()
        reds, d = self._redo.pop()
        recs = [self.surface.reapply(r) for r in reversed(reds)]
        self._strokes.append(d)
        self._undo.append((recs, d))
        return True

    # -- background work ----------------------------------------------------------------------------
    @_locked
    def advance(self, dt: float, budget: int | None = None, downsample: bool = True) -> None:
        """Drying (5.12/5.13), diffusion (5.15) and downsampling (5.5.2) over ``dt`` seconds.

        ``budget`` limits downsampling to that many fathers per call (round robin), so an
        interactive caller never waits long; ``None`` checks all; ``downsample=False`` skips it.
        Deterministic; recorded in the stroke file (``"advance"``: seconds, or
        ``{"dt", "budget", "downsample"}`` for a limited step) so that a replay repeats it.
        """
        try:
            dt = float(dt)
        except (TypeError, ValueError):
            raise InputError(f"dt: expected a number of seconds, got {dt!r}") from None
        if not np.isfinite(dt) or dt < 0:
            raise InputError(f"dt: expected a finite number >= 0, got {dt!r}")
        if budget is not None and (int(budget) != budget or budget < 0):
            raise InputError(f"budget: expected a non-negative integer, got {budget!r}")
        km = self.options.mixing == "km"
        background.dry(self.surface, dt, km)
        background.diffuse(self.surface, dt, km)
        if downsample:
            self._cursor = background.downsample(self.surface, self.options.color_variance,
                                                 self.options.normal_variance, budget, self._cursor)
        self.time += dt
        step: Any = dt if downsample and budget is None else {"dt": dt, "budget": budget, "downsample": downsample}
        (self._strokes[-1].setdefault("advance", []) if self._strokes else self._pre_advance).append(step)

    # -- output ------------------------------------------------------------------------------------
    def _view_for(self, camera: Camera) -> PaintView:
        if self._view is None:
            self._view = PaintView(self.surface)
        return self._view

    @_locked
    def render(self, camera: Camera, shading: Any = "phong", background: Any = (1.0, 1.0, 1.0),
               brush: bool = True, full: bool = False, cull: bool = True, palette: Any = None) -> RenderResult:
        """Image of the painted model: differential update when only paint changed, full when the
        view changed (5.7); the brush of an open stroke is drawn with its shadow.

        ``cull`` culls back faces (surfels facing away from the camera are not drawn): right for
        closed models, where the far side's splats would otherwise poke out dark past thin
        features; pass False for open surfaces seen from both sides (a palette plane, scans).
        ``palette`` (a :class:`unmesh.paint.palette.Palette`) is drawn into the same image, in its
        inset's corner viewport over the object and the brush (5.7: "the final normalization
        pass ... additionally draws palette and brush handle")."""
        if not isinstance(camera, Camera):
            raise InputError(f"camera: expected a Camera, got {type(camera).__name__}")
        view = self._view_for(camera)
        view.set_style(shading, background)
        view.update(camera, force_full=full, cull_backfaces=bool(cull))
        self.view_axes = (np.asarray(camera.right, float), np.asarray(camera.true_up, float))
        b = self._last_brush if brush else None
        extra = None
        if b is not None:
            pos, nrm = b.surfels()
            col = np.where(b.vw[:, None] > 0, b.wet, _BRISTLE)
            extra = (pos, nrm, col)
        overlay = palette.overlay(camera.width, camera.height) if palette is not None else None
        return view.result(extra, overlay=overlay)

    @_locked
    def preview(self, camera: Camera, stride: int = 1, shading: Any = "phong", background: Any = (1.0, 1.0, 1.0),
                cull: bool = True) -> RenderResult:
        """A quick image of the painted model from every ``stride``-th surfel with enlarged splats
        (a level of detail while the view is dragged); the next :meth:`render` is not affected."""
        if not isinstance(camera, Camera):
            raise InputError(f"camera: expected a Camera, got {type(camera).__name__}")
        view = PaintView(self.surface, self._view_for(camera).options)
        view.shading, view.background, view.cull_backfaces = shading, background, bool(cull)
        return view.preview(camera, stride)

    @property
    def last_windows(self) -> list[tuple[int, int, int, int]] | None:
        """Pixel windows ``(r0, r1, c0, c1)`` where the last render's colour may differ from the
        render before it (through the same camera); None: anywhere (a full update, a new view)."""
        return self._view.last_windows if self._view is not None else None

    @property
    def render_serial(self) -> int:
        """Renders so far: :attr:`last_windows` is relative to render ``render_serial - 1``."""
        return self._view.results if self._view is not None else 0

    @property
    def last_update(self) -> str:
        """``"full"`` or ``"differential"``: the kind of the last render's update."""
        return self._view.last_update if self._view is not None else "none"

    @_locked
    def pick(self, camera: Camera, x_px: float, y_px: float) -> np.ndarray | None:
        """The surface point seen at pixel column ``x_px``, row ``y_px`` (None: background)."""
        view = self._view_for(camera)
        r = view.update(camera)
        col, row = int(np.floor(x_px)), int(np.floor(y_px))
        h, w = camera.shape
        if not (0 <= row < h and 0 <= col < w):
            return None
        if r.count[row, col] == 0:
            return None
        z = r.sum_depth[row, col] / r.sum_weight[row, col]
        return unproject(camera, np.array([row]), np.array([col]), np.array([z]))[0]

    def force(self) -> np.ndarray:
        """Latest low-passed haptic force (5.4.2), (3,)."""
        if self._haptic.running:
            return np.array(self._haptic.force)
        b = self._last_brush
        if b is None:
            return np.zeros(3)
        return haptic_force(b.handle_depth, b.handle_normal, b.handle_velocity, K_PENALTY, b.brush.friction,
                            b.spring_reaction)

    def haptic_stats(self) -> dict[str, float]:
        """Rate (Hz) and jitter (s) measured by the haptic loop."""
        return self._haptic.stats()

    def close(self) -> None:
        """Stop the haptic thread."""
        self._haptic.stop()

    @_locked
    def cloud(self) -> SurfelCloud:
        """Current visible surfels with their visible colours."""
        return self.surface.cloud()

    @_locked
    def strokes_json(self) -> dict[str, Any]:
        """The stroke-file dict of everything painted so far (see ``docs/paint.md``)."""
        out: dict[str, Any] = {"version": 1, "strokes": json.loads(json.dumps(self._strokes))}
        if self._pre_advance:
            out["advance"] = list(self._pre_advance)
        return out

    # -- files ------------------------------------------------------------------------------------
    def _record_with_open(self) -> dict[str, Any]:
        """The stroke record, with an open stroke's samples so far as a finished stroke (a save in
        the middle of a stroke reloads to the state at that moment)."""
        rec = self.strokes_json()
        for st in self._open.values():
            if st.samples:
                d = stroke_dict(st.brush, st.paint, st.samples)
                d["view"] = [self.view_axes[0].tolist(), self.view_axes[1].tolist()]
                rec["strokes"].append(d)
        return rec

    @_locked
    def save(self, path: str | os.PathLike[str]) -> None:
        """Write every row with every paint attribute (PLY, atomic); :meth:`load` continues exactly.

        May be called in the middle of a stroke: the samples painted so far are recorded as a
        stroke of their own."""
        self.write_snapshot(path, self._state(copy=False))

    @_locked
    def snapshot(self) -> tuple[dict[str, np.ndarray], bytes]:
        """What :meth:`save` writes, copied now: every field's rows and the metadata line.
        :meth:`write_snapshot` makes the cloud of them (checks, visible colours), encodes and
        writes it later, on any thread, while painting goes on (the studio's autosave)."""
        return self._state(copy=True)

    @staticmethod
    def write_snapshot(path: str | os.PathLike[str], snapshot: tuple[dict[str, np.ndarray], bytes]) -> None:
        """Write a :meth:`snapshot` as :meth:`save` would have written it then (PLY, atomic)."""
        from unmesh.io.atomic import atomic_write_bytes
        from unmesh.io.ply import encode_surfels

        fields, line = snapshot
        data = encode_surfels(_cloud_of(fields))
        i = data.index(b"\n", data.index(b"format")) + 1
        atomic_write_bytes(path, data[:i] + b"comment " + line + b"\n" + data[i:])

    def _state(self, copy: bool) -> tuple[dict[str, np.ndarray], bytes]:
        """Every field's rows (views, or copies) and the metadata comment line."""
        s = self.surface
        return {name: np.array(getattr(s, name), copy=True) if copy else getattr(s, name) for name in FIELDS}, \
            self._meta_line()

    def _meta_line(self) -> bytes:
        meta = {"version": 1, "time": self.time, "cursor": self._cursor, "options": asdict(self.options),
                "strokes": self._record_with_open()}
        return (_META + json.dumps(meta, separators=(",", ":"))).encode("utf-8")

    @classmethod
    def load(cls, path: str | os.PathLike[str], options: PaintOptions | None = None) -> Session:
        """A session from a PLY written by :meth:`save` (continues exactly), or any surfel PLY."""
        from unmesh.io import load_surfels

        name = os.fspath(path)
        cloud = load_surfels(name)
        meta = _read_meta(name)
        if meta is None:
            return cls(cloud, options)
        state = {}
        for fname, (tail, dt) in FIELDS.items():
            if fname == "pos":
                state[fname] = cloud.positions
            elif fname == "rad":
                state[fname] = cloud.radii
            else:
                key = "p_" + fname
                if key not in cloud.attributes:
                    raise FormatError(f"{name}: painted PLY without attribute {key!r}")
                state[fname] = np.asarray(cloud.attributes[key]).astype(dt).reshape(len(cloud), *tail)
        opts = options if options is not None else PaintOptions(**meta.get("options", {}))
        surface = PaintSurface(cloud, _state=state)
        s = cls(cloud, opts, _surface=surface)
        s.time = float(meta.get("time", 0.0))
        s._cursor = int(meta.get("cursor", 0))
        strokes = meta.get("strokes", {"version": 1, "strokes": []})
        parse_strokes(strokes, name)
        s._strokes = strokes["strokes"]
        s._pre_advance = list(strokes.get("advance", []))
        return s

    # -- replay ----------------------------------------------------------------------------------
    @_locked
    def replay(self, data: dict[str, Any], source: str = "strokes") -> int:
        """Paint a stroke-file dict (with its recorded background steps); returns the strokes painted."""
        strokes = parse_strokes(data, source)
        for i, a in enumerate(data.get("advance", [])):
            self._step(a, f"{source}: advance[{i}]")
        for k, (brush, paint, samples, advance) in enumerate(strokes):
            view = data["strokes"][k].get("view")
            if view is not None:
                try:
                    self.view_axes = (np.array(view[0], float).reshape(3), np.array(view[1], float).reshape(3))
                except (TypeError, ValueError, IndexError):
                    raise InputError(f"{source}: strokes[{k}].view: expected two 3-vectors, got {view!r}") from None
            try:
                self.stroke(samples, brush=brush, paint=paint)
            except InputError as exc:
                raise InputError(f"{source}: strokes[{k}].{exc}") from None
            for i, a in enumerate(advance):
                self._step(a, f"{source}: strokes[{k}].advance[{i}]")
        return len(strokes)

    def _step(self, a: Any, key: str) -> None:
        if isinstance(a, dict):
            budget = a.get("budget")
            if budget is not None and (not isinstance(budget, int) or isinstance(budget, bool) or budget < 0):
                raise InputError(f"{key}.budget: expected a non-negative integer or null, got {budget!r}")
            self.advance(_num(a.get("dt"), f"{key}.dt"), budget, bool(a.get("downsample", True)))
        else:
            self.advance(_num(a, key))


def _subdivide(last: Sample | None, samples: list[Sample], step: float) -> list[Sample]:
    """The samples with intermediate paint events wherever the pen moved more than ``step``
    since the previous one (linear in point, time, pressure and tilt), so that a stroke stays
    continuous however sparsely it was sampled. Intermediate samples are marked ``_between``."""
    out: list[Sample] = []
    prev = last
    for smp in samples:
        if prev is not None:
            d = float(np.linalg.norm(np.subtract(smp.point, prev.point)))
            k = int(np.ceil(d / step)) if d > step else 1
            for j in range(1, k):
                a = j / k
                mid = Sample(prev.t + a * (smp.t - prev.t),
                             tuple(float(v) for v in (1 - a) * np.asarray(prev.point) + a * np.asarray(smp.point)),
                             prev.pressure + a * (smp.pressure - prev.pressure),
                             tuple(float(v) for v in (1 - a) * np.asarray(prev.tilt) + a * np.asarray(smp.tilt)))
                object.__setattr__(mid, "_between", True)
                out.append(mid)
        out.append(smp)
        prev = smp
    return out


def _cloud_of(fields: dict[str, np.ndarray]) -> SurfelCloud:
    """The rows of a surface's fields (:meth:`Session.snapshot`) as a cloud with every paint
    attribute (``p_<field>``; booleans as uint8) and the visible colours (5.8)."""
    attrs = {}
    for name in FIELDS:
        if name in ("pos", "rad"):
            continue
        a = fields[name]
        attrs["p_" + name] = a.astype(np.uint8) if a.dtype == np.bool_ else a
    return SurfelCloud(fields["pos"], fields["nrm"], radii=fields["rad"], colors=state_colors(fields),
                       attributes=attrs)


def _num(v: Any, key: str) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{key}: expected seconds, got {v!r}") from None
    if not np.isfinite(f) or f < 0:
        raise InputError(f"{key}: expected seconds >= 0, got {v!r}")
    return f


def _read_meta(path: str) -> dict[str, Any] | None:
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
        while b"end_header" not in head:
            more = fh.read(1 << 20)
            if not more:
                break
            head += more
    text = head.split(b"end_header", 1)[0].decode("utf-8", errors="replace")
    for line in text.splitlines():
        if line.startswith("comment " + _META):
            try:
                return json.loads(line[len("comment " + _META):])
            except json.JSONDecodeError as exc:
                raise FormatError(f"{path}: damaged paint-session comment ({exc.msg})") from None
    return None


def _rotate(v: np.ndarray, axis: np.ndarray, deg: float) -> np.ndarray:
    """Rotate ``v`` about unit ``axis`` by ``deg`` degrees (Rodrigues)."""
    if deg == 0:
        return v
    a = axis / np.linalg.norm(axis)
    t = np.radians(deg)
    return v * np.cos(t) + cross3(a, v) * np.sin(t) + a * np.dot(a, v) * (1 - np.cos(t))


def _across(axis: np.ndarray, move: np.ndarray, prev: np.ndarray | None, fallback: np.ndarray) -> np.ndarray:
    """Unit vector perpendicular to the handle axis and to the motion (a flat brush's width)."""
    m = move - np.dot(move, axis) * axis
    if np.linalg.norm(m) > 1e-12:
        c = cross3(axis, m / np.linalg.norm(m))
    elif prev is not None:
        c = prev - np.dot(prev, axis) * axis
    else:
        c = fallback - np.dot(fallback, axis) * axis
    if np.linalg.norm(c) < 1e-9:
        h = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
        c = h - np.dot(h, axis) * axis
    c = c / np.linalg.norm(c)
    if prev is not None and np.dot(c, prev) < 0:
        c = -c
    return c
