"""The ``unmesh`` command.

Each capability owns its sub-command in a module that defines
``register(subparsers)``; the module adds a parser and sets ``func`` to a function
``run(args) -> int``. Modules are listed in :data:`COMMAND_MODULES` and must stay
cheap to import (heavy imports go inside ``run``).

User errors (:class:`unmesh.errors.UnmeshError`, missing files, bad flags) print a
single line ``unmesh: error: ...`` on stderr and exit with status 1. Any other
exception (a bug) prints one line too, ending in "run with --debug for the
traceback", and exits with status 1. ``--debug`` (accepted anywhere on the command
line) shows the traceback instead. Ctrl-C exits with status 130.

Help texts are written as reST in docstrings; :class:`_Parser` shows them without
the markup (``literal`` quotes, ``::`` block markers, ``:func:`` roles).
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
from collections.abc import Sequence

from unmesh._version import __version__
from unmesh.errors import UnmeshError

__all__ = ["COMMAND_MODULES", "build_parser", "main", "plain_text"]

#: Modules that contribute sub-commands, in help order.
COMMAND_MODULES: tuple[str, ...] = (
    "unmesh.cli.info",
    "unmesh.cli.sample",
    "unmesh.render.cli",
    "unmesh.sph.cli",
    "unmesh.shells.cli",
    "unmesh.fem.cli",
    "unmesh.csg.cli",
    "unmesh.batch.cli",
    "unmesh.paint.cli",
    "unmesh.convert.cli",
    "unmesh.gallery.cli",
    "unmesh.cli.scenes",
)

_ROLE = re.compile(r":(?:func|class|meth|mod|data|attr|exc|obj|ref|doc):`~?([^`]+)`")


def plain_text(text: str) -> str:
    """reST markup of help texts removed: ````x```` -> ``x``, ``Examples::`` -> ``Examples:``.

    Example
    -------
    >>> plain_text("Writes ``OUT/a.ply``. See :func:`unmesh.io.load`. Examples::")
    'Writes OUT/a.ply. See unmesh.io.load. Examples:'
    """
    text = _ROLE.sub(r"\1", text)
    text = text.replace("``", "")
    text = re.sub(r"(\S)::(\s*)$", r"\1:\2", text, flags=re.MULTILINE)
    return re.sub(r"^(\s*)::\s*$\n?", "", text, flags=re.MULTILINE)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line and exit status 1."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(1, f"unmesh: error: {message} (see '{self.prog} --help')\n")

    def format_help(self) -> str:
        return plain_text(super().format_help())

    def format_usage(self) -> str:
        return plain_text(super().format_usage())


def _split_debug(argv: Sequence[str]) -> tuple[list[str], bool]:
    """Remove every ``--debug`` before a ``--`` separator; returns (argv, debug)."""
    out: list[str] = []
    debug = False
    for i, a in enumerate(argv):
        if a == "--":
            out.extend(argv[i:])
            break
        if a == "--debug":
            debug = True
        else:
            out.append(a)
    return out, debug


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered sub-command."""
    parser = _Parser(prog="unmesh", description="Modeling and animation with relaxed connectivity.",
                     epilog="Environment: UNMESH_MEMORY_BUDGET (default 4GiB, 0 = no limit) caps what a file "
                            "header or a scene may make unmesh allocate; larger inputs are refused up front "
                            "with an estimate. 'unmesh scenes' lists the shipped example scenes.")
    parser.add_argument("--version", action="version", version=f"unmesh {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``unmesh`` console script; returns the exit status.

    ``--debug`` may appear anywhere (``unmesh sph scene.toml -o out --debug``).
    """
    argv, debug = _split_debug(list(sys.argv[1:] if argv is None else argv))
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 1
    try:
        return int(args.func(args) or 0)
    except UnmeshError as exc:
        if debug:
            raise
        print(f"unmesh: error: {_one_line(str(exc))}", file=sys.stderr)
        return 1
    except OSError as exc:
        if debug:
            raise
        where = f": {exc.filename}" if getattr(exc, "filename", None) else ""
        print(f"unmesh: error: {_one_line(str(exc.strerror or exc))}{where}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if debug:
            raise
        print("unmesh: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: still one line, the traceback on request
        if debug:
            raise
        print(f"unmesh: error: unexpected {type(exc).__name__}: {_one_line(str(exc))} "
              "(run with --debug for the traceback)", file=sys.stderr)
        return 1


def _one_line(text: str, limit: int = 2000) -> str:
    """Messages on one line (multi-line exception texts joined with ' | '), at most ``limit`` chars."""
    line = " | ".join(part.strip() for part in text.splitlines() if part.strip())
    return line if len(line) <= limit else line[:limit - 3] + "..."
