"""Frame sequences and turntables: simulation output directories to MP4/GIF.

Simulation output (``unmesh.sim``): ``OUTDIR/frames.json`` lists every file the run wrote,
frame by frame (``{"frames": [{"frame", "time", "files"}], "static": [...], "fps"}``, paths
relative to OUTDIR). For such a folder the frames are exactly the manifest's: each frame draws
its renderable files under ``OUTDIR/frames/`` (``unmesh render OUTDIR``) or under another
listed folder given instead (``unmesh render OUTDIR/surfaces`` for SPH fluid surfaces), plus
the manifest's renderable static files (``boundary.ply``) in every frame; other files in the
folder are ignored and nothing is guessed from names. The manifest's ``fps`` is the default
frame rate of the video.

A directory without ``frames.json`` (frame files written by other tools) is read by name:
its ``frames/`` sub-folder if there is one, else its own files, grouped by their trailing
frame number, so several series written for the same frame (e.g. ``fluid_00012.ply`` and
``solid_00012.ply``) are drawn together; unnumbered files are static and drawn in every
frame, as are ``boundary.{ply,obj,off}`` next to ``frames/``. Each file is loaded with
:func:`unmesh.io.load` (surfel clouds, particles or triangle meshes by content).

One fixed camera frames the union of the bounds of a sample of frames (first, last and up to
:data:`BOUNDS_SAMPLES` in between, so a splash mid-run stays in view) and of the static
geometry; ``color_by`` ranges are fixed over the run the same way, and particle radii are
estimated once from the first frame, so nothing flickers. Static particle geometry (boundary
particles) is drawn in grey and cut away where it lies in front of the moving content.

Example
-------
>>> import tempfile, pathlib
>>> from unmesh import Particles, io
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> for k in range(3):
...     io.save(d / "frames" / f"frame_{k:05d}.ply", Particles([[0.1 * k, 0, 0], [0, 0.2, 0]]))
>>> frames, static = find_frames(d)
>>> [p.name for group in frames for p in group], static
(['frame_00000.ply', 'frame_00001.ply', 'frame_00002.ply'], [])
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from unmesh.errors import InputError
from unmesh.particles import Particles
from unmesh.render.camera import Camera
from unmesh.render.pipeline import collect, render, scene_bounds, scene_points

__all__ = [
    "BOUNDS_SAMPLES",
    "FRAME_EXTENSIONS",
    "MANIFEST",
    "SequencePlan",
    "find_frames",
    "render_frame",
    "render_sequence",
    "sequence_fps",
    "sequence_plan",
    "turntable",
    "turntable_camera",
    "write_frames",
]

#: Renderable frame file extensions.
FRAME_EXTENSIONS = (".ply", ".obj", ".off")
#: Frames sampled (besides first and last) to fix the camera and colour range of a sequence.
BOUNDS_SAMPLES = 16
_NUMBERED = re.compile(r"^(?P<series>.*?)(?P<num>\d+)$")
STATIC_COLOR = (0.72, 0.72, 0.72)
#: The manifest a simulation run writes into its output folder (see :mod:`unmesh.sim.runner`).
MANIFEST = "frames.json"


def _renderable(p: Path) -> bool:
    return p.is_file() and p.suffix.lower() in FRAME_EXTENSIONS and not p.name.startswith(".")


def _manifest_of(root: Path) -> tuple[Path, str, dict[str, Any]] | None:
    """(run folder, series folder, manifest) when ``root`` is a run folder or a folder listed in one."""
    for home, series in ((root, "frames"), (root.parent, root.name)):
        path = home / MANIFEST
        if not path.is_file():
            continue
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"frames: {path} is not readable JSON ({exc})") from None
        if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
            raise InputError(f"frames: {path}: expected an object with a \"frames\" list")
        if home == root.parent:
            listed = {str(f).split("/", 1)[0] for e in data["frames"] if isinstance(e, dict)
                      for f in e.get("files", []) if "/" in str(f)}
            if series not in listed:
                continue
        return home, series, data
    return None


def _member(home: Path, rel: Any, path: Path) -> Path:
    if not isinstance(rel, str) or not rel or rel.startswith("/") or ".." in rel.split("/"):
        raise InputError(f"frames: {path}: expected file paths relative to {home}, got {rel!r}")
    return home / rel


def _from_manifest(home: Path, series: str, data: dict[str, Any]) -> tuple[list[list[Path]], list[Path]]:
    path = home / MANIFEST
    entries = [e for e in data["frames"] if isinstance(e, dict)]
    entries.sort(key=lambda e: e.get("frame", 0))
    groups: list[list[Path]] = []
    for e in entries:
        files = [_member(home, f, path) for f in e.get("files", [])]
        picked = [p for p in files if p.parent == home / series and p.suffix.lower() in FRAME_EXTENSIONS]
        missing = [p for p in picked if not p.is_file()]
        if missing:
            raise InputError(f"frames: {path} lists {missing[0].relative_to(home).as_posix()} (frame "
                             f"{e.get('frame')}) but it does not exist")
        if picked:
            groups.append(sorted(picked))
    static = [p for p in (_member(home, f, path) for f in data.get("static", []))
              if p.suffix.lower() in FRAME_EXTENSIONS and p.is_file()]
    if not groups:
        raise InputError(f"frames: {path} lists no renderable frame files ({', '.join(FRAME_EXTENSIONS)}) "
                         f"under {series}/")
    return groups, sorted(static)


def sequence_fps(source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> float | None:
    """The frame rate recorded in the simulation manifest of ``source`` (a run folder), else None.

    Example
    -------
    >>> import tempfile
    >>> sequence_fps(tempfile.mkdtemp()) is None
    True
    """
    if not isinstance(source, str | os.PathLike):
        return None
    root = Path(source)
    if not root.is_dir():
        return None
    found = _manifest_of(root)
    if found is None:
        return None
    fps = found[2].get("fps")
    return float(fps) if isinstance(fps, int | float) and not isinstance(fps, bool) and fps > 0 else None


def find_frames(source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> tuple[list[list[Path]], list[Path]]:
    """Frame files grouped by frame number, and the static files.

    Parameters
    ----------
    source : path or sequence of paths
        A simulation output directory (read through its ``frames.json``; or one of its
        folders listed there, such as ``OUTDIR/surfaces``), a directory of frame files, or an
        explicit list of files (each file one frame, ordered by trailing number then name).

    Returns
    -------
    frames : list of list of Path
        Files of each frame, in frame order.
    static : list of Path
        Files drawn in every frame (``boundary.*`` next to ``frames/``, unnumbered files).

    Raises
    ------
    unmesh.errors.InputError
        When no frame files are found, or a manifest lists a missing file.
    """
    if isinstance(source, str | os.PathLike):
        root = Path(source)
        if not root.exists():
            raise InputError(f"frames: {root} does not exist")
        found = _manifest_of(root) if root.is_dir() else None
        if found is not None:
            return _from_manifest(*found)
        if root.is_file():
            files = [root]
            static: list[Path] = []
        else:
            sub = root / "frames"
            fdir = sub if sub.is_dir() else root
            files = sorted(p for p in fdir.iterdir() if _renderable(p))
            # static geometry next to frames/ (or next to the given frames/ or surfaces/ folder)
            home = root if fdir != root else (root.parent if root.name in ("frames", "surfaces") else None)
            static = sorted(p for p in home.iterdir() if _renderable(p) and p.stem.lower().startswith("boundary")) \
                if home is not None else []
    else:
        files = [Path(p) for p in source]
        static = []
        missing = [str(p) for p in files if not p.is_file()]
        if missing:
            raise InputError(f"frames: no such file: {missing[0]}")
        keyed = []
        for p in files:
            m = _NUMBERED.match(p.stem)
            keyed.append(((int(m.group("num")) if m else -1), p.name, p))
        return [[p] for _, _, p in sorted(keyed, key=lambda t: (t[0], t[1]))], []
    groups: dict[int, list[Path]] = {}
    for p in files:
        m = _NUMBERED.match(p.stem)
        if m is None:
            if p not in static:
                static.append(p)
            continue
        if p in static:
            continue
        groups.setdefault(int(m.group("num")), []).append(p)
    if not groups:
        raise InputError(f"frames: no numbered frame files ({', '.join(FRAME_EXTENSIONS)}) found in {source}")
    return [sorted(groups[k]) for k in sorted(groups)], static


def _load(path: Path) -> Any:
    from unmesh import io

    return io.load(path)


def _sample_indices(n: int, k: int = BOUNDS_SAMPLES) -> list[int]:
    if n <= k + 2:
        return list(range(n))
    return sorted(set(np.linspace(0, n - 1, k + 2).round().astype(int).tolist()))


def turntable_camera(objects: Any, width: int = 640, height: int = 480, fov: float = 40.0, elevation: float = 20.0,
                     up: Sequence[float] = (0.0, 1.0, 0.0)) -> Camera:
    """A camera at ``elevation`` degrees above the horizon that keeps the bounding sphere of
    ``objects`` in view from every azimuth (for :func:`turntable`).

    Example
    -------
    >>> cam = turntable_camera(Particles([[-1, -1, -1], [1, 1, 1]]), 64, 64)
    >>> bool(np.allclose(cam.target, 0))
    True
    """
    b = scene_bounds(objects)
    if not np.all(np.isfinite(b)):
        b = np.array([[-0.5] * 3, [0.5] * 3])
    center = 0.5 * (b[0] + b[1])
    radius = max(0.5 * float(np.linalg.norm(b[1] - b[0])), 1e-9)
    cube = np.stack([center - radius, center + radius])
    upv = np.asarray(up, dtype=np.float64)
    upv = upv / np.linalg.norm(upv)
    helper = np.array([0.0, 0.0, 1.0]) if abs(upv[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    horiz = helper - (helper @ upv) * upv
    horiz /= np.linalg.norm(horiz)
    e = np.radians(elevation)
    direction = np.cos(e) * horiz + np.sin(e) * upv
    return Camera.framing(cube, width, height, fov=fov, direction=direction, up=tuple(upv), margin=1.0)


def turntable(objects: Any, n: int, path: str | os.PathLike[str] | None = None, camera: Camera | None = None,
              width: int = 640, height: int = 480, fps: float = 30.0, progress: bool = False,
              **render_options: Any) -> list[np.ndarray] | Path:
    """Render ``n`` frames orbiting the camera once around its up axis through the target.

    Parameters
    ----------
    objects : renderable or list
    n : int
        Number of frames (>= 1); frame ``k`` is rotated by ``360 k / n`` degrees.
    path : path-like, optional
        ``.mp4`` or ``.gif`` to write (atomic); otherwise the frames are returned.
    camera : Camera, optional
        Start camera (default :func:`turntable_camera`).
    width, height : int
        Image size when no camera is given.
    fps : float
    progress : bool
        tqdm progress bar.
    **render_options
        Passed to :func:`unmesh.render.render` (``method``, ``shading``, ``color_by``...).

    Returns
    -------
    list of (H, W, 3) float arrays, or the written Path.

    Example
    -------
    >>> frames = turntable(Particles([[0, 0, 0], [0.5, 0, 0]], radii=[0.2, 0.2]), 4, width=16, height=16)
    >>> len(frames), frames[0].shape
    (4, (16, 16, 3))
    """
    from tqdm.auto import tqdm

    count = int(n)
    if count != n or count < 1:
        raise InputError(f"turntable: expected a positive number of frames, got {n!r}")
    scene = collect(objects)
    cam = camera if camera is not None else turntable_camera(scene, width, height)
    opts = dict(render_options)
    if opts.get("color_by") is not None and opts.get("color_range") is None:
        first = render(scene, cam.resized(8, 8), **{**opts, "legend": False})
        opts["color_range"] = first.color_range

    def frames() -> Iterator[np.ndarray]:
        for k in tqdm(range(count), desc="turntable", unit="frame", disable=not progress):
            yield render(scene, cam.orbit(360.0 * k / count), **opts).color

    if path is None:
        return list(frames())
    from unmesh.render.image import write_video

    return write_video(frames(), path, fps=fps)


def _frame_objects(paths: Iterable[Path]) -> list[Any]:
    return [_load(p) for p in paths]


def render_sequence(
    frames: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    out_path: str | os.PathLike[str],
    camera: Camera | None = None,
    fps: float | None = None,
    progress: bool = True,
    width: int = 640,
    height: int = 480,
    color_by: str | None = None,
    color_range: Sequence[float] | None = None,
    particle_radius: float | None = None,
    cutaway: bool = True,
    context: Sequence[Any] = (),
    **render_options: Any,
) -> Path:
    """Render a simulation's frames into a video (MP4 or GIF) or a directory of PNGs.

    Parameters
    ----------
    frames : path or sequence of paths
        Simulation output directory, frame directory, or list of frame files (see
        :func:`find_frames`).
    out_path : path-like
        ``.mp4``/``.gif`` (atomic), or a directory (``frame_NNNNN.png`` files).
    camera : Camera, optional
        Default: :meth:`Camera.framing` of the union of the bounds of sampled frames.
    fps : float, optional
        Video frame rate; default the simulation's (``fps`` in ``frames.json``), else 30.
    progress : bool
        tqdm progress bar over frames.
    width, height : int
        Image size of the default camera.
    color_by, color_range
        As for :func:`unmesh.render.render`; the range defaults to the values of the sampled frames.
    particle_radius : float, optional
        Drawing radius of particles without stored radii (default: estimated on the first frame).
    cutaway : bool
        Drop static particles (boundaries) that lie in front of the moving content.
    context : sequence
        Objects drawn in every frame and not framed by the default camera, e.g. the floor and
        walls of :mod:`unmesh.render.context`.
    **render_options
        Passed to :func:`unmesh.render.render` (``method``, ``shading``, ``background``, ``legend``...).

    Returns
    -------
    pathlib.Path

    Example
    -------
    >>> import tempfile, pathlib
    >>> from unmesh import io
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> for k in range(2):
    ...     io.save(d / "frames" / f"frame_{k:05d}.ply", Particles([[0.1 * k, 0, 0], [0, 0.2, 0]]))
    >>> render_sequence(d, d / "movie.gif", width=32, height=24, progress=False).name
    'movie.gif'
    """
    from tqdm.auto import tqdm

    if fps is None:
        fps = sequence_fps(frames) or 30.0
    plan = sequence_plan(frames, camera, width, height, color_by, color_range, particle_radius, cutaway,
                         context=context, **render_options)
    images = (render_frame(plan, i) for i in tqdm(range(len(plan.groups)), desc="render", unit="frame",
                                                  disable=not progress))
    return write_frames(images, out_path, fps)


def write_frames(images: Iterable[np.ndarray], out_path: str | os.PathLike[str], fps: float) -> Path:
    """Write rendered frames, in order, as a video (``.mp4``/``.gif``, atomic) or a directory of PNGs."""
    from unmesh.render.image import save_image, write_video

    out = check_output(out_path)
    if out.suffix:
        return write_video(images, out, fps=fps)
    out.mkdir(parents=True, exist_ok=True)
    for k, img in enumerate(images):
        save_image(out / f"frame_{k:05d}.png", img)
    return out


def check_output(out_path: str | os.PathLike[str]) -> Path:
    """The output path of a frame sequence: a video file or a directory (no other suffix)."""
    from unmesh.render.image import VIDEO_EXTENSIONS

    out = Path(out_path)
    if out.suffix and out.suffix.lower() not in VIDEO_EXTENSIONS:
        raise InputError(f"output: expected .mp4, .gif or a directory for a frame sequence, got {out.name!r}")
    return out


@dataclass(frozen=True)
class SequencePlan:
    """What every frame of a sequence shares (see :func:`sequence_plan`)."""

    groups: tuple[tuple[Path, ...], ...]
    static_objects: tuple[Any, ...]
    camera: Camera
    color_by: str | None
    color_range: tuple[float, float] | None
    particle_radius: float | None
    render_options: dict[str, Any] = field(default_factory=dict)


def sequence_plan(frames: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], camera: Camera | None = None,
                  width: int = 640, height: int = 480, color_by: str | None = None,
                  color_range: Sequence[float] | None = None, particle_radius: float | None = None,
                  cutaway: bool = True, context: Sequence[Any] = (), **render_options: Any) -> SequencePlan:
    """The camera, colour range, particle radius and static geometry of a frame sequence.

    Parameters are those of :func:`render_sequence` (the same defaults
    and the same choices, so a frame of the plan is the frame ``render_sequence`` draws).
    """
    from unmesh.render.colormap import attribute_values, value_range
    from unmesh.render.particles import estimate_radius

    groups, static_paths = find_frames(frames)
    static = collect(_frame_objects(static_paths))
    sampled = {i: collect(_frame_objects(groups[i])) for i in _sample_indices(len(groups))}
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for sc in sampled.values():
        b = scene_bounds(sc)
        lo = np.minimum(lo, b[0])
        hi = np.maximum(hi, b[1])
    dyn_bounds = np.stack([lo, hi])
    if camera is None:
        pts = np.concatenate([scene_points(sc, 4000) for sc in [*sampled.values(), static]])
        margin = 1.35 if color_by is not None and render_options.get("legend", True) else 1.08
        cam = Camera.fit(pts, width, height, margin=margin) if len(pts) else \
            Camera.framing(np.stack([lo, hi]), width, height, margin=margin)
    else:
        cam = camera
    if color_by is not None and color_range is None:
        vals = []
        for sc in sampled.values():
            for obj in sc.all():
                try:
                    vals.append(attribute_values(obj, color_by))
                except InputError:
                    pass
        if not vals:
            raise InputError(f"color_by: no frame object has attribute {color_by!r}")
        color_range = value_range(vals)
    first = sampled[0]
    if particle_radius is None and first.particles:
        missing = [p for p in first.particles if p.radii is None]
        if missing:
            particle_radius = estimate_radius(np.concatenate([p.positions for p in missing]))
    static_particles: list[Particles] = []
    for p in static.particles:
        keep = np.ones(len(p), dtype=bool)
        if cutaway and np.all(np.isfinite(dyn_bounds)) and len(p):
            corners = np.array([[dyn_bounds[i, 0], dyn_bounds[j, 1], dyn_bounds[k, 2]]
                                for i in (0, 1) for j in (0, 1) for k in (0, 1)])
            zmin = float(cam.to_camera(corners)[:, 2].min())
            keep = cam.to_camera(p.positions)[:, 2] >= zmin - 1e-9 * max(1.0, abs(zmin))
        sub = p.subset(keep)
        col = np.tile(STATIC_COLOR, (len(sub), 1))
        static_particles.append(sub.replace(attributes={**sub.attributes, "colors": col}))
    static_objects = (*static.clouds, *static.meshes, *static_particles, *context)
    crange = None if color_range is None else (float(color_range[0]), float(color_range[1]))
    return SequencePlan(tuple(tuple(g) for g in groups), static_objects, cam, color_by, crange,
                        particle_radius, dict(render_options))


def render_frame(plan: SequencePlan, i: int) -> np.ndarray:
    """Frame ``i`` of a plan: (H, W, 3) float colours, as :func:`render_sequence` draws it."""
    if not 0 <= int(i) < len(plan.groups):
        raise InputError(f"i: expected a frame index in [0, {len(plan.groups)}), got {i}")
    # the frame's own objects go to render() as loaded, so its discontinuity surfels reach the
    # splatter as clip information
    return render([*plan.static_objects, *_frame_objects(plan.groups[int(i)])], plan.camera, color_by=plan.color_by,
                  color_range=plan.color_range, particle_radius=plan.particle_radius, **plan.render_options).color
