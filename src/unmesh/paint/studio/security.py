"""The studio's guards: session token, same-origin checks, static files and output paths.

Every check is a pure function so that it is tested without a server:

* :func:`new_token` makes the per-session secret that the page's URL carries;
  :func:`token_ok` compares in constant time.
* :func:`origin_ok` / :func:`host_ok` accept only the studio's own origin
  (``http://127.0.0.1:PORT`` or ``http://localhost:PORT``): a page on another site cannot
  drive the session (cross-site WebSocket hijacking) and a rebound DNS name cannot reach it.
* :func:`static_file` maps a request path to one of the package's own static files, refusing
  ``..``, encoded and double-encoded dots, absolute paths, backslashes and symlinks.
* :func:`output_path` confines save/load/export names to the output folder.

Example
-------
>>> origin_ok("http://127.0.0.1:8000", 8000), origin_ok("http://evil.example", 8000)
(True, False)
>>> output_path("/tmp/out", "model.ply", (".ply",)).name
'model.ply'
"""

from __future__ import annotations

import hmac
import os
import re
import secrets
from pathlib import Path

from unmesh.errors import InputError

__all__ = ["STATIC_TYPES", "PathRefused", "host_ok", "new_token", "origin_ok", "output_path", "static_file",
           "token_ok"]

#: File types the studio serves, with their content types.
STATIC_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".png": "image/png",
    ".svg": "image/svg+xml",
}

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,119}$")
_SEGMENT = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,119}$")


class PathRefused(InputError):
    """A request path or file name that escapes its folder (HTTP 403)."""


def new_token() -> str:
    """A fresh random session token (32 bytes, URL-safe base64)."""
    return secrets.token_urlsafe(32)


def token_ok(given: str | None, token: str) -> bool:
    """True when ``given`` equals the session ``token`` (constant-time comparison)."""
    if not given or not isinstance(given, str):
        return False
    return hmac.compare_digest(given.encode("utf-8", "replace"), token.encode("utf-8"))


def _allowed_hosts(port: int) -> set[str]:
    return {f"127.0.0.1:{port}", f"localhost:{port}"}


def host_ok(host: str | None, port: int) -> bool:
    """True when the ``Host`` header names the studio itself (defeats DNS rebinding)."""
    return bool(host) and host.lower() in _allowed_hosts(port)


def origin_ok(origin: str | None, port: int) -> bool:
    """True when ``origin`` is the studio's own origin; a missing origin is refused."""
    if not origin:
        return False
    return origin.lower() in {f"http://{h}" for h in _allowed_hosts(port)}


def static_file(root: str | os.PathLike[str], relpath: str) -> Path:
    """The file of the static folder ``root`` that the (already URL-decoded) ``relpath`` names.

    Raises
    ------
    PathRefused
        When ``relpath`` is absolute, has empty, ``.``/``..`` or encoded segments (a ``%`` left after
        decoding means double encoding), backslashes or NUL, a file type not in
        :data:`STATIC_TYPES`, or resolves (through symlinks) outside ``root`` or to a symlink.
    FileNotFoundError
        When the name is acceptable but no such file exists.

    Example
    -------
    >>> static_file("/nonexistent", "../etc/passwd")
    Traceback (most recent call last):
    ...
    unmesh.paint.studio.security.PathRefused: path: refused '../etc/passwd' (segment '..')
    """
    if not isinstance(relpath, str) or not relpath or relpath.startswith("/") or "\\" in relpath or "\x00" in relpath:
        raise PathRefused(f"path: refused {relpath!r} (absolute, empty or with backslash/NUL)")
    parts = relpath.split("/")
    for part in parts:
        if not _SEGMENT.match(part) or set(part) == {"."} or ".." in part:
            raise PathRefused(f"path: refused {relpath!r} (segment {part!r})")
    if Path(parts[-1]).suffix.lower() not in STATIC_TYPES:
        raise PathRefused(f"path: refused {relpath!r} (file type not served)")
    base = Path(root).resolve()
    path = base.joinpath(*parts)
    probe = base
    for part in parts:
        probe = probe / part
        if probe.is_symlink():
            raise PathRefused(f"path: refused {relpath!r} (symlink)")
    real = path.resolve()
    if base not in real.parents:
        raise PathRefused(f"path: refused {relpath!r} (outside the static folder)")
    if not real.is_file():
        raise FileNotFoundError(relpath)
    return real


def output_path(folder: str | os.PathLike[str], name: str, suffixes: tuple[str, ...]) -> Path:
    """``folder / name`` for a plain file name with one of ``suffixes``, never outside ``folder``.

    Raises
    ------
    PathRefused
        For names with separators, ``..``, a leading dot, absolute paths, other suffixes, or an
        existing symlink at that name.

    Example
    -------
    >>> output_path("/tmp/out", "../x.ply", (".ply",))
    Traceback (most recent call last):
    ...
    unmesh.paint.studio.security.PathRefused: name: expected a plain file name ending in .ply, got '../x.ply'
    """
    want = " or ".join(suffixes)
    if not isinstance(name, str) or not _NAME.match(name) or ".." in name \
            or not name.lower().endswith(tuple(s.lower() for s in suffixes)):
        raise PathRefused(f"name: expected a plain file name ending in {want}, got {name!r}")
    base = Path(folder).resolve()
    path = base / name
    if path.is_symlink() or path.resolve().parent != base:
        raise PathRefused(f"name: refused {name!r} (symlink or outside the output folder)")
    return path
