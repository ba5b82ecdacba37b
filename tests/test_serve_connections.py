"""``iloci serve``'s connections (:mod:`iloci.web.connections`) against a real uvicorn on a socket.

A client that connects and sends nothing, or a byte at a time (a "slow
loris"), is closed once the head deadline passes; hundreds of them do not
keep the page from being answered, and no descriptor runs out. The
deadline here is short (1 s); the assertions wait up to 60 s for what must
happen, so a loaded machine makes them slower, not wrong.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time

import pytest

pytest.importorskip("uvicorn")

from iloci.web.connections import connection_limit, guarded_protocol, uvicorn_options  # noqa: E402


async def hello(scope, receive, send):
    """The smallest ASGI app: 200 "ok" (the protocol, not the app, is under test)."""
    if scope["type"] != "http":
        return
    await send({"type": "http.response.start", "status": 200,
                "headers": [(b"content-type", b"text/plain")]})
    await send({"type": "http.response.body", "body": b"ok"})


@contextlib.contextmanager
def server(**options):
    import uvicorn
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    srv = uvicorn.Server(uvicorn.Config(hello, host="127.0.0.1", port=port, log_level="warning",
                                        **uvicorn_options(**options)))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not srv.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert srv.started
    try:
        yield port
    finally:
        srv.should_exit = True
        thread.join(10)


def get(port: int) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=60) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        data = b""
        while chunk := s.recv(4096):
            data += chunk
    return data


def closed_by_server(s: socket.socket, seconds: float = 60) -> bool:
    """Whether the server closes ``s`` within ``seconds`` (EOF or reset)."""
    s.settimeout(seconds)
    try:
        return s.recv(100) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def test_a_client_that_sends_its_request_head_slowly_is_closed():
    with server(head_seconds=1.0) as port:
        silent = socket.create_connection(("127.0.0.1", port))
        partial = socket.create_connection(("127.0.0.1", port))
        partial.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n")      # the head never ends
        drip = socket.create_connection(("127.0.0.1", port))
        drip.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-A: ")
        stop = threading.Event()

        def dripping():
            with contextlib.suppress(OSError):
                while not stop.is_set():
                    drip.sendall(b"a")          # a byte every 0.2 s: never a whole head
                    time.sleep(0.2)
        t = threading.Thread(target=dripping, daemon=True)
        t.start()
        try:
            assert closed_by_server(silent)
            assert closed_by_server(partial)
            assert closed_by_server(drip)
        finally:
            stop.set()
            t.join(5)
            for s in (silent, partial, drip):
                s.close()
        assert get(port).startswith(b"HTTP/1.1 200")                       # still serving


def test_many_stalled_connections_do_not_keep_the_page_from_an_answer():
    with server(head_seconds=30.0, max_connections=16) as port:
        stalled = []
        try:
            for _ in range(100):
                s = socket.create_connection(("127.0.0.1", port), timeout=60)
                s.sendall(b"GET / HTTP/1.1\r\n")
                stalled.append(s)
            time.sleep(1.5)                     # past the grace: the stalled ones may go
            # answered although 100 clients hold (or held) a connection and the head
            # deadline (30 s) has not passed: the longest-waiting ones were closed
            assert get(port).startswith(b"HTTP/1.1 200")
            assert sum(closed_by_server(s, 10) for s in stalled[:50]) == 50
        finally:
            for s in stalled:
                s.close()


def test_the_limits_are_checked():
    with pytest.raises(ValueError, match="head_seconds"):
        guarded_protocol(head_seconds=0)
    with pytest.raises(ValueError, match="max_connections"):
        guarded_protocol(max_connections=0)
    assert 8 <= connection_limit() <= 128
    assert uvicorn_options(max_connections=20)["backlog"] == 20
