"""The ``iloci`` command line: a thin layer over the library.

Exit codes: 0 success; 2 user error (bad config, unknown component name,
invalid input, missing back end); 1 any other failure; 130 interrupted.

Each subcommand lives in a module of :mod:`iloci.commands` with a
``register(subparsers)`` function that adds its parser and sets
``func(args) -> int``. Plugins add theirs through the
``iloci_add_commands`` hook (e.g. ``iloci sweep`` from ``iloci-ray``).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import importlib.util
import os
import re
import sys
import warnings
from collections.abc import Sequence
from typing import Any

from iloci._version import __version__
from iloci.errors import IlociError, PluginError
from iloci.plugins import (FIRST_PARTY_DISTRIBUTIONS, PluginLoadWarning, get_plugin_manager,
                           hook_results)
from iloci.progress import FULL_ERRNOS, progress_sink, why_not_written

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
    "iloci.commands.serve",
)


def make_parser(plugin_manager: Any = None) -> argparse.ArgumentParser:
    """The ``iloci`` parser: the kernel's commands, then the plugins'.

    Parameters
    ----------
    plugin_manager : pluggy.PluginManager, optional
        Whose ``iloci_add_commands`` implementations add commands
        (default :func:`~iloci.plugins.get_plugin_manager`).

    Raises
    ------
    PluginError
        A plugin's command has a name already taken, or its ``iloci_add_commands``
        raised (naming the plugin).
    """

    parser = argparse.ArgumentParser(
        prog="iloci",
        description="Incremental Learning of Concepts by Imitation.")
    parser.add_argument("--version", action="version", version=f"iloci {__version__}")
    parser.add_argument("--traceback", action="store_true",
                        help="show the full traceback on errors (also ILOCI_TRACEBACK=1)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in COMMAND_MODULES:
        importlib.import_module(mod).register(sub)
    pm = plugin_manager or get_plugin_manager()
    info = getattr(pm, "iloci_plugin_info", {}) or {}
    for impl in reversed(pm.hook.iloci_add_commands.get_hookimpls()):
        # one plugin at a time, so that a failure names the plugin
        try:
            for _ in hook_results(pm, "iloci_add_commands", only=impl.plugin_name,
                                  subparsers=sub):
                pass
        except PluginError as exc:
            error = exc
            if isinstance(exc.__cause__, argparse.ArgumentError):  # a name taken twice
                error = PluginError(f"{exc.args[0].partition('. Fix')[0]}: a plugin's "
                                    "command clashes with another command; rename it, or "
                                    "block the plugin with ILOCI_BLOCK_PLUGINS.")
                error.__cause__ = exc.__cause__
            dist = getattr(info.get(impl.plugin_name), "distribution", None)
            if dist is None or dist == "iloci":   # the caller's plugin object, or iloci's
                raise error from error.__cause__
            # an installed plugin: its commands are left out, every other command works
            # (one raising iloci_add_commands made every iloci command fail)
            warnings.warn(f"iloci plugin {impl.plugin_name!r} (distribution {dist!r}) "
                          f"could not add its commands, which are left out: {error}",
                          PluginLoadWarning, stacklevel=2)
    _once(parser)
    return parser


class _StoreOnce(argparse._StoreAction):
    """A single-valued option given twice is an error, not "the last one wins" (which
    silently ran with another config, memory or output than the one meant)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        seen = namespace.__dict__.setdefault("_given_once", {})
        if self.dest in seen:
            parser.error(f"{option_string or self.option_strings[0]} given twice "
                         f"({seen[self.dest]!r} "
                         f"and {values!r}); give it once.")
        seen[self.dest] = values
        super().__call__(parser, namespace, values, option_string)


