"""Running gallery examples and writing ``index.html``."""

from __future__ import annotations

import html
import time
from pathlib import Path

from unmesh.gallery.pool import run_in_workers
from unmesh.gallery.registry import Example
from unmesh.gallery.run import ExampleResult, run_one
from unmesh.gallery.timing import expected_seconds, record
from unmesh.io.atomic import atomic_write_text

__all__ = ["ExampleResult", "run_examples", "write_index"]


def run_examples(examples: list[Example], outdir: Path, quick: bool = False, progress: bool = True,
                 jobs: int = 1) -> list[ExampleResult]:
    """Run ``examples`` into ``outdir/<name>/`` and write ``outdir/index.html``.

    A failing example is recorded (with its traceback) and the others still run. The progress
    bar counts the examples' expected seconds (:func:`unmesh.gallery.timing.expected_seconds`);
    each successful example's time is recorded in ``outdir/timings.json`` for the next run.
    ``jobs`` > 1 runs them in that many worker processes (:mod:`unmesh.gallery.pool`); the page
    lists them in the order given either way and is rewritten as each one ends.

    Returns
    -------
    list of ExampleResult, in the order of ``examples``.
    """
    from tqdm import tqdm

    outdir.mkdir(parents=True, exist_ok=True)
    weights = [round(w, 1) for w in expected_seconds(examples, outdir, quick)]
    done: dict[int, ExampleResult] = {}
    # the bar counts expected seconds, so its estimate of the time left weighs each example by its cost
    bar = tqdm(total=sum(weights), disable=not progress, leave=True,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]")

    def finish(k: int, result: ExampleResult) -> None:
        done[k] = result
        write_index([done[i] for i in sorted(done)], outdir, quick)
        if result.error is None:
            record(outdir, quick, {result.example.name: result.seconds})
        bar.update(weights[k])

    def running(names: list[str]) -> None:
        bar.set_description_str(f"gallery {len(done)}/{len(examples)} running {', '.join(names[:jobs])}")
        bar.refresh()

    if jobs > 1 and len(examples) > 1:
        bar.set_description_str(f"gallery 0/{len(examples)} ({jobs} processes)")
        run_in_workers(list(enumerate(examples)), weights, outdir, quick, jobs, finish, running)
    else:
        for k, ex in enumerate(examples):
            bar.set_description_str(f"gallery {k}/{len(examples)} {ex.name}")
            finish(k, run_one(ex, outdir, quick, progress))
    bar.set_description_str(f"gallery {len(examples)}/{len(examples)}")
    bar.close()
    return [done[k] for k in range(len(examples))]


_CSS = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1200px;color:#222;background:#fafafa}
h1{margin-bottom:0}h2{border-bottom:2px solid #ccc;margin-top:2em}
.ex{background:#fff;border:1px solid #ddd;border-radius:6px;padding:1em;margin:1em 0}
.ex.failed{border-color:#c33}.figs{display:flex;flex-wrap:wrap;gap:12px}
figure{margin:0;max-width:560px}figure img,figure video{max-width:100%;border:1px solid #eee}
figcaption{font-size:.9em;color:#555}table{border-collapse:collapse;margin:.5em 0}
td,th{border:1px solid #ddd;padding:2px 8px;text-align:left;font-size:.9em}
pre{background:#fee;padding:.5em;overflow:auto;font-size:.8em}.meta{color:#777;font-size:.85em}
"""


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def write_index(results: list[ExampleResult], outdir: Path, quick: bool = False) -> Path:
    """Write ``index.html`` for ``results`` (atomically) and return its path."""
    from unmesh._version import __version__

    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>unmesh gallery</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>unmesh gallery</h1>",
        f"<p class='meta'>unmesh {html.escape(__version__)} &middot; {len(results)} examples"
        f"{' (quick mode)' if quick else ''} &middot; generated {time.strftime('%Y-%m-%d %H:%M')}</p>",
    ]
    section = None
    for r in results:
        if r.example.section != section:
            section = r.example.section
            parts.append(f"<h2>{html.escape(section)}</h2>")
        cls = "ex failed" if r.error else "ex"
        parts.append(f"<div class='{cls}' id='{html.escape(r.example.name)}'>")
        parts.append(f"<h3>{html.escape(r.example.title)} <span class='meta'>({html.escape(r.example.name)}, {r.seconds:.1f} s)</span></h3>")
        if r.example.description:
            parts.append(f"<p>{html.escape(r.example.description)}</p>")
        figs = []
        for a in r.context.artifacts:
            src = html.escape(a.path)
            cap = f"<figcaption>{html.escape(a.caption)}</figcaption>" if a.caption else ""
            if a.kind == "image":
                figs.append(f"<figure><img src='{src}' alt='{html.escape(a.caption)}'>{cap}</figure>")
            elif a.kind == "video":
                figs.append(f"<figure><video src='{src}' controls loop muted autoplay></video>{cap}</figure>")
            elif a.kind == "file":
                parts.append(f"<p><a href='{src}'>{html.escape(Path(a.path).name)}</a> {html.escape(a.caption)}</p>")
            elif a.kind == "text":
                parts.append(f"<p>{html.escape(a.caption)}</p>")
        if figs:
            parts.append("<div class='figs'>" + "".join(figs) + "</div>")
        if r.context.metrics:
            rows = "".join(f"<tr><td>{html.escape(n)}</td><td>{html.escape(_fmt(v))}</td><td>{html.escape(u)}</td></tr>" for n, v, u in r.context.metrics)
            parts.append(f"<table><tr><th>measure</th><th>value</th><th>unit</th></tr>{rows}</table>")
        if r.error:
            parts.append(f"<p><b>This example failed.</b></p><pre>{html.escape(r.error)}</pre>")
        parts.append("</div>")
    parts.append("</body></html>")
    path = outdir / "index.html"
    atomic_write_text(path, "\n".join(parts))
    return path
