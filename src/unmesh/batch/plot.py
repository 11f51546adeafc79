"""``unmesh batch --plot METRIC --against KEY OUTDIR -o plot.png``: a result against a swept parameter.

One line per combination of the other swept parameters (and input), points sorted by the
parameter, drawn with matplotlib (part of the ``unmesh[batch]`` extra). ``METRIC`` is a
column of ``batch.csv`` (a figure of the tasks' ``summary.json`` such as
``final.kinetic_energy``, or ``wall_seconds``) and ``KEY`` a swept parameter; either may be
shortened to a unique suffix (``viscosity`` for ``materials.water.viscosity``).

Example
-------
>>> plot_metric("out", "final.kinetic_energy", "viscosity", "plot.png")   # doctest: +SKIP
PosixPath('plot.png')
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from unmesh.batch.manifest import load_manifest, task_figures
from unmesh.errors import InputError, MissingDependencyError

__all__ = ["metric_table", "plot_metric"]


def _pick(name: str, options: Iterable[str], what: str) -> str:
    opts = list(dict.fromkeys(options))
    if name in opts:
        return name
    hits = [o for o in opts if o.endswith("." + name) or o.split(".")[-1] == name]
    if len(hits) == 1:
        return hits[0]
    if hits:
        raise InputError(f"{what}: {name!r} is ambiguous; expected one of {', '.join(hits)}")
    shown = ", ".join(opts[:30]) + (" ..." if len(opts) > 30 else "")
    raise InputError(f"{what}: no {name!r} in this batch; expected one of {shown or '(none)'}")


def metric_table(outdir: str | os.PathLike[str], metric: str, against: str) -> tuple[str, str, dict[str, list[tuple[Any, float]]]]:
    """The points to plot: ``(metric key, parameter key, {line label: [(x, y), ...]})`` of the done tasks.

    Raises
    ------
    unmesh.errors.InputError
        No batch in ``outdir``, or unknown / ambiguous ``metric`` or ``against``.
    """
    manifest = load_manifest(outdir)
    if manifest is None:
        raise InputError(f"OUTDIR: no batch.json in {outdir}")
    done = [rec for rec in manifest["tasks"] if rec.get("status") == "done"]
    if not done:
        raise InputError(f"OUTDIR: no task of {outdir} is done yet")
    params = [k for rec in manifest["tasks"] for k in rec.get("parameters", {})]
    key = _pick(against, params, "--against")
    figs = {rec["id"]: {**task_figures(rec, outdir), "wall_seconds": rec.get("wall_seconds")} for rec in done}
    mkey = _pick(metric, [f for fs in figs.values() for f in fs], "--plot")
    lines: dict[str, list[tuple[Any, float]]] = {}
    for rec in done:
        p = rec.get("parameters", {})
        if key not in p:
            continue
        y = figs[rec["id"]].get(mkey)
        if isinstance(y, bool) or not isinstance(y, int | float) or not math.isfinite(y):
            continue
        others = [f"{k.split('.')[-1]}={v}" for k, v in p.items() if k != key]
        if rec.get("input") is not None:
            others.insert(0, Path(str(rec["input"])).stem)
        lines.setdefault(", ".join(others), []).append((p[key], float(y)))
    if not lines:
        raise InputError(f"--plot: no done task has a number {mkey!r} and a value of {key!r}")
    return mkey, key, lines


def plot_metric(outdir: str | os.PathLike[str], metric: str, against: str, path: str | os.PathLike[str], *,
                title: str | None = None) -> Path:
    """Plot ``metric`` of the done tasks of a batch against the swept parameter ``against`` (PNG, atomic).

    Parameters
    ----------
    outdir : path-like
        A batch output directory (with ``batch.json``).
    metric : str
        A figure (column of ``batch.csv``) or a unique suffix of one.
    against : str
        A swept parameter or a unique suffix of one.
    path : path-like
        Output image (``.png``, ``.svg`` or ``.pdf``).
    title : str, optional

    Raises
    ------
    unmesh.errors.MissingDependencyError
        matplotlib is missing (``pip install 'unmesh[batch]'``).
    """
    out = Path(path)
    if out.suffix.lower() not in (".png", ".svg", ".pdf"):
        raise InputError(f"-o: expected a .png, .svg or .pdf file, got {out.name!r}")
    mkey, key, lines = metric_table(outdir, metric, against)
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        from matplotlib.figure import Figure
    except ImportError:
        raise MissingDependencyError("--plot needs matplotlib; install it with: pip install 'unmesh[batch]'") from None
    from unmesh.io.atomic import atomic_path

    fig = Figure(figsize=(6.4, 4.4), dpi=120)
    ax = fig.add_subplot()
    numeric = all(isinstance(x, int | float) and not isinstance(x, bool) for pts in lines.values() for x, _ in pts)
    cats = sorted({str(x) for pts in lines.values() for x, _ in pts})
    for label, pts in lines.items():
        pts = sorted(pts, key=lambda t: t[0]) if numeric else sorted(pts, key=lambda t: str(t[0]))
        xs = [x for x, _ in pts] if numeric else [cats.index(str(x)) for x, _ in pts]
        ax.plot(xs, [y for _, y in pts], marker="o", label=label or None)
    if not numeric:
        ax.set_xticks(range(len(cats)), cats)
    ax.set_xlabel(key)
    ax.set_ylabel(mkey)
    ax.set_title(title or f"{mkey} against {key.split('.')[-1]}")
    ax.grid(True, alpha=0.3)
    if any(lines):
        ax.legend(fontsize="small")
    fig.tight_layout()
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format=out.suffix.lower().lstrip("."))
    return out
