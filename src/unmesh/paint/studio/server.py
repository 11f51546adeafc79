"""The studio's web server (aiohttp): static page, WebSocket session, uploads and downloads.

Routes (all on ``127.0.0.1`` only; every response checks the ``Host`` header):

``GET /``, ``GET /static/<file>``
    The package's own page, scripts and styles (:func:`security.static_file`).
``GET /ws?token=T``
    The WebSocket session: JSON messages from the page (:mod:`unmesh.paint.studio.protocol`),
    JSON replies and binary frames (:mod:`unmesh.paint.studio.frames`) back. Needs the token and
    a same-origin ``Origin``.
``POST /api/upload?token=T&name=N``
    Puts a ``.ply`` or ``.json`` file into the output folder (token, same origin, size cap).
``GET /api/file?token=T&name=N``
    Downloads a ``.ply``, ``.json`` or ``.png`` of the output folder (token).

Messages are handled one batch at a time on a single worker thread (the engine is never called
from two threads; the event loop only moves bytes, so it keeps receiving pen messages while the
engine paints), and a batch paints its pen samples in one engine call and renders once, so a
burst of pen samples costs one frame; samples beyond the frame's paint budget
(:attr:`Workspace.backlog`) get the next frame at once. A malformed message gets an ``{"type": "error"}`` reply;
the session goes on.

Example
-------
>>> # run_studio(session, "blob_painted.ply", port=0, open_browser=False)  # blocks until Ctrl-C
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import signal
import socket
import sys
import threading
import time
import traceback
import webbrowser
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from unmesh.errors import InputError, UnmeshError
from unmesh.io.atomic import atomic_write_bytes
from unmesh.paint.studio import security
from unmesh.paint.studio.protocol import MAX_MESSAGE, parse_message
from unmesh.paint.studio.workspace import Workspace

__all__ = ["MAX_UPLOAD", "STATIC", "BackgroundStudio", "Studio", "run_studio"]

#: The package's static folder.
STATIC = Path(__file__).resolve().parent / "static"
#: Largest upload (bytes).
MAX_UPLOAD = 256 << 20
_RAW_REFUSED = ("..", "%2e", "%2f", "%5c", "%25", "%00", "\\", "//")
_FORCE_PERIOD = 0.05
#: Seconds of message handling after which the worker renders a frame before going on.
FRAME_BUDGET = 0.04
#: WebSocket per-message compression (RFC 7692 permessage-deflate, negotiated with the page):
#: painting frames carry raw RGBA tiles, which deflate several-fold; the browser inflates them
#: in its network stack, before the page's handler runs.
COMPRESS = True


class Studio:
    """One studio: a :class:`Workspace` served on a bound local socket.

    Parameters
    ----------
    workspace : Workspace
    sock : socket.socket
        Bound listening socket on 127.0.0.1.
    static_root : path, optional
        Folder of the page's files (the package's by default).
    max_upload : int
        Upload size cap in bytes.
    """

    def __init__(self, workspace: Workspace, sock: socket.socket, *, static_root: str | Path = STATIC,
                 max_upload: int = MAX_UPLOAD) -> None:
        self.workspace = workspace
        self.sock = sock
        self.port = int(sock.getsockname()[1])
        self.token = security.new_token()
        self.static_root = Path(static_root)
        self.max_upload = int(max_upload)
        self.pool = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="unmesh-studio")
        self.clients: set[web.WebSocketResponse] = set()
        self._queue: list[tuple[web.WebSocketResponse, str, float, float]] = []
        self._wake: asyncio.Event | None = None
        self._tasks: list[asyncio.Task[Any]] = []
        self.errors = 0

    @property
    def url(self) -> str:
        """The page's address with the session token."""
        return f"http://127.0.0.1:{self.port}/?token={self.token}"

    # -- app ------------------------------------------------------------------------------
    def app(self) -> web.Application:
        app = web.Application(middlewares=[self._guard])
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{path:.*}", self._static)
        app.router.add_get("/ws", self._ws)
        app.router.add_post("/api/upload", self._upload)
        app.router.add_get("/api/file", self._file)
        return app

    @web.middleware
    async def _guard(self, request: web.Request, handler: Callable[..., Any]) -> web.StreamResponse:
        if not security.host_ok(request.headers.get("Host"), self.port):
            raise web.HTTPForbidden(text="unmesh studio: wrong Host\n")
        raw = request.raw_path.split("?", 1)[0].lower()
        if any(bad in raw for bad in _RAW_REFUSED):
            raise web.HTTPForbidden(text="unmesh studio: path refused\n")
        response = await handler(request)
        if not isinstance(response, web.WebSocketResponse):
            response.headers["Cache-Control"] = "no-store"
            response.headers["X-Content-Type-Options"] = "nosniff"
            response.headers["Referrer-Policy"] = "no-referrer"
            response.headers["Content-Security-Policy"] = (
                "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; "
                f"connect-src 'self' ws://127.0.0.1:{self.port} ws://localhost:{self.port}; frame-ancestors 'none'")
        return response

    def _check(self, request: web.Request, *, state_changing: bool) -> None:
        if not security.token_ok(request.query.get("token"), self.token):
            raise web.HTTPForbidden(text="unmesh studio: missing or wrong token\n")
        if state_changing and not security.origin_ok(request.headers.get("Origin"), self.port):
            raise web.HTTPForbidden(text="unmesh studio: cross-origin request refused\n")

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return await self._serve(self.static_root, "index.html")

    async def _static(self, request: web.Request) -> web.StreamResponse:
        return await self._serve(self.static_root, request.match_info["path"])

    async def _serve(self, root: Path, rel: str) -> web.StreamResponse:
        try:
            path = security.static_file(root, rel)
        except security.PathRefused:
            raise web.HTTPForbidden(text="unmesh studio: path refused\n") from None
        except FileNotFoundError:
            raise web.HTTPNotFound(text="unmesh studio: no such file\n") from None
        kind = security.STATIC_TYPES[path.suffix.lower()]
        return web.Response(body=path.read_bytes(), headers={"Content-Type": kind})

    async def _upload(self, request: web.Request) -> web.StreamResponse:
        self._check(request, state_changing=True)
        try:
            path = security.output_path(self.workspace.folder, request.query.get("name", ""), (".ply", ".json"))
        except security.PathRefused as exc:
            raise web.HTTPForbidden(text=f"unmesh studio: {exc}\n") from None
        if request.content_length is not None and request.content_length > self.max_upload:
            raise web.HTTPRequestEntityTooLarge(max_size=self.max_upload, actual_size=request.content_length)
        chunks, size = [], 0
        async for chunk in request.content.iter_chunked(1 << 16):
            size += len(chunk)
            if size > self.max_upload:  # chunked bodies have no Content-Length to check first
                raise web.HTTPRequestEntityTooLarge(max_size=self.max_upload, actual_size=size)
            chunks.append(chunk)
        body = b"".join(chunks)
        await asyncio.get_running_loop().run_in_executor(self.pool, atomic_write_bytes, path, body)
        return web.json_response({"name": path.name, "bytes": len(body)})

    async def _file(self, request: web.Request) -> web.StreamResponse:
        self._check(request, state_changing=False)
        try:
            path = security.output_path(self.workspace.folder, request.query.get("name", ""), (".ply", ".json", ".png"))
        except security.PathRefused as exc:
            raise web.HTTPForbidden(text=f"unmesh studio: {exc}\n") from None
        if not path.is_file():
            raise web.HTTPNotFound(text="unmesh studio: no such file\n")
        return web.Response(body=path.read_bytes(), content_type="application/octet-stream",
                            headers={"Content-Disposition": f'attachment; filename="{path.name}"'})

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        self._check(request, state_changing=True)
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE, compress=COMPRESS)
        await ws.prepare(request)
        self.clients.add(ws)
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    self._queue.append((ws, msg.data, time.perf_counter(), time.time()))
                    assert self._wake is not None
                    self._wake.set()
                elif msg.type == WSMsgType.BINARY:
                    await ws.send_json({"type": "error", "message": "message: expected JSON text, got binary"})
                elif msg.type == WSMsgType.ERROR:
                    break
        finally:
            self.clients.discard(ws)
        return ws

    # -- work -----------------------------------------------------------------------------
    def _process(self, batch: list[tuple[Any, str, float, float]]) -> tuple[list[tuple[Any, dict[str, Any]]], list[bytes], int]:
        """Handle messages of ``batch`` for at most :data:`FRAME_BUDGET` seconds, then render once.

        Returns the replies, the frames and how many messages were handled (the rest wait for
        the next round, so the page sees frames while a long stroke is still being painted)."""
        replies: list[tuple[Any, dict[str, Any]]] = []
        start = time.perf_counter()
        done = 0
        queue_ms = received_at = None
        for ws, text, received, wall in batch:
            if done and time.perf_counter() - start > FRAME_BUDGET:
                break
            done += 1
            if queue_ms is None or '"samples"' in text:  # the wait of the newest pen message
                queue_ms, received_at = 1000 * (time.perf_counter() - received), 1000 * wall
            self.workspace.arrival = (received, 1000 * wall)
            try:
                msg = parse_message(text)
                replies.extend((ws, r) for r in self.workspace.handle(msg))
            except (UnmeshError, InputError) as exc:
                self.errors += 1
                replies.append((ws, {"type": "error", "message": str(exc)}))
            except Exception as exc:  # the session must survive any message
                self.errors += 1
                traceback.print_exc(file=sys.stderr)
                replies.append((ws, {"type": "error", "message": f"internal error: {type(exc).__name__}: {exc}"}))
        try:
            frames = self.workspace.frames(queue_ms, received_at)
        except Exception as exc:
            traceback.print_exc(file=sys.stderr)
            frames = []
            replies.append((None, {"type": "error", "message": f"render failed: {type(exc).__name__}: {exc}"}))
        replies.extend((None, r) for r in self.workspace.notices())  # autosaves written meanwhile
        return replies, frames, done

    async def _worker(self) -> None:
        loop = asyncio.get_running_loop()
        assert self._wake is not None
        while True:
            await self._wake.wait()
            self._wake.clear()
            batch, self._queue = self._queue, []
            if not batch and not self.workspace.backlog:
                continue
            replies, frames, done = await loop.run_in_executor(self.pool, self._process, batch)
            if done < len(batch):  # the rest first, before anything that arrived meanwhile
                self._queue = batch[done:] + self._queue
                self._wake.set()
            if self.workspace.backlog:  # pen samples the last frame had no time for: another frame
                self._wake.set()
            # frames first: a reply (e.g. "synced") tells the page that the frames before it arrived
            for frame in frames:
                for client in list(self.clients):
                    with contextlib.suppress(ConnectionError, RuntimeError):
                        await client.send_bytes(frame)
            for ws, reply in replies:
                targets = list(self.clients) if ws is None else [ws]
                for client in targets:
                    with contextlib.suppress(ConnectionError, RuntimeError):
                        await client.send_json(reply)

    async def _ticks(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(0.25)
            if not self.clients or self._queue:
                continue

            def tick() -> tuple[list[bytes], list[dict[str, Any]]]:
                try:
                    return (self.workspace.frames() if self.workspace.tick() else []), self.workspace.notices()
                except Exception:
                    traceback.print_exc(file=sys.stderr)
                    return [], []

            frames, notices = await loop.run_in_executor(self.pool, tick)
            for frame in frames:
                for client in list(self.clients):
                    with contextlib.suppress(ConnectionError, RuntimeError):
                        await client.send_bytes(frame)
            for notice in notices:
                for client in list(self.clients):
                    with contextlib.suppress(ConnectionError, RuntimeError):
                        await client.send_json(notice)

    async def _forces(self) -> None:
        last_active = -1e9
        while True:
            await asyncio.sleep(_FORCE_PERIOD)
            if not self.clients:
                continue
            now = time.monotonic()
            if self.workspace.painting:
                last_active = now
            if now - last_active > 0.5:
                continue
            try:
                f = self.workspace.force()
            except Exception:
                continue
            for client in list(self.clients):
                with contextlib.suppress(ConnectionError, RuntimeError):
                    await client.send_json({"type": "force", "force": f})

    async def serve(self, stop: asyncio.Event, ready: Callable[[Studio], None] | None = None) -> None:
        """Serve until ``stop`` is set, then close clients and save (``Workspace.shutdown``)."""
        self._wake = asyncio.Event()
        runner = web.AppRunner(self.app(), handle_signals=False, access_log=None)
        await runner.setup()
        site = web.SockSite(runner, self.sock)
        await site.start()
        self._tasks = [asyncio.create_task(t()) for t in (self._worker, self._forces, self._ticks)]
        if ready is not None:
            ready(self)
        try:
            await stop.wait()
        finally:
            for task in self._tasks:
                task.cancel()
            for ws in list(self.clients):
                with contextlib.suppress(Exception):
                    await ws.close()
            await runner.cleanup()
            saved = await asyncio.get_running_loop().run_in_executor(self.pool, self.workspace.shutdown)
            self.pool.shutdown(wait=True)
            if saved is not None:
                print(f"unmesh paint: saved {saved}", flush=True)

    def run_in_worker(self, fn: Callable[[Workspace], Any]) -> Any:
        """Run ``fn(workspace)`` on the worker thread (serialised with the messages); its result."""
        return self.pool.submit(fn, self.workspace).result()


def bind_local(port: int = 0) -> socket.socket:
    """A listening TCP socket on 127.0.0.1 (``port`` 0: a free port)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(("127.0.0.1", int(port)))
    except OSError as exc:
        sock.close()
        raise InputError(f"--port: cannot listen on 127.0.0.1:{port} ({exc.strerror})") from None
    sock.listen(64)
    sock.setblocking(False)
    return sock


def run_studio(session: Any, out_path: str | Path, port: int = 0, open_browser: bool = True) -> None:
    """Serve the painting studio for ``session`` until Ctrl-C or SIGTERM.

    Prints the page's URL (with the session token), opens it in the default browser unless
    ``open_browser`` is false, autosaves every few strokes and saves ``out_path`` on shutdown
    when the model changed.

    Parameters
    ----------
    session : unmesh.paint.Session
    out_path : path
        The painted model's file; autosaves, exports and recordings go to its folder.
    port : int
        TCP port on 127.0.0.1; 0 picks a free one.
    open_browser : bool
    """
    studio = Studio(Workspace(session, out_path), bind_local(port))

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, stop.set)

        def ready(s: Studio) -> None:
            print(f"unmesh paint: studio at {s.url}", flush=True)
            print("unmesh paint: press Ctrl-C to save and quit", flush=True)
            if open_browser:
                threading.Thread(target=webbrowser.open, args=(s.url,), daemon=True).start()

        await studio.serve(stop, ready)

    asyncio.run(main())


class BackgroundStudio:
    """A studio served from a background thread (tests, benchmarks): ``with BackgroundStudio(ws) as s:``.

    Example
    -------
    >>> # with BackgroundStudio(Workspace(session, tmp / "out.ply")) as studio: print(studio.url)
    """

    def __init__(self, workspace: Workspace, *, port: int = 0, static_root: str | Path = STATIC,
                 max_upload: int = MAX_UPLOAD) -> None:
        self.studio = Studio(workspace, bind_local(port), static_root=static_root, max_upload=max_upload)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    def __enter__(self) -> Studio:
        def target() -> None:
            async def main() -> None:
                self._loop = asyncio.get_running_loop()
                self._stop = asyncio.Event()
                await self.studio.serve(self._stop, lambda s: self._ready.set())

            try:
                asyncio.run(main())
            except BaseException as exc:
                self._error = exc
                self._ready.set()

        self._thread = threading.Thread(target=target, name="unmesh-studio-server", daemon=True)
        self._thread.start()
        self._ready.wait(60)
        if self._error is not None:
            raise self._error
        return self.studio

    def __exit__(self, *exc: Any) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread is not None:
            self._thread.join(60)
