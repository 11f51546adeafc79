"""The ``unmesh`` command.

Each capability owns its sub-command in a module that defines
``register(subparsers)``; the module adds a parser and sets ``func`` to a function
``run(args) -> int``. Modules are listed in :data:`COMMAND_MODULES` and must stay
cheap to import (heavy imports go inside ``run``).

User errors (:class:`unmesh.errors.UnmeshError`, missing files, bad flags) print a
single line ``unmesh: error: ...`` on stderr and exit with status 1; ``--debug``
shows the traceback instead. Ctrl-C exits with status 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from unmesh._version import __version__
from unmesh.errors import UnmeshError

__all__ = ["COMMAND_MODULES", "build_parser", "main"]

#: Modules that contribute sub-commands, in help order.
COMMAND_MODULES: tuple[str, ...] = (
    "unmesh.cli.info",
    "unmesh.cli.sample",
    "unmesh.render.cli",
    "unmesh.sph.cli",
    "unmesh.shells.cli",
    "unmesh.fem.cli",
    "unmesh.batch.cli",
    "unmesh.gallery.cli",
)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line and exit status 1."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(1, f"unmesh: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered sub-command."""
    parser = _Parser(prog="unmesh", description="Modeling and animation with relaxed connectivity.")
    parser.add_argument("--version", action="version", version=f"unmesh {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``unmesh`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 1
    debug = bool(args.debug)
    try:
        return int(args.func(args) or 0)
    except UnmeshError as exc:
        if debug:
            raise
        print(f"unmesh: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        if debug:
            raise
        where = f": {exc.filename}" if getattr(exc, "filename", None) else ""
        print(f"unmesh: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if debug:
            raise
        print("unmesh: interrupted", file=sys.stderr)
        return 130
