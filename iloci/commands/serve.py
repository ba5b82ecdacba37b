"""``iloci serve``: teach the robot in a browser (a local web app).

Draw on the page; the robot guesses and answers by drawing; say yes or no.
The memory file is saved after every change, and a restarted server goes on
from it. Needs the ``serve`` extra: ``pip install 'iloci[serve]'``.
"""

from __future__ import annotations

import argparse
import asyncio
import errno
import logging
import signal
import socket
import sys
from pathlib import Path
from typing import Any

from iloci.agent import Agent, build
from iloci.commands.teach import DEFAULT_MEMORY, PAGE, add_protocol_argument, command_config
from iloci.concepts.memory import load_memory
from iloci.data.writes import check_memory_path
from iloci.errors import InvalidInputError, MissingBackendError
from iloci.progress import acquire_memory_lock
from iloci.worker import WorkerError

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
    InvalidInputError
        ``memory`` cannot be a memory file (a symlink loop, a directory, a
        folder where nothing can be written).
    MemoryLockedError
        Another process (``iloci teach``, another ``iloci serve``) holds
        the memory, under this name or another (a hard link); its holder
        is named.
    """
    check_memory_path(memory)               # a loop, a directory, a folder that takes no file
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
    # the web page needs the serve extra (starlette): loaded when the command runs
    from iloci.web.app import Classroom

    path = Path(memory)
    header = load_memory(path)[2] if path.exists() else None
    cfg = command_config(config, header, protocol, PAGE, memory=path)
    # the person at the page is the teacher: no teacher object is asked
    agent = Agent.load(path, cfg) if header is not None else build(cfg)
    if worker:
        agent.start_worker()
    return Classroom(agent, path)


def run(args: argparse.Namespace) -> int:
    try:
        import uvicorn

        # the web page needs the serve extra (starlette): loaded when the command runs
        from iloci.web.app import create_app
        from iloci.web.connections import uvicorn_options
    except ImportError as exc:
        raise MissingBackendError("command", "serve", ["starlette", "uvicorn"],
                                  "pip install 'iloci[serve]'") from exc
    if not 0 < args.port < 65536:
        raise InvalidInputError(f"--port must be 1..65535, got {args.port}.")
    check_can_listen(args.host, args.port)  # before the memory is opened and a URL shown
    classroom = build_classroom(args.memory, args.config, protocol=args.protocol)
    hosts = [args.host, *args.allow_host]
    app = create_app(classroom, hosts=hosts, on_shutdown=lambda: _stop_worker(classroom))
    # uvicorn stops gracefully on SIGTERM, then raises it again once it has
    # stopped: with the default action the process would end before the
    # lines below release the memory's lock; as SystemExit they run
    previous = signal.signal(signal.SIGTERM, _exit_on_sigterm)
    try:
        mem = classroom.agent.memory
        print(f"memory {args.memory}: {mem.summary().splitlines()[0]}")
        print(f"teach the robot at http://{_shown(args.host)}:{args.port}/ (Ctrl-C to stop)",
              flush=True)
        # a request's head must arrive within 10 s and at most 128 connections stay
        # open (iloci.web.connections): a client that connects and sends slowly
        # does not hold the server
        server = _server_class(uvicorn)(uvicorn.Config(
            app, host=args.host, port=args.port, log_level="warning", timeout_keep_alive=5,
            **uvicorn_options()))
        quiet = _CancelledAtExit()
        logging.getLogger("uvicorn.error").addFilter(quiet)
        try:
            server.run()
        finally:
            logging.getLogger("uvicorn.error").removeFilter(quiet)
    finally:
        _stop_worker(classroom)
        classroom.close()
        signal.signal(signal.SIGTERM, previous)
    return 0


def check_can_listen(host: str, port: int) -> None:
    """Raise InvalidInputError when ``host:port`` cannot be listened on: an unknown host,
    a port in use (another server), a port this user may not open. uvicorn said so only
    after the page's address was printed, in its own words, with exit code 3."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                   flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise InvalidInputError(f"--host {host}: no such host or address here ({exc.strerror}"
                                "); give an address of this machine, e.g. 127.0.0.1 (the "
                                "default) or 0.0.0.0 (every interface).") from None
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn binds
        try:
            probe.bind(address)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                why = "is in use (another iloci serve, or another server)"
            elif exc.errno in (errno.EACCES, errno.EPERM):
                why = "may not be opened by this user (ports below 1024 need root)"
            elif exc.errno == errno.EADDRNOTAVAIL:
                raise InvalidInputError(f"--host {host}: not an address of this machine; "
                                        "give one of its addresses, e.g. 127.0.0.1 (the "
                                        "default) or 0.0.0.0.") from None
            else:
                why = f"cannot be opened ({exc.strerror})"
            raise InvalidInputError(f"port {port} on {host} {why}: choose another --port. "
                                    "Nothing was started.") from None


def _exit_on_sigterm(signum: int, frame: Any) -> None:
    raise SystemExit(128 + signum)


def _server_class(uvicorn: Any) -> type:
    """uvicorn's Server, saying on the first Ctrl-C what it waits for.

    uvicorn stops taking connections and lets the requests under way end
    (a drawing being learned is learned and saved; a client sending slowly
    has up to 15 s, iloci.web.schemas); it used to do so without a word,
    for up to 16 s. A second Ctrl-C stops at once.
    """
    class Server(uvicorn.Server):
        def handle_exit(self, sig: int, frame: Any) -> None:
            if not self.should_exit:
                open_now = len(getattr(self.server_state, "connections", ()))
                print(f"stopping: finishing the {open_now} request(s) under way (a drawing "
                      "being learned is saved first; a slow client gets at most 15 s). "
                      "Ctrl-C again to stop at once.", file=sys.stderr, flush=True)
            super().handle_exit(sig, frame)
    return Server


class _CancelledAtExit(logging.Filter):
    """Drops uvicorn's tracebacks of the tasks it cancels when told to stop at once (a
    second Ctrl-C): requests cut short on purpose, not faults. The memory file holds
    every step saved before (each is saved whole)."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, asyncio.CancelledError):
            return False
        # the lifespan task logs its traceback as the message itself
        text = str(record.msg)
        return not (text.startswith("Traceback") and text.rstrip().endswith(
            "CancelledError"))


def _stop_worker(classroom: Any) -> None:
    """Stop the agent's worker; one that is already gone is said in a line, not a traceback.

    A signal to the whole process group (``timeout``, a service manager,
    a closed terminal) stops the worker process before the server: its
    network cannot be copied back then, and nothing is lost, since the
    memory file was saved after every change.
    """
    try:
        classroom.agent.close()
    except WorkerError:
        print(f"the network's worker process had already stopped; {classroom.memory_path} "
              "holds every change saved before.", file=sys.stderr, flush=True)


def _shown(host: str) -> str:
    """The address to open in a browser for a listen address."""
    if host in ("0.0.0.0", "", "::"):
        return "127.0.0.1"
    return f"[{host}]" if ":" in host else host
