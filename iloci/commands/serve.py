"""``iloci serve``: teach the robot in a browser (a local web app).

Draw on the page; the robot guesses and answers by drawing; say yes or no.
The memory file is saved after every change, and a restarted server goes on
from it. Needs the ``serve`` extra: ``pip install 'iloci[serve]'``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from iloci.commands.teach import DEFAULT_MEMORY, PAGE, add_protocol_argument, command_config
from iloci.errors import InvalidInputError, MissingBackendError

__all__ = ["register", "run", "build_classroom"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve", help="teach the robot in a browser: draw, watch it answer, say yes or no",
        description="Start a local web app: draw a shape with the mouse, a pen or a finger; "
                    "the robot guesses its concept and answers by drawing; answer yes or no "
                    "and it learns. Name its concepts, recognize drawings. The memory file "
                    "is saved after every change; with an existing --memory, teaching goes "
                    "on from it.")
    p.add_argument("--memory", metavar="FILE", default=DEFAULT_MEMORY,
                   help=f"memory file to continue from and save to (default {DEFAULT_MEMORY})")
    p.add_argument("--config", metavar="FILE",
                   help="TOML config (default: the one saved in --memory, else the defaults)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this computer only)")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    add_protocol_argument(p)
    p.add_argument("--allow-host", metavar="NAME", action="append", default=[],
                   help="also accept requests whose Host header is NAME (a name this computer "
                        "is reached by, e.g. behind a proxy; repeatable). Requests under any "
                        "other name are refused, which stops DNS-rebinding attacks; '*' accepts "
                        "every name")
    p.set_defaults(func=run)


def build_classroom(memory: str | Path, config: Any = None, *, worker: bool = True,
                    lock: bool = True, protocol: str = "interactive"):
    """The :class:`~iloci.web.app.Classroom` of a memory file (new when it does not exist).

    The config is ``config`` (a TOML path or a mapping), else the memory's,
    else the defaults; with ``protocol="interactive"`` the ``[learner]``
    settings of :data:`iloci.commands.teach.PAGE` fill what ``config`` does
    not set (see :func:`~iloci.commands.teach.command_config`).
    The agent's network runs in a worker process unless ``worker=False``.
    With ``lock`` (the default) the memory's lock is taken first, the one
    ``iloci teach`` takes (:func:`iloci.progress.acquire_memory_lock`), and
    held until ``classroom.close()``.

    Raises
    ------
    MemoryLockedError
        Another process (``iloci teach``, another ``iloci serve``) holds
        the memory; its holder is named.
    InvalidInputError
        The memory's folder cannot take files (nothing was done).
    """
    from iloci.data.files import writable_file
    from iloci.progress import acquire_memory_lock
    writable_file(memory, "--memory")  # before the lock: its folder must take files
    release = acquire_memory_lock(memory, "iloci serve") if lock else None
    try:
        classroom = _build(memory, config, worker, protocol)
    except BaseException:
        if release is not None:
            release()
        raise
    classroom.close_lock = release
    return classroom


def _build(memory: str | Path, config: Any, worker: bool, protocol: str):
    from iloci.agent import Agent, build
    from iloci.concepts.memory import load_memory
    from iloci.web.app import Classroom

    path = Path(memory)
    header = load_memory(path)[2] if path.exists() else None
    cfg = command_config(config, header, protocol, PAGE)
    # the person at the page is the teacher: no teacher object is asked
    agent = Agent.load(path, cfg) if header is not None else build(cfg)
    if worker:
        agent.start_worker()
    return Classroom(agent, path)


def run(args: argparse.Namespace) -> int:
    try:
        import uvicorn

        from iloci.web.app import create_app
    except ImportError as exc:
        raise MissingBackendError("command", "serve", ["starlette", "uvicorn"],
                                  "pip install 'iloci[serve]'") from exc
    if not 0 < args.port < 65536:
        raise InvalidInputError(f"--port must be 1..65535, got {args.port}.")
    classroom = build_classroom(args.memory, args.config, protocol=args.protocol)
    hosts = [args.host, *args.allow_host]
    app = create_app(classroom, hosts=hosts, on_shutdown=classroom.agent.close)
    mem = classroom.agent.memory
    print(f"memory {args.memory}: {mem.summary().splitlines()[0]}")
    print(f"teach the robot at http://{_shown(args.host)}:{args.port}/ (Ctrl-C to stop)",
          flush=True)
    try:
        uvicorn.run(app, host=args.host, port=args.port, log_level="warning",
                    timeout_keep_alive=5)
    finally:
        classroom.close()
    return 0


def _shown(host: str) -> str:
    """The address to open in a browser for a listen address."""
    if host in ("0.0.0.0", "", "::"):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host else host