def _once(parser: argparse.ArgumentParser) -> None:
    """Make every single-valued option of ``parser`` and its subcommands a :class:`_StoreOnce`."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in set(action.choices.values()):
                _once(sub)
        elif type(action) is argparse._StoreAction and action.option_strings and \
                action.nargs in (None, "?"):
            action.__class__ = _StoreOnce


_shown: set[str] = set()


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one ``warning: ...`` line on stderr (no source line), once.

    A command builds the plugin manager more than once (the parser, then the
    command), and each build warns about the same faulty plugin again.
    """
    text = str(message)
    if text in _shown:
        return
    _shown.add(text)
    print(f"warning: {text}", file=sys.stderr, flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the exit code."""
    # warnings (a plugin that failed to load, a time unit) as one line each,
    # from parsing on; restored afterwards for in-process callers
    import iloci.data.writes  # noqa: F401  (registers the "iloci-bytes" codec error handler)
    for stream in (sys.stdout, sys.stderr):
        # a file name the OS gives as bytes that are not UTF-8 is printed with those
        # bytes as \xNN, not a UnicodeEncodeError (see iloci.data.files.shape_name)
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None and getattr(stream, "errors", "") in (
                "strict", "backslashreplace"):  # stderr: \udcNN otherwise
            reconfigure(errors="iloci-bytes")
    with warnings.catch_warnings(), progress_sink(_show_progress):
        warnings.showwarning = _show_warning
        _shown.clear()
        return _main(argv)


def _show_progress(what: str, fraction: float, seconds: float) -> None:
    """A long step's progress, one line on stderr (see :func:`iloci.progress.long_step`)."""
    state = f"done in {seconds:.1f} s" if fraction >= 1.0 else \
        f"{100 * fraction:.0f} % after {seconds:.1f} s"
    print(f"{what}: {state}", file=sys.stderr, flush=True)


def _main(argv: Sequence[str] | None) -> int:
    try:
        parser = make_parser()
    except IlociError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    show_tb = args.traceback or os.environ.get("ILOCI_TRACEBACK") == "1"
    try:
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
        # the reader of our output went away (`| head`): the command stopped where it was;
        # say so where it can still be read, and exit as a shell's SIGPIPE would
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # no second error when Python flushes at exit
        if getattr(args, "command", None) in ("teach", "evaluate", "sweep"):  # it learns
            with contextlib.suppress(OSError):
                print(f"stopped: the output of `iloci {args.command}` was closed (a pipe "
                      "into head?), so it stopped where it was; what it saved is kept. Run "
                      "it again without closing the pipe to go on.", file=sys.stderr)
        return 141
    except Exception as exc:  # a failure, not a user error
        if show_tb:
            raise
        said = _machine_refused(exc)
        if said:
            print(f"error: {said}", file=sys.stderr)
            return 1
        print(f"failed: {type(exc).__name__}: {exc}{_whose(args) or _raised_in_plugin(exc)}"
              "\n(run with --traceback for details)", file=sys.stderr)
        return 1


def _machine_refused(exc: BaseException) -> str:
    """What to say of an OSError the machine raised (a full disk, a file size limit, a
    read-only disk, no permission), naming the file; "" for any other exception."""
    if not isinstance(exc, OSError) or not exc.filename:
        return ""
    if exc.errno in FULL_ERRNOS or exc.errno == errno.EROFS:
        return (f"{why_not_written(exc.filename, exc)} Free some space (or write elsewhere) "
                "and run the command again.")
    if exc.errno in (errno.EACCES, errno.EPERM):
        return (f"permission denied: {exc.filename}. Fix its permissions (or use another "
                "file) and run the command again.")
    return ""


def _raised_in_plugin(exc: BaseException) -> str:
    """``""``, or which installed plugin's code raised ``exc`` (the innermost frame of the
    traceback in a module of a third-party plugin: a teacher's feedback, a clusterer), to
    report the failure to or block. A plugin audit: a teacher that raised inside
    feedback() gave "failed: RuntimeError: ..." naming no plugin."""
    owners = {top: (name, dist) for top, (name, dist) in _plugin_packages().items()
              if dist not in FIRST_PARTY_DISTRIBUTIONS}
    if not owners:
        return ""
    frames = []
    tb = exc.__traceback__
    while tb is not None:
        frames.append(tb)
        tb = tb.tb_next
    found = None
    for tb in reversed(frames):  # the innermost first
        module = str(tb.tb_frame.f_globals.get("__name__", ""))
        if module.partition(".")[0] in owners:
            found = (module, tb.tb_frame.f_code.co_name, tb.tb_lineno)
            break
    if found is None:  # raised in a worker process: its traceback came as text
        found = _in_remote_traceback(exc, owners)
    if found is None:
        return ""
    module, function, line = found
    name, dist = owners[module.partition(".")[0]]
    return (f"\nraised in plugin {name!r}" + (f" ({dist})" if dist else "")
            + f", {module}.{function} line {line}, not in iloci: report it to its authors, "
              f"or leave the plugin out with ILOCI_BLOCK_PLUGINS={name} (docs/hooks.md)")


def _in_remote_traceback(exc: BaseException, owners: dict[str, Any]
                         ) -> tuple[str, str, int] | None:
    """(module, function, line) of the innermost frame in a plugin's module of a worker's
    traceback (joblib's loky attaches it as the cause, as text), or None."""
    text = ""
    cause = exc.__cause__
    while cause is not None and not text:
        if type(cause).__name__ == "_RemoteTraceback":
            text = str(cause)
        cause = cause.__cause__
    if not text:
        return None
    places: dict[str, str] = {}      # a plugin module's file or folder -> its top module
    for top in owners:
        try:
            spec = importlib.util.find_spec(top)
        except (ImportError, ValueError):
            continue
        if spec is not None and spec.origin:
            where = os.path.dirname(spec.origin) if spec.submodule_search_locations \
                else spec.origin
            places[where] = top
    for path, line, function in reversed(re.findall(r'File "([^"]+)", line (\d+), in (\S+)',
                                                    text)):
        for where, top in places.items():
            if path == where or path.startswith(where + os.sep):
                rest = os.path.splitext(os.path.relpath(path, os.path.dirname(where)))[0]
                module = rest.replace(os.sep, ".") if where != path else top
                return module.removesuffix(".__init__"), function, int(line)
    return None


def _plugin_packages() -> dict[str, tuple[str, str | None]]:
    """Top-level package of each installed ``iloci`` entry point -> (plugin name, its
    distribution); the first entry point of a package names it."""
    from importlib.metadata import entry_points

    out: dict[str, tuple[str, str | None]] = {}
    for ep in entry_points(group="iloci"):
        out.setdefault(ep.module.partition(".")[0], (ep.name, getattr(ep.dist, "name", None)))
    return out


def _whose(args: argparse.Namespace) -> str:
    """``""`` for iloci's own commands; for a plugin's, which plugin's it is (to report
    the failure to, or block)."""
    module = getattr(args.func, "__module__", "") or ""
    top = module.partition(".")[0]
    if not top or top == "iloci":
        return ""
    owner = _plugin_packages().get(top)
    if owner is not None:
        name, dist = owner
        who = f"plugin {name!r}" + (f" ({dist}, module {module})" if dist else
                                    f" (module {module})")
        block = f"ILOCI_BLOCK_PLUGINS={name}"
    else:
        who, block = f"module {module}", "ILOCI_BLOCK_PLUGINS"
    return (f"\nin `iloci {args.command}`, a command of {who}, not of iloci: report it to its "
            f"authors, or leave the plugin out with {block} (docs/hooks.md)")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
