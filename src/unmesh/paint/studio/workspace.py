"""The studio's state: the painting session, its palette, the view, files and autosave.

A :class:`Workspace` turns the page's messages (:mod:`unmesh.paint.studio.protocol`) into calls
on the engine (:class:`unmesh.paint.Session`) and renders what they changed. It is used from one
thread at a time (the server's worker thread); nothing here knows about HTTP.

* The model and the **palette** are two sessions: the palette is the engine's
  :class:`unmesh.paint.palette.Palette`, a paintable surfel plane on which paint is mixed with
  the brush like on the object (chapter 5's palette), and ``pick_color`` loads the brush with the
  paint under the pen. The page shows it in its own canvas beside the model.
* Pen positions arrive in image pixels and are ray-cast onto the surface with
  ``Session.pick``; samples that miss the surface are dropped; the rest are resampled along
  the surface at the engine's dab step (:class:`unmesh.paint.studio.resample.DabResampler`), so
  each costs one paint event however the surface slants. Sample times are the page's
  clock mapped to seconds since the studio started, so drying follows real time and a
  recorded session replays exactly.
* Pen samples are checked when their message arrives but painted in one engine call per frame
  (:meth:`Workspace.flush`, run before any other message and before rendering): the samples of
  every ``samples`` message queued while the engine was busy cost one ``add_samples`` and one
  render, so the server catches up with a fast pen instead of falling further behind. A frame
  paints only what fits in :data:`PAINT_BUDGET` (less the last render's time: a frame every
  :data:`FRAME_PERIOD`) at the measured cost per sample (at least one
  sample); the rest wait for the next frame, so a slow engine (a large model) shows the stroke
  growing at a steady frame rate instead of in one late frame per burst.
* While painting, a frame converts and compares only the windows where the engine's image
  changed (``Session.last_windows``), never the whole image.
* Every frame's header carries the server's timings in milliseconds (``srv``: ``queue`` wait of
  the newest pen message, ``paint`` = ray casts + ``add_samples``, ``render``; wall-clock
  ``received`` and ``done``) and the encoder's ``enc``, next to the time stamp ``ts`` of the
  newest pen event it shows, for the page's latency split.
* Files are plain names inside the output file's folder (:func:`security.output_path`); all
  writes are atomic; the model is autosaved every ``autosave_every`` strokes (to
  ``STEM.autosave.ply``) and by :meth:`Workspace.shutdown` (to the output file). An autosave
  copies the model's fields (``Session.snapshot``) and builds, encodes and writes the cloud on a thread of its own, so
  painting goes on meanwhile; its ``autosaved`` reply comes from :meth:`Workspace.notices` when
  the file is written (a ``sync`` waits for it).

Example
-------
>>> # ws = Workspace(Session(cloud), "out/blob_painted.ply"); ws.handle({"type": "undo"})
"""

from __future__ import annotations

import concurrent.futures
import copy
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.io.atomic import atomic_write_json
from unmesh.paint.palette import PALETTE_EXTENT, PALETTE_SIZE, Palette
from unmesh.paint.studio.frames import FrameEncoder, to_uint8
from unmesh.paint.studio.protocol import brush_spec, paint_spec, samples_spec
from unmesh.paint.studio.resample import DabResampler
from unmesh.paint.studio.security import output_path
from unmesh.paint.studio.view import PRESETS, Framing, View, view_from_message
from unmesh.render.camera import Camera

__all__ = ["PALETTE_SIZE", "Workspace"]

#: Seconds of painting per frame while pen samples queue up (:meth:`Workspace.flush`).
PAINT_BUDGET = 0.05
#: Seconds from frame to frame while pen samples queue: a frame paints for this long less the
#: last differential render's time (at most :data:`PAINT_BUDGET`, at least a fifth of this), so
#: that paint + render of a frame take about this long (20 frames per second).
FRAME_PERIOD = 0.05
#: Largest model image (pixels per side).
MAX_SIDE = 2048
#: Preview (view drag) resolution divisors: the studio picks one from the last preview's render time.
PREVIEW_SCALES = (2, 3, 4)
#: Surfels drawn in a preview (view drag): a larger model is drawn from every k-th surfel
#: with larger splats (``Session.preview``).
PREVIEW_SURFELS = 60_000
#: Render time (s) of a preview above which the next preview uses a coarser image, and below which a finer one.
PREVIEW_SLOW, PREVIEW_FAST = 0.05, 0.015


