"""Connections of ``iloci serve``: no client holds the server by sending slowly.

uvicorn waits for a request's head (request line and headers) without a
time limit: a client that connects and sends nothing, or a byte a second
(a "slow loris"), keeps its connection, and a few hundred of them use up
the process's file descriptors. Then the page gets no answer and asyncio
logs a traceback for every refused ``accept`` (``OSError: [Errno 24] Too
many open files``), tens of thousands of lines.

:func:`guarded_protocol` is uvicorn's h11 protocol with two limits:

- a request's head must arrive within :data:`HEAD_SECONDS` of the
  connection opening or of the previous response (else the connection is
  closed); the body has its own limit in the app
  (:data:`iloci.web.app.BODY_SECONDS`);
- at most :data:`MAX_CONNECTIONS` connections are open: a new one closes
  those that have waited longest (over :data:`GRACE_SECONDS`) for a
  request head (idle or stalled; a browser opens a new one when it needs
  it), so the person's page is answered while others hold connections.
  The listening socket's backlog is the same number (``uvicorn.run(...,
  backlog=...)``, see :func:`uvicorn_options`): asyncio accepts up to a
  backlog of connections at once, and uvicorn's default of 2048 would run
  out of descriptors before any limit applies.

A request whose head has arrived is never cut: a rehearsal may take
minutes before its answer.
"""

from __future__ import annotations

import resource
from typing import Any

__all__ = ["HEAD_SECONDS", "MAX_CONNECTIONS", "GRACE_SECONDS", "guarded_protocol",
           "connection_limit", "uvicorn_options"]

#: Seconds a request's head (request line and headers) may take to arrive.
HEAD_SECONDS = 10.0
#: Most connections open at once (fewer where the descriptor limit is low:
#: :func:`connection_limit`). A browser opens at most 6 to one server.
MAX_CONNECTIONS = 128
#: A connection waiting this long for its request head may be closed for a new one.
GRACE_SECONDS = 1.0


def connection_limit(wanted: int = MAX_CONNECTIONS) -> int:
    """``wanted``, or a quarter of the soft descriptor limit if lower (at least 8).

    The rest of the descriptors stay for the memory file, the worker's
    pipes and the libraries.
    """
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY or soft <= 0:
        return wanted
    return max(8, min(wanted, soft // 4))


def guarded_protocol(head_seconds: float = HEAD_SECONDS,
                     max_connections: int | None = None) -> type:
    """uvicorn's h11 protocol class with a head deadline and a connection limit.

    Parameters
    ----------
    head_seconds : float
        Deadline for a request's head, in seconds (> 0).
    max_connections : int, optional
        Most connections open at once; default :func:`connection_limit`.

    Returns
    -------
    type
        For ``uvicorn.run(app, http=...)`` / ``uvicorn.Config(http=...)``.

    Raises
    ------
    ValueError
        ``head_seconds`` not positive or ``max_connections`` below 1.
    """
    from uvicorn.protocols.http.h11_impl import H11Protocol

    if not head_seconds > 0:
        raise ValueError(f"head_seconds must be > 0, got {head_seconds!r}.")
    limit = connection_limit() if max_connections is None else int(max_connections)
    if limit < 1:
        raise ValueError(f"max_connections must be >= 1, got {max_connections!r}.")

    class GuardedH11Protocol(H11Protocol):
        """h11 with a deadline for each request head and a cap on open connections."""

        head_seconds: float         # set below, for inspection (tests, logs)
        max_connections: int
        _head_timer: Any = None
        _waiting_since = 0.0

        def connection_made(self, transport: Any) -> None:
            super().connection_made(transport)
            self._await_head()
            connections: Any = self.connections     # uvicorn's set of open protocols
            if len(connections) > limit:
                now = self.loop.time()
                grace = min(GRACE_SECONDS, head_seconds)
                idle: list[Any] = sorted(
                    (c for c in connections
                     if c is not self and getattr(c, "_waiting_head", lambda: False)()
                     and now - c._waiting_since >= grace),
                    key=lambda c: c._waiting_since)
                for c in idle[:len(connections) - limit]:
                    c._close_waiting()

        def _waiting_head(self) -> bool:
            """No request under way: idle, or its head still arriving."""
            return self.cycle is None or self.cycle.response_complete

        def _await_head(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
            self._waiting_since = self.loop.time()
            self._head_timer = self.loop.call_later(head_seconds, self._head_late)

        def _head_late(self) -> None:
            self._head_timer = None
            if self._waiting_head():
                self._close_waiting()

        def _close_waiting(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
                self._head_timer = None
            if not self.transport.is_closing():
                self.transport.close()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            if not self.transport.is_closing():
                self._await_head()

        def connection_lost(self, exc: Exception | None) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
                self._head_timer = None
            super().connection_lost(exc)

    GuardedH11Protocol.head_seconds = head_seconds
    GuardedH11Protocol.max_connections = limit
    return GuardedH11Protocol


def uvicorn_options(head_seconds: float = HEAD_SECONDS,
                    max_connections: int | None = None) -> dict[str, Any]:
    """Keyword arguments for ``uvicorn.run`` / ``uvicorn.Config``: the protocol, its backlog."""
    protocol = guarded_protocol(head_seconds, max_connections)
    return {"http": protocol, "backlog": protocol.max_connections}  # type: ignore[attr-defined]
