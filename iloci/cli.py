"""The ``iloci`` command line: a thin layer over the library.

Exit codes: 0 success; 2 user error (bad config, unknown component name,
invalid input, missing back end); 1 any other failure; 130 interrupted.

Each subcommand lives in a module of :mod:`iloci.commands` with a
``register(subparsers)`` function that adds its parser and sets
``func(args) -> int``.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings
from collections.abc import Sequence

from iloci.errors import IlociError

__all__ = ["main"]

#: Subcommand modules, in the order ``iloci --help`` lists them.
COMMAND_MODULES = (
    "iloci.commands.plugins",
    "iloci.commands.robots",
    "iloci.commands.config",
    "iloci.commands.show",
    "iloci.commands.teach",
    "iloci.commands.recognize",
    "iloci.commands.evaluate",
    "iloci.commands.draw",
)


def make_parser() -> argparse.ArgumentParser:
    from iloci import __version__

    parser = argparse.ArgumentParser(
        prog="iloci",
        description="Incremental Learning of Concepts by Imitation.")
    parser.add_argument("--version", action="version", version=f"iloci {__version__}")
    parser.add_argument("--traceback", action="store_true",
                        help="show the full traceback on errors (also ILOCI_TRACEBACK=1)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in COMMAND_MODULES:
        importlib.import_module(mod).register(sub)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one ``warning: ...`` line on stderr (no source line)."""
    print(f"warning: {message}", file=sys.stderr, flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the exit code."""
    parser = make_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    show_tb = args.traceback or os.environ.get("ILOCI_TRACEBACK") == "1"
    try:
        with warnings.catch_warnings():  # restores showwarning for in-process callers
            warnings.showwarning = _show_warning
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return 130
    except IlociError as exc:
        if show_tb:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0
    except Exception as exc:  # a failure, not a user error
        if show_tb:
            raise
        print(f"failed: {type(exc).__name__}: {exc}\n(run with --traceback for details)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