#: The studio's resampling distance in units of the engine's dab step (``DAB_STEP`` brush sizes):
#: just below it, so that rounding never makes the engine add an event between two samples.
DAB_SPACING = 1.0 - 1e-6


def _engine():
    # the engine's defining modules (unmesh.paint's __init__ never imports the studio)
    from unmesh.paint.session import Session
    from unmesh.paint.strokes import Brush, Paint, Sample

    return Brush, Paint, Sample, Session


class Workspace:
    """Session, palette, view and files of one studio (see the module notes)."""

    def __init__(self, session: Any, out_path: str | Path, *, palette: Any = None, autosave_every: int = 5,
                 advance_every: float | None = 1.0) -> None:
        self.session = session
        self.out_path = Path(out_path).resolve()
        self.folder = self.out_path.parent
        self.folder.mkdir(parents=True, exist_ok=True)
        self.palette = palette if palette is not None else Palette()
        self.framing = Framing.of_points(session.cloud().positions)
        self.view = View()
        self.width, self.height = 800, 600
        self.palette_camera = Palette.camera(*PALETTE_SIZE)
        self.autosave_every = int(autosave_every)
        self.advance_every = advance_every
        self._last_advance = time.monotonic()
        self._force_session = self.session
        self.encoder = FrameEncoder(tiles="rgba")  # painting frames: raw tiles, drawn at once by the page
        self._t0 = time.monotonic()
        self._stroke: dict[str, Any] | None = None
        self._since_autosave = 0
        self._saver: concurrent.futures.ThreadPoolExecutor | None = None
        self._saves: list[concurrent.futures.Future[dict[str, Any]]] = []
        self.changed_since_save = False
        self.strokes = 0
        self._pending: dict[str, str] = {"model": "full", "palette": "full"}
        self._last_ts: float | None = None
        self._model_u8: np.ndarray | None = None
        self._model_serial: tuple[int, int] | None = None
        self._rows: list[tuple[float, float, float, float, float, float]] = []
        self._row_ts: list[tuple[float, Any] | None] = []
        #: (perf counter s, wall clock ms) at which the server received the message being handled
        self.arrival: tuple[float, float] | None = None
        self._last_arrival: tuple[float, float] | None = None
        # ray-cast samples waiting to be painted: (sample or None for a miss, row time (None: the
        # stroke's last point), message ts)
        self._ready: list[tuple[Any, float | None, tuple[float, Any] | None]] = []
        #: Seconds of engine work (ray casts + ``add_samples``) a frame may spend on pen samples.
        self.paint_budget = PAINT_BUDGET
        self._sample_cost: float | None = None
        self._paint_time = 0.0
        self._render_cost: float | None = None
        self.preview_scale = PREVIEW_SCALES[0]

    # -- cameras ------------------------------------------------------------------------
    def camera(self) -> Camera:
        """The model camera of the current view at the current image size."""
        return self.framing.camera(self.view, self.width, self.height)

    def px_per_unit(self) -> float:
        """Pixels per world unit at the view's target (the brush cursor's scale)."""
        cam = self.camera()
        return cam.pixels_per_unit / float(np.linalg.norm(cam.target - cam.eye))

    def state(self) -> dict[str, Any]:
        """The ``state`` reply: image sizes, view, brush scale, counts."""
        v = self.view
        return {"type": "state", "width": self.width, "height": self.height, "palette": list(PALETTE_SIZE),
                "view": {"yaw": v.yaw, "pitch": v.pitch, "zoom": v.zoom, "pan": list(v.pan)},
                "px_per_unit": self.px_per_unit(), "palette_px_per_unit": PALETTE_SIZE[1] / PALETTE_EXTENT,
                "radius": self.framing.radius, "strokes": self.strokes, "out": self.out_path.name,
                "presets": {k: list(p) for k, p in PRESETS.items()}}

    # -- messages -----------------------------------------------------------------------
    def handle(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        """Apply one parsed message; returns the JSON replies (frames come from :meth:`frames`)."""
        kind = msg["type"]
        method = getattr(self, "_on_" + kind)
        if kind != "samples":
            self.flush()
        return method(msg) or []

    def _on_hello(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        self._resize(msg)
        if "view" in msg:
            self.view = view_from_message(msg["view"])
        self._pending = {"model": "full", "palette": "full"}
        self.encoder.reset()
        return [self.state()]

    def _resize(self, msg: dict[str, Any]) -> None:
        w, h = msg.get("width", self.width), msg.get("height", self.height)
        for key, v in (("width", w), ("height", h)):
            if isinstance(v, bool) or not isinstance(v, int) or not 16 <= v <= MAX_SIDE:
                raise InputError(f"{key}: expected an integer in [16, {MAX_SIDE}], got {v!r}")
        self.width, self.height = w, h

    def _on_resize(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        self._resize(msg)
        self._pending["model"] = "full"
        return [self.state()]

    def _on_view(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        self.view = view_from_message(msg.get("view"))
        self._pending["model"] = "preview" if msg.get("preview") is True else "full"
        return [self.state()]

    def _target(self, name: Any) -> tuple[Any, Camera]:
        if name == "model":
            return self.session, self.camera()
        if name == "palette":
            return self.palette.session, self.palette_camera
        raise InputError(f"target: expected 'model' or 'palette', got {name!r}")

    def _on_begin(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        from unmesh.paint.session import DAB_STEP

        Brush, Paint, _, _ = _engine()
        if self._stroke is not None:
            self._on_end({})
        target = msg.get("target", "model")
        session, camera = self._target(target)
        brush = Brush(**brush_spec(msg.get("brush")))
        paint = Paint(**paint_spec(msg.get("paint")))
        self._force_session = session
        self._stroke = {"target": target, "session": session, "camera": camera, "brush": brush, "paint": paint,
                        "sid": None, "t_server": time.monotonic() - self._t0, "t_client": None, "n": 0,
                        "resampler": DabResampler(DAB_SPACING * DAB_STEP * brush.size)}
        return [{"type": "begun", "target": target}]

    def _on_samples(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        st = self._stroke
        if st is None:
            raise InputError("samples: no stroke begun (send 'begin' first)")
        cam = st["camera"]
        rows = samples_spec(msg.get("samples"), cam.width, cam.height)
        ts = msg.get("ts")
        if not (isinstance(ts, int | float) and not isinstance(ts, bool) and math.isfinite(ts)):
            ts = None
        self._rows.extend(rows)
        # the message's time stamp (and arrival) goes with its last row: a frame that painted it shows the message
        mark = None if ts is None else (float(ts), self.arrival)
        self._row_ts.extend([None] * (len(rows) - 1) + [mark] if rows else [])
        self.arrival = None
        return []

    @property
    def backlog(self) -> int:
        """Pen samples received but not painted yet (a frame paints at most :attr:`paint_budget`)."""
        return len(self._rows) + len(self._ready) if self._stroke is not None else 0

    def flush(self, budget: float | None = None) -> None:
        """Paint the pen samples received since the last flush: ray-cast each onto the surface
        and give them to the engine in one ``add_samples`` call.

        ``budget`` (seconds) paints only as many of the oldest samples as the measured cost per
        sample allows (at least one); the rest stay queued for the next frame (:attr:`backlog`),
        so a slow engine still sends frames at a steady rate instead of one late frame per burst.
        The next frame's time stamp is that of the newest message whose samples are all painted
        (or of the newest painted sample)."""
        _, _, Sample, _ = _engine()
        st = self._stroke
        if st is None:
            self._rows, self._row_ts, self._ready = [], [], []
            return
        t0 = time.perf_counter()
        cam = st["camera"]
        # every received row is ray-cast now, before any of them is painted (as when all are
        # painted at once), so the points do not depend on how the samples are split into frames
        # and resampled at the engine's dab spacing (:class:`DabResampler`: one paint event each)
        for (t_ms, x, y, pressure, tilt_x, tilt_y), mark in zip(self._rows, self._row_ts, strict=True):
            if st["t_client"] is None:
                st["t_client"] = t_ms
            point = st["session"].pick(cam, x, y)
            if point is not None:
                t = st["t_server"] + max(0.0, (t_ms - st["t_client"]) / 1000.0)
                out = st["resampler"].push((t, tuple(float(c) for c in point), pressure, (tilt_x, tilt_y)))
            else:  # a miss ends the polyline (never resampled across the gap)
                out = st["resampler"].finish()
            self._ready.extend((Sample(*p), float(t_ms), None) for p in out)
            if mark is not None:  # the message is shown once the samples it completed are painted
                if out:
                    self._ready[-1] = (self._ready[-1][0], float(t_ms), mark)
                else:
                    self._ready.append((None, float(t_ms), mark))
        self._rows, self._row_ts = [], []
        if not self._ready:
            return
        n = len(self._ready)
        if budget is not None and self._sample_cost is not None:
            n = max(1, min(n, int(budget / max(self._sample_cost, 1e-6))))
        ready, self._ready = self._ready[:n], self._ready[n:]
        done = [m for _, _, m in ready if m is not None]
        if done or ready[-1][1] is not None:  # (the stroke's last point keeps the frame's time stamp)
            self._last_ts, arrival = done[-1] if done else (ready[-1][1], None)
            # the newest painted message's wait for the engine (perf counter) and arrival (wall clock, ms)
            self._last_arrival = None if arrival is None else (1000 * (t0 - arrival[0]), arrival[1])
        samples = [smp for smp, _, _ in ready if smp is not None]
        t1 = time.perf_counter()
        if samples:
            if st["sid"] is None:
                st["sid"] = st["session"].begin_stroke(st["brush"], st["paint"])
            st["session"].add_samples(st["sid"], samples)
            st["n"] += len(samples)
            self._pending.setdefault(st["target"], "diff")
        t2 = time.perf_counter()
        self._paint_time += t2 - t0
        cost = (t2 - t1) / len(ready)
        self._sample_cost = cost if self._sample_cost is None else 0.5 * (self._sample_cost + cost)

    def _on_end(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        st = self._stroke
        if st is not None:  # the pen's last point, beyond the last resampled one
            self.flush()
            _, _, Sample, _ = _engine()
            # no time stamp: the pen events were shown (their point lies within a dab step of the
            # last painted sample, inside its footprint) and their latency counted
            self._ready.extend((Sample(*p), None, None) for p in st["resampler"].finish())
            self.flush()
        st, self._stroke = self._stroke, None
        if st is None or st["sid"] is None:
            return [{"type": "ended", "painted": False}]
        st["session"].end_stroke(st["sid"])
        self._pending.setdefault(st["target"], "diff")
        replies: list[dict[str, Any]] = [{"type": "ended", "painted": True, "samples": st["n"]}]
        if st["target"] == "model":
            self.strokes += 1
            self.changed_since_save = True
            self._since_autosave += 1
            if self._since_autosave >= self.autosave_every:
                self.autosave()
        return replies

    def _on_undo(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        if self._stroke is not None:
            self._on_end({})
        done = bool(self.session.undo())
        if done:
            self.strokes = max(0, self.strokes - 1)  # strokes in the model (what the page shows)
            self.changed_since_save = True
            self._pending.setdefault("model", "diff")
        return [{"type": "undone", "ok": done}]

    def _on_redo(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        done = bool(self.session.redo())
        if done:
            self.strokes += 1
            self.changed_since_save = True
            self._pending.setdefault("model", "diff")
        return [{"type": "redone", "ok": done}]

    def _name(self, msg: dict[str, Any], default: str, suffixes: tuple[str, ...]) -> Path:
        return output_path(self.folder, msg.get("name") or default, suffixes)

    def _on_save(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        path = self._name(msg, self.out_path.name, (".ply",))
        self._save_model(path)
        if path == self.out_path:
            self.changed_since_save = False
        return [{"type": "saved", "name": path.name}]

    def _on_load(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        _, _, _, Session = _engine()
        path = self._name(msg, self.out_path.name, (".ply",))
        if not path.is_file():
            raise InputError(f"name: no file {path.name!r} in the output folder")
        self._stroke = None
        old, self.session = self.session, Session.load(path)
        old.close()
        self._force_session = self.session
        self.framing = Framing.of_points(self.session.cloud().positions)
        self._pending["model"] = "full"
        return [{"type": "loaded", "name": path.name}, self.state()]

    def _on_export(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        path = self._name(msg, self.out_path.stem + ".png", (".png",))
        self.session.render(self.camera()).save(path)
        return [{"type": "exported", "name": path.name}]

    def _on_record(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        path = self._name(msg, self.out_path.stem + "_strokes.json", (".json",))
        atomic_write_json(path, self.session.strokes_json())
        return [{"type": "recorded", "name": path.name}]

    def _on_replay(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        import json

        path = self._name(msg, self.out_path.stem + "_strokes.json", (".json",))
        if not path.is_file():
            raise InputError(f"name: no file {path.name!r} in the output folder")
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            raise InputError(f"{path.name}: expected a stroke JSON file, got a parse error ({exc})") from None
        if self._stroke is not None:
            self._on_end({})
        n = self.session.replay(data, path.name)
        self.strokes += n
        self.changed_since_save = True
        self._pending["model"] = "full"
        return [{"type": "replayed", "name": path.name, "strokes": n}]

    def _on_sync(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        return [*self.notices(wait=True), {"type": "synced", "id": msg.get("id") if isinstance(msg.get("id"), int) else None}]

    def _on_pick_color(self, msg: dict[str, Any]) -> list[dict[str, Any]]:
        x, y = msg.get("x"), msg.get("y")
        if isinstance(x, bool) or isinstance(y, bool):
            x = y = None  # refused by color_at
        rgb = self.palette.color_at(x, y, *PALETTE_SIZE)
        return [{"type": "color", "color": [round(float(c), 4) for c in rgb]}]

    # -- output -------------------------------------------------------------------------
    def frames(self, queue_ms: float | None = None, received_at: float | None = None) -> list[bytes]:
        """Paint pending samples (:meth:`flush`, within :attr:`paint_budget`: the rest are the
        :attr:`backlog` for the next frame), then render and encode every target that changed
        since the last call.

        ``queue_ms`` (the server's queue wait of the newest pen message) and ``received_at`` (the
        wall-clock time in ms at which the server received it) go into the headers' ``srv``, with
        ``done``, the wall-clock time at which the image was rendered (the page, on the same
        machine, splits its latency with them)."""
        budget = self.paint_budget
        if budget is not None and self._render_cost is not None:
            budget = min(budget, max(0.2 * FRAME_PERIOD, FRAME_PERIOD - self._render_cost))
        self.flush(budget)
        out = []
        pending, self._pending = self._pending, {}
        for target, mode in pending.items():
            t0 = time.perf_counter()
            windows = None
            if target == "model":
                cam = self.camera()
                scale = 1
                if mode == "preview":
                    scale = self.preview_scale
                    cam = cam.resized(max(8, self.width // scale), max(8, self.height // scale))
                if mode == "preview":  # a level of detail: at most about PREVIEW_SURFELS surfels
                    stride = max(1, round(len(self.session.surface.visible_rows()) / PREVIEW_SURFELS))
                    img = to_uint8(self.session.preview(cam, stride).color)
                    self._adapt_preview(time.perf_counter() - t0)
                else:
                    res = self.session.render(cam)
                    # the engine's changed windows, if this render follows the previous frame's
                    serial, self._model_serial = self._model_serial, (id(self.session), self.session.render_serial)
                    consecutive = serial == (id(self.session), self.session.render_serial - 1)
                    windows = self.session.last_windows if mode != "full" and consecutive else None
                    img = self._model_image(res.color, windows)
                    if windows is not None:  # a painting frame's render time, for the next paint budget
                        cost = time.perf_counter() - t0
                        self._render_cost = cost if self._render_cost is None else 0.5 * (self._render_cost + cost)
            else:
                res = self.palette.render(*PALETTE_SIZE)
                img, scale = to_uint8(res.color), 1
            srv = {"paint": round(1000 * self._paint_time, 2), "render": round(1000 * (time.perf_counter() - t0), 2)}
            if self._last_arrival is not None:  # the newest pen message this frame shows
                queue_ms, received_at = self._last_arrival
            if queue_ms is not None:
                srv["queue"] = round(queue_ms, 2)
            if received_at is not None:
                srv["received"] = round(received_at, 2)
            srv["done"] = round(1000 * time.time(), 2)
            extra: dict[str, Any] = {"srv": srv}
            if self._last_ts is not None:
                extra["ts"] = self._last_ts
            size = (self.width, self.height) if target == "model" else None
            msg = self.encoder.encode(target, img, full=mode in ("full", "preview"), scale=scale, size=size,
                                      extra=extra, windows=windows)
            if msg is not None:
                out.append(msg)
        self._last_ts = self._last_arrival = None
        self._paint_time = 0.0
        return out

    def _model_image(self, color: np.ndarray, windows: list[tuple[int, int, int, int]] | None) -> np.ndarray:
        """The model image as uint8, kept between frames: only ``windows`` (where the engine's
        image changed, ``Session.last_windows``) are converted again; None converts all of it."""
        img = self._model_u8
        if windows is None or img is None or img.shape != color.shape:
            self._model_u8 = to_uint8(color)
            return self._model_u8
        for r0, r1, c0, c1 in windows:
            img[r0:r1, c0:c1] = to_uint8(color[r0:r1, c0:c1])
        return img

    def _adapt_preview(self, seconds: float) -> None:
        """Coarser previews when the last one rendered slowly, finer ones when fast."""
        i = PREVIEW_SCALES.index(self.preview_scale)
        if seconds > PREVIEW_SLOW and i + 1 < len(PREVIEW_SCALES):
            self.preview_scale = PREVIEW_SCALES[i + 1]
        elif seconds < PREVIEW_FAST and i > 0:
            self.preview_scale = PREVIEW_SCALES[i - 1]

    def force(self) -> list[float]:
        """The brush's current penalty force (3,) from the engine's haptic signal."""
        f = np.asarray(self._force_session.force(), dtype=np.float64).reshape(3)
        return [float(c) for c in f]

    @property
    def painting(self) -> bool:
        """True while a stroke is open."""
        return self._stroke is not None

    def _save_model(self, path: Path) -> None:
        self.session.save(path)  # atomic

    def tick(self) -> bool:
        """Background work between strokes: ``Session.advance`` over the time since the last tick
        (drying, diffusion, downsampling; recorded in the stroke file, so a replay matches).
        True when it ran."""
        now = time.monotonic()
        if self.advance_every is None or self._stroke is not None or now - self._last_advance < self.advance_every:
            return False
        dt, self._last_advance = now - self._last_advance, now
        if self.strokes == 0:
            return False
        self.session.advance(round(dt, 3), budget=256)
        self._pending.setdefault("model", "diff")
        return True

    def autosave(self) -> None:
        """Save the model to ``STEM.autosave.ply`` and the strokes to ``STEM.autosave.json``: copied
        now, written on the autosave thread (the ``autosaved`` reply comes from :meth:`notices`)."""
        _, _, _, Session = _engine()
        self._since_autosave = 0
        ply = self.folder / (self.out_path.stem + ".autosave.ply")
        snap = self.session.snapshot()
        strokes = copy.deepcopy(self.session.strokes_json())

        def write() -> dict[str, Any]:
            Session.write_snapshot(ply, snap)
            atomic_write_json(self.folder / (self.out_path.stem + ".autosave.json"), strokes)
            return {"type": "autosaved", "name": ply.name}

        if self._saver is None:
            self._saver = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="unmesh-autosave")
        self._saves.append(self._saver.submit(write))

    def notices(self, wait: bool = False) -> list[dict[str, Any]]:
        """Replies of the autosaves written since the last call (``wait``: of all started ones,
        waiting for them); a failed write gives an ``error`` reply."""
        out, pending = [], []
        for f in self._saves:
            if not (wait or f.done()):
                pending.append(f)
                continue
            try:
                out.append(f.result())
            except Exception as exc:  # the session goes on; the page shows it
                out.append({"type": "error", "message": f"autosave failed: {type(exc).__name__}: {exc}"})
        self._saves = pending
        return out

    def shutdown(self) -> Path | None:
        """Close an open stroke (painting its queued samples) and save the model to the output file
        if it changed."""
        if self._stroke is not None:
            self.flush()
            self._on_end({})
        self.notices(wait=True)
        if self._saver is not None:
            self._saver.shutdown(wait=True)
            self._saver = None
        self.session.close()
        self.palette.session.close()
        if not self.changed_since_save:
            return None
        self._save_model(self.out_path)
        atomic_write_json(self.folder / (self.out_path.stem + "_strokes.json"), self.session.strokes_json())
        self.changed_since_save = False
        return self.out_path
