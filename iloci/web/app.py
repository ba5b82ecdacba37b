"""The web app of ``iloci serve``: teach the robot in a browser.

One page (``static/index.html``, plain JavaScript, nothing fetched from
the internet) and a small JSON API on Starlette. The page draws with
Pointer Events and sends each stroke as ``[x, y, t]`` points (x right, y up,
any unit; t in seconds); the app runs the step-wise learning phase
(:meth:`iloci.Agent.observe`, :meth:`iloci.concepts.learner.Turn.feedback`)
with the network in a worker process, and saves the memory file atomically
after every change.

API (JSON in and out; an error is ``{"error": message}`` with a 4xx status
and leaves the memory untouched; a failed save is a 507 whose memory is
what the file still holds; a body holding a field its endpoint does not
take, :data:`BODY_FIELDS`, is refused with 400 naming it; every body may
carry the tab's ``"client"`` id and, for the memory's controls, the
``"version"`` of the memory the page shows, refused with 409 when another
tab changed it since):

``GET /api/state?client=ID``
    The memory (concepts, entries with thumbnails), the client's pending
    guess with the drawing it answers (``points``), the rehearsal in
    progress, whether a drawing or an answer of this client is being
    handled now (``working``: a tab reloaded meanwhile waits for it),
    whether the last save failed (``save_error``), whether a step can be
    undone.
``POST /api/observe`` ``{"points": [[x, y, t], ...], "client": ID}``
    A demonstration: the robot's guess (``answer``), or, with an empty
    memory, the ``outcome`` (a new concept). The client's own guess still
    pending is dropped (nothing learned from it); other clients' guesses
    are kept (each tab has its own turn).
``POST /api/feedback`` ``{"turn": id, "answer": id, "value": 1 | -1 | "new"}``
    Judge the pending guess, named by its turn and its answer's ``id``
    (every answer carries one): the next ``answer`` or the ``outcome``. A
    feedback naming an answer that is no longer pending (a double click, a
    late request) is refused with 409 and changes nothing.
    ``"new"``: none of the robot's concepts, something new (every guess
    left is refused at once). When the memory changed since the guess was
    made (another tab taught, an undo), the drawing is looked at again and
    the new guess comes back with a ``notice``.
``POST /api/recognize`` ``{"points": [...]}``
    Concept and confidence, or ``unknown``, and the robot's drawing of the
    concept (``drawing``); nothing learned.
``POST /api/rename`` ``{"concept": "c3", "name": "circle"}``
``POST /api/undo`` ``{}``
    The memory and the network exactly as before the last change.
``POST /api/forget`` ``{"concept": "c3"}`` or ``{"entry": 4}``
    Forget a concept (every entry) or one entry.
``POST /api/reset`` ``{}``
    Start over: an empty memory (undo brings it back).
``GET /api/export``
    The memory file (download).
``POST /api/import`` (body: a memory file, ``application/octet-stream``)
    Replace the memory with an uploaded one, checked as :meth:`Agent.load
    <iloci.agent.Agent.load>` checks a file (never unpickled).
``GET /api/progress``
    The rehearsal running, if any: phase, fraction of phases, seconds.
``GET /api/arm.png?turn=id&attempt=n``
    With a simulator configured: the simulated arm after drawing the guess.

Safe by default (as Jupyter's server): ``iloci serve`` binds to 127.0.0.1;
every request whose ``Host`` is not an address the server listens on (or
one allowed with ``--allow-host``) is refused (403: DNS rebinding); every
request that changes something needs the server's token (a new one each
start, given to the page, sent as the ``X-Iloci-Token`` header), a JSON
``Content-Type`` (a file for ``/api/import``) and no foreign ``Origin`` or
``Sec-Fetch-Site``; the API answers no cross-origin reads (no CORS
headers, ``Cross-Origin-Resource-Policy: same-origin``) and the page
cannot be framed. A body over :data:`MAX_BODY` bytes is refused (413), one
not received within :data:`BODY_SECONDS` too (408), a stroke over
:data:`MAX_POINTS` points or malformed (422); the client never names a
file.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
import contextlib
from pathlib import Path
import secrets
from typing import Any

from iloci.errors import IlociError
from iloci.web.classroom import Classroom
from iloci.web.schemas import (MAX_BODY, MAX_MEMORY_BYTES, MAX_POINTS, HTTPError, client_id,
                               known_fields, plain_words, read_body, read_json,
                               status_of)
from iloci.web.security import LOCAL_HOSTS, TOKEN_HEADER, HostGuard, foreign, write_refusal

#: The fields each JSON action's body may hold (``POST /api/<name>``); any other is refused
#: (400), so a misspelt field is not read as a missing one.
BODY_FIELDS: dict[str, tuple[str, ...]] = {
    "observe": ("points", "client"),
    "feedback": ("turn", "answer", "value", "client"),
    "recognize": ("points", "client"),
    "rename": ("concept", "name", "version", "client"),
    "undo": ("version", "client"),
    "forget": ("concept", "entry", "version", "client"),
    "reset": ("version", "client"),
}

__all__ = ["BODY_FIELDS", "Classroom", "create_app", "plain_words", "MAX_BODY", "MAX_POINTS",
           "MAX_MEMORY_BYTES", "STATIC", "TOKEN_HEADER", "LOCAL_HOSTS"]

STATIC = Path(__file__).parent / "static"


def create_app(classroom: Classroom, *, token: str | None = None,
               hosts: Any = (), on_shutdown: Any = None) -> Any:
    """The Starlette application serving ``classroom``.

    Parameters
    ----------
    classroom : Classroom
    token : str, optional
        Required (header :data:`TOKEN_HEADER`) on every request that changes
        something; default: a new random one (``secrets.token_urlsafe(32)``),
        also kept as ``app.state.token``. The page gets it in its HTML.
    hosts : iterable of str
        Host names accepted besides :data:`LOCAL_HOSTS` (the address the
        server listens on, ``--allow-host``); ``"*"`` accepts any (no DNS
        rebinding protection).
    on_shutdown : callable, optional
        Called when the server stops (e.g. to stop the agent's worker).
    """
    # the serve extra: imported when a server is made
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import HTMLResponse, JSONResponse, Response
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    token = token or secrets.token_urlsafe(32)
    page = (STATIC / "index.html").read_text(encoding="utf-8").replace(
        "__ILOCI_TOKEN__", token)

    def refuse(status: int, message: str) -> Any:
        return JSONResponse({"error": message}, status_code=status)

    def guarded(handler: Any, write: bool = True, body: str = "json") -> Any:
        async def endpoint(request: Request) -> Any:
            why = foreign(request.headers, request.url.scheme)
            if why is not None:
                return refuse(403, f"refused {why}: only the iloci page itself may use "
                                   "this server.")
            if write:
                refusal = write_refusal(request.headers, token, body)
                if refusal is not None:
                    return refuse(*refusal)
            try:
                return await handler(request)
            except HTTPError as exc:
                out = {"error": str(exc), **exc.extra}
                if exc.status == 507:
                    out["memory"] = await asyncio.to_thread(classroom.memory_json)
                return JSONResponse(out, status_code=exc.status)
            except IlociError as exc:
                return refuse(status_of(exc), plain_words(str(exc)))
        return endpoint

    async def index(request: Request) -> Any:
        return HTMLResponse(page, headers={"Cache-Control": "no-store"})

    async def state(request: Request) -> Any:
        client = request.query_params.get("client", "")
        return JSONResponse(await asyncio.to_thread(
            classroom.state_json, client_id({"client": client})))

    async def progress(request: Request) -> Any:
        return JSONResponse({"progress": classroom.progress})

    def action(method: Any, fields: tuple[str, ...]) -> Any:
        """The endpoint of a JSON action: its body, checked to hold only ``fields``."""
        async def run(request: Request) -> Any:
            body = await read_json(request)
            known_fields(body, fields, request.url.path)
            return JSONResponse(await method(body))
        return run

    async def import_(request: Request) -> Any:
        data = await read_body(request, MAX_MEMORY_BYTES)
        return JSONResponse(await classroom.import_memory(data))

    async def export(request: Request) -> Any:
        data = await asyncio.to_thread(classroom.export_bytes)
        name = classroom.memory_path.name.replace('"', "")
        return Response(data, media_type="application/octet-stream",
                        headers={"Content-Disposition": f'attachment; filename="{name}"'})

    async def arm(request: Request) -> Any:
        data = await classroom.arm_png(request.query_params.get("turn"),
                                       request.query_params.get("attempt"))
        return Response(data, media_type="image/png")

    @contextlib.asynccontextmanager
    async def lifespan(app: Any) -> AsyncIterator[None]:
        yield
        if on_shutdown is not None:
            on_shutdown()

    routes = [
        Route("/", index),
        Route("/api/state", guarded(state, write=False)),
        Route("/api/progress", guarded(progress, write=False)),
        Route("/api/export", guarded(export, write=False)),
        Route("/api/arm.png", guarded(arm, write=False)),
        *[Route(f"/api/{name}", guarded(action(getattr(classroom, name), fields)),
                methods=["POST"]) for name, fields in BODY_FIELDS.items()],
        Route("/api/import", guarded(import_, body="file"), methods=["POST"]),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    async def not_here(request: Request, exc: Exception) -> Any:
        # the API's errors are JSON with a message, these too (not Starlette's plain text)
        status = getattr(exc, "status_code", 404)
        if status == 405:
            allowed = getattr(exc, "headers", None) or {}
            return JSONResponse({"error": f"{request.url.path} does not take {request.method} "
                                          f"(it takes {allowed.get('Allow', 'GET')})."},
                                status_code=405, headers=dict(allowed))
        return JSONResponse({"error": f"there is nothing at {request.url.path[:80]}; the page "
                                      "is at /."}, status_code=status)

    inner = Starlette(routes=routes, lifespan=lifespan,
                      exception_handlers={404: not_here, 405: not_here})
    inner.state.token = token
    return HostGuard(inner, hosts)
