"""Who may use the server: the Host check (DNS rebinding), the origin check, the token.

As Jupyter's server does: a request whose ``Host`` is not an address the
server listens on is refused before any route runs (:class:`HostGuard`);
a request from another site (``Origin``, ``Sec-Fetch-Site``) is refused;
a write needs the server's token (:data:`TOKEN_HEADER`) and the body's
declared type. Every response carries :data:`SAFETY_HEADERS` (no framing,
no cross-origin reads, no sniffing).
"""

from __future__ import annotations

import hmac
import json
import re
from typing import Any

__all__ = ["TOKEN_HEADER", "LOCAL_HOSTS", "SAFETY_HEADERS", "host_name", "foreign",
           "write_refusal", "HostGuard"]

#: The header carrying the server's token on every write.
TOKEN_HEADER = "X-Iloci-Token"
#: Host names always accepted (this computer).
LOCAL_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})
#: Added to every response.
SAFETY_HEADERS = [
    (b"x-frame-options", b"DENY"),
    (b"content-security-policy",
     b"default-src 'self'; img-src 'self' data: blob:; frame-ancestors 'none'; "
     b"form-action 'none'; base-uri 'none'"),
    (b"cross-origin-resource-policy", b"same-origin"),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer")]


#: A Host header: a name or IPv4 address, or an IPv6 address in brackets, then an optional port.
_HOST = re.compile(r"(\[[0-9a-f:.]+\]|[a-z0-9._-]+)(:[0-9]{1,5})?")


def host_name(host: str) -> str:
    """``"127.0.0.1:8000"`` -> ``"127.0.0.1"``, ``"[::1]:8000"`` -> ``"::1"`` (lower case).

    Anything else than a name (or address) and an optional port, such as
    ``"[::1]evil.test"`` or ``"127.0.0.1:8000 evil"``, gives ``""``, which
    no server accepts unless every name is (``--allow-host '*'``). The port
    is not compared: a port forward (``ssh -L 9000:127.0.0.1:8000``)
    reaches the server under another one, and a DNS-rebinding page always
    sends its own name.
    """
    host = host.strip().lower()
    m = _HOST.fullmatch(host)
    if m is None:
        return ""
    name = m.group(1)
    return name[1:-1] if name.startswith("[") else name


def foreign(headers: Any, scheme: str = "http") -> str | None:
    """Why a request with these headers comes from another site, or None.

    ``scheme``: the request's (``http``; ``https`` behind a proxy that says
    so): an ``Origin`` must be this scheme, this host and this port.
    """
    site = headers.get("sec-fetch-site")
    if site is not None and site not in ("same-origin", "none"):
        return f"a request from another site (Sec-Fetch-Site: {site[:20]})"
    origin = headers.get("origin")
    if origin is not None:
        host = headers.get("host", "")
        if origin.lower() != f"{scheme}://{host}".lower():
            return f"a request from another page (Origin {origin[:80]})"
    return None


def write_refusal(headers: Any, token: str, body: str = "json") -> tuple[int, str] | None:
    """Why a write with these headers is refused (status, message), or None.

    Parameters
    ----------
    headers : mapping
        The request's headers (lower-case names).
    token : str
        The server's token, compared in constant time.
    body : {"json", "file"}
        The body the route takes: ``application/json`` or ``application/octet-stream``.
    """
    given = headers.get(TOKEN_HEADER.lower(), "")
    if not hmac.compare_digest(given.encode("utf-8", "replace"), token.encode()):
        return 403, ("refused: this page is out of date (iloci serve was started again since "
                     "it was loaded) or the request does not come from it. Reload the page; "
                     "the memory is safe. (A script sends the token of the page's <meta "
                     f"name=\"iloci-token\"> in the {TOKEN_HEADER} header.)")
    ctype = headers.get("content-type", "").split(";")[0].strip().lower()
    want = "application/json" if body == "json" else "application/octet-stream"
    if ctype != want:
        return 415, f"refused: the body must be sent as {want}, got {ctype or 'no Content-Type'}."
    return None


class HostGuard:
    """ASGI wrapper: the Host check (DNS rebinding) and :data:`SAFETY_HEADERS` on every response.

    Parameters
    ----------
    inner : ASGI application
    hosts : iterable of str
        Host names accepted besides :data:`LOCAL_HOSTS`; ``"*"`` accepts any.
    """

    def __init__(self, inner: Any, hosts: Any = ()) -> None:
        self.inner = inner
        self.state = inner.state
        names = [h.strip() for h in hosts if h and h.strip()]
        self.any_host = "*" in names
        self.allowed = set(LOCAL_HOSTS) | {host_name(h) for h in names if h != "*"}
        self.allowed.discard("")

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.inner(scope, receive, send)
            return
        host = dict(scope.get("headers") or []).get(b"host", b"").decode("latin-1")
        if scope["type"] == "websocket":
            # the page uses none; a socket to it under another name is closed unanswered
            if not self.any_host and host_name(host) not in self.allowed:
                await send({"type": "websocket.close", "code": 1008})
                return
            await self.inner(scope, receive, send)
            return
        if not self.any_host and host_name(host) not in self.allowed:
            body = json.dumps({"error": (
                f"refused: the Host {host[:80]!r} is not an address this server "
                "listens on. Open it as http://127.0.0.1:PORT/, or start iloci serve "
                "with --allow-host NAME to allow that name.")}).encode()
            await send({"type": "http.response.start", "status": 403,
                        "headers": [(b"content-type", b"application/json"),
                                    (b"content-length", str(len(body)).encode()),
                                    *SAFETY_HEADERS]})
            await send({"type": "http.response.body", "body": body})
            return

        async def send_with_headers(message: Any) -> None:
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []), *SAFETY_HEADERS]}
            await send(message)
        await self.inner(scope, receive, send_with_headers)
