"""The web app of ``iloci serve``: teach the robot in a browser.

One page (``static/index.html``, plain JavaScript, nothing fetched from
the internet) and a small JSON API on Starlette. The page draws with
Pointer Events and sends each stroke as ``[x, y, t]`` points (x right, y up,
any unit; t in seconds); the app runs the step-wise learning phase
(:meth:`iloci.Agent.observe`, :meth:`iloci.concepts.learner.Turn.feedback`)
with the network in a worker process, and saves the memory file atomically
after every change.

API (JSON in and out; an error is ``{"error": message}`` with a 4xx status
and leaves the memory untouched):

``GET /api/state``
    The memory (concepts, entries with thumbnails), the pending guess, the
    rehearsal in progress.
``POST /api/observe`` ``{"points": [[x, y, t], ...]}``
    A demonstration: the robot's guess (``answer``), or, with an empty
    memory, the ``outcome`` (a new concept). A guess still pending is
    dropped (nothing learned from it).
``POST /api/feedback`` ``{"answer": id, "value": 1 | -1}``
    Judge the pending guess, named by its ``id`` (every answer carries
    one): the next ``answer`` or the ``outcome``. A feedback naming an
    answer that is not pending (a double click, a late request, a guess
    replaced by a newer drawing) is refused with 409 and changes nothing.
``POST /api/recognize`` ``{"points": [...]}``
    Concept and confidence; nothing learned.
``POST /api/rename`` ``{"concept": "c3", "name": "circle"}``
``GET /api/progress``
    The rehearsal running, if any: phase, fraction of phases, seconds.
``GET /api/arm.png?answer=id``
    With a simulator configured: the simulated arm after drawing the
    pending guess.

Safe by default: ``iloci serve`` binds to 127.0.0.1; a body over
:data:`MAX_BODY` bytes is refused (413), a stroke over :data:`MAX_POINTS`
points or malformed (422); the client never names a file.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
from pathlib import Path
import threading
import time
from typing import Any

import numpy as np

from iloci.errors import (FeedbackError, IlociError, InvalidDemonstrationError,
                          InvalidInputError, NotFittedError)

__all__ = ["Classroom", "create_app", "MAX_BODY", "MAX_POINTS", "STATIC"]

#: Largest request body accepted (bytes).
MAX_BODY = 512 * 1024
#: Most points in one stroke.
MAX_POINTS = 5000
#: Fewest points in one stroke.
MIN_POINTS = 3
#: Largest absolute coordinate or time accepted.
MAX_VALUE = 1e7
#: Points per thumbnail / answer polyline sent to the page.
STATIC = Path(__file__).parent / "static"


class HTTPError(Exception):
    """An error answered as ``{"error": message}`` with ``status``."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def _status_of(exc: IlociError) -> int:
    if isinstance(exc, NotFittedError):
        return 409
    if isinstance(exc, (InvalidInputError, FeedbackError)):
        return 422
    return 500


def parse_points(body: Any) -> tuple[np.ndarray, np.ndarray]:
    """``{"points": [[x, y, t], ...]}`` -> positions (N, 2), times (N,); HTTPError if bad."""
    if not isinstance(body, dict) or "points" not in body:
        raise HTTPError(400, 'expected a JSON object {"points": [[x, y, t], ...]}.')
    pts = body["points"]
    if not isinstance(pts, list):
        raise HTTPError(400, '"points" must be a list of [x, y, t] triples.')
    if len(pts) > MAX_POINTS:
        raise HTTPError(422, f"the stroke has {len(pts)} points; at most {MAX_POINTS} are "
                             "accepted. Draw a shorter stroke.")
    if len(pts) < MIN_POINTS:
        raise HTTPError(422, f"the stroke has {len(pts)} point(s); draw at least "
                             f"{MIN_POINTS} (one stroke, pen down to pen up).")
    for i, p in enumerate(pts):
        if (not isinstance(p, list) or len(p) != 3
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                           for v in p)):
            raise HTTPError(400, f"point {i} must be [x, y, t] with three numbers, got "
                                 f"{json.dumps(p)[:60]}.")
        if not all(math.isfinite(v) and abs(v) <= MAX_VALUE for v in p):
            raise HTTPError(422, f"point {i} has a value that is not finite or exceeds "
                                 f"{MAX_VALUE:g}.")
    a = np.asarray(pts, dtype=np.float64)
    if np.any(np.diff(a[:, 2]) <= 0):
        i = int(np.argmax(np.diff(a[:, 2]) <= 0)) + 1
        raise HTTPError(422, f"the times must increase from point to point (point {i} does "
                             "not); send t in seconds.")
    return a[:, :2], a[:, 2]


def _number(value: float, digits: int = 4) -> float | None:
    """``value`` rounded, or None where it is not a finite number (JSON has no NaN)."""
    value = float(value)
    return round(value, digits) if math.isfinite(value) else None


def _polyline(points: np.ndarray) -> list[list[float]]:
    return [[round(float(x), 4), round(float(y), 4)] for x, y in np.asarray(points)]


class Classroom:
    """The server's state: one agent, its memory file, the pending guess, the progress.

    Parameters
    ----------
    agent : Agent
        Its network should run in a worker (``agent.start_worker()``) so
        the server answers while a rehearsal trains.
    memory_path : path-like
        Saved atomically after every change.

    One person teaches at a time: each learning step holds an asyncio
    lock; state and progress are answered meanwhile.
    """

    def __init__(self, agent: Any, memory_path: str | os.PathLike[str]) -> None:
        self.agent = agent
        self.memory_path = Path(memory_path)
        self.turn: Any = None
        self.turn_id = 0
        self.lock = asyncio.Lock()
        self.progress: dict[str, Any] | None = None
        self._thumbs: tuple[int, int, list] | None = None
        self._thumb_lock = threading.Lock()
        agent.on_progress = self._on_progress

    # -- helpers -------------------------------------------------------------------
    def _on_progress(self, p: Any) -> None:  # called in the rehearsing thread
        self.progress = {"reason": p.reason, "phase": p.phase, "fraction": p.fraction,
                         "elapsed": round(p.elapsed, 3), "patterns": p.patterns,
                         "epochs": p.epochs, "since": time.time()}

    def _save(self) -> None:
        self.agent.save(self.memory_path)

    def _demo(self, positions: np.ndarray, times: np.ndarray) -> Any:
        from iloci.interfaces import Demonstration
        index = self.agent.memory.demonstrations_seen
        try:
            return Demonstration(positions, times=times, shape="drawing", index=index)
        except InvalidDemonstrationError as exc:
            raise HTTPError(422, str(exc)) from None

    def answer_json(self, answer: Any) -> dict[str, Any]:
        r = answer.response
        # a novelty answer ([learner] novelty_below, novelty_after) names the
        # concept it would found and has no confidence (NaN): null in JSON,
        # which has no NaN
        out = {"id": answer.id, "turn": self.turn_id, "concept": answer.concept,
               "novel": bool(r.novel),
               "confidence": _number(answer.confidence), "attempt": answer.attempt,
               "drawing": _polyline(answer.drawing), "dt": answer.dt,
               "joint_path": [[round(float(v), 5) for v in row] for row in answer.joint_path],
               "start_posture": [float(v) for v in answer.start_posture],
               "executed": r.execution is not None, "arm": None}
        if r.execution is not None and self.agent.simulator is not None:
            out["arm"] = f"/api/arm.png?answer={answer.id}"
        return out

    def outcome_json(self, outcome: Any) -> dict[str, Any]:
        return {"demo": outcome.demo, "concept": outcome.concept, "action": outcome.action,
                "feedbacks": list(outcome.feedbacks), "clustered": outcome.clustered,
                "rehearsal_seconds": round(sum(r.seconds for r in outcome.rehearsals), 3)}

    def memory_json(self) -> dict[str, Any]:
        """Concepts, their entries and a thumbnail (drawing-plane polyline) of each."""
        mem = self.agent.memory
        entries = list(mem.entries)
        thumbs = self._thumbnails(entries)
        concepts = []
        for name in mem.concepts():
            own = [i for i, e in enumerate(entries) if e.concept == name]
            concepts.append({
                "name": name, "num_samples": sum(entries[i].num_samples for i in own),
                "entries": [{"index": i, "prototype": entries[i].prototype,
                             "num_samples": entries[i].num_samples,
                             "sources": list(entries[i].sources),
                             "drawing": thumbs[i] if i < len(thumbs) else []}
                            for i in own]})
        return {"concepts": concepts, "entries": len(entries),
                "demonstrations_seen": mem.demonstrations_seen,
                "file": self.memory_path.name}

    def _thumbnails(self, entries: list) -> list:
        """Each entry regenerated by the network, in the drawing plane; cached per revision."""
        mem = self.agent.memory
        key = (mem.revision, len(entries))
        with self._thumb_lock:
            if self._thumbs is not None and self._thumbs[:2] == key:
                return self._thumbs[2]
            out: list = []
            if entries and mem.encoder is not None:
                from iloci.concepts.rehearsal import regenerate
                seqs = regenerate(self.agent.perceptual_model, entries)
                out = [_polyline(mem.encoder.decode(s, e.start)[0])
                       for s, e in zip(seqs, entries)]
            self._thumbs = (*key, out)
            return out

    def state_json(self) -> dict[str, Any]:
        turn = self.turn
        pending = None
        if turn is not None and turn.answer is not None:
            pending = self.answer_json(turn.answer)
        return {"memory": self.memory_json(), "pending": pending,
                "progress": self.progress, "simulator": self.agent.simulator is not None}

    # -- actions (each under the lock) ------------------------------------------------
    async def observe(self, body: Any) -> dict[str, Any]:
        positions, times = parse_points(body)
        async with self.lock:
            demo = self._demo(positions, times)
            self.turn = None                     # a pending guess is dropped
            turn = await self.agent.aobserve(demo)
            self.turn_id += 1
            self.turn = turn
            if turn.done:
                self.turn = None
                await asyncio.to_thread(self._save)
                self.progress = None
                return {"outcome": self.outcome_json(turn.outcome),
                        "memory": await asyncio.to_thread(self.memory_json)}
            return {"answer": self.answer_json(turn.answer)}

    async def feedback(self, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict) or "value" not in body \
                or not isinstance(body.get("answer"), str):
            raise HTTPError(400, 'expected {"answer": "<the answer\'s id>", "value": 1 or -1}.')
        value, answer_id = body["value"], body["answer"]
        if isinstance(value, bool) or value not in (1, -1):
            raise HTTPError(422, f"value must be 1 (yes) or -1 (no), got {json.dumps(value)}.")
        async with self.lock:
            turn = self.turn
            if turn is None or turn.answer is None or turn.answer.id != answer_id:
                raise HTTPError(409, f"no guess {answer_id!r} is waiting for an answer (it was "
                                     "answered or replaced by a newer drawing); draw again.")
            step = await turn.afeedback(int(value), answer_id)
            if turn.done:
                self.turn = None
                await asyncio.to_thread(self._save)
                self.progress = None
                return {"outcome": self.outcome_json(step),
                        "memory": await asyncio.to_thread(self.memory_json)}
            return {"answer": self.answer_json(step)}

    async def recognize(self, body: Any) -> dict[str, Any]:
        positions, times = parse_points(body)
        async with self.lock:
            demo = self._demo(positions, times)
            r = await asyncio.to_thread(self.agent.recognize, demo)
        return {"concept": r.concept, "confidence": _number(r.confidence),
                "distance": _number(r.distance), "entry": r.entry, "tilt": r.tilt,
                "unknown": bool(r.unknown), "familiarity": _number(r.familiarity)}

    async def rename(self, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict) or not isinstance(body.get("concept"), str) \
                or not isinstance(body.get("name"), str):
            raise HTTPError(400, 'expected {"concept": "c3", "name": "circle"} (strings).')
        async with self.lock:
            if body["concept"] not in self.agent.memory.concepts():
                raise HTTPError(404, f"the memory holds no concept {body['concept']!r}.")
            self.agent.rename(body["concept"], body["name"])
            self.turn = None                     # its guess named the old label
            await asyncio.to_thread(self._save)
            return {"memory": await asyncio.to_thread(self.memory_json)}

    async def arm_png(self, answer_id: str | None) -> bytes:
        turn = self.turn
        sim = self.agent.simulator
        if sim is None:
            raise HTTPError(404, "no simulator is configured ([simulator] name in the config).")
        if turn is None or turn.answer is None or turn.answer.id != answer_id:
            raise HTTPError(404, "no such guess is pending.")
        execution = turn.answer.response.execution

        def render() -> bytes:
            import io

            from PIL import Image
            buf = io.BytesIO()
            image = np.ascontiguousarray(sim.render(execution, 360, 270), dtype=np.uint8)
            Image.fromarray(image).save(buf, format="PNG")
            return buf.getvalue()
        return await asyncio.to_thread(render)


async def _read_json(request: Any) -> Any:
    length = request.headers.get("content-length")
    if length is not None and (not length.isdigit() or int(length) > MAX_BODY):
        raise HTTPError(413, f"request body over {MAX_BODY} bytes.")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY:
            raise HTTPError(413, f"request body over {MAX_BODY} bytes.")
        chunks.append(chunk)
    try:
        return json.loads(b"".join(chunks) or b"null")
    except (ValueError, UnicodeDecodeError) as exc:
        raise HTTPError(400, f"the body is not JSON ({exc}).") from None


def create_app(classroom: Classroom, *, on_shutdown: Any = None) -> Any:
    """The Starlette application serving ``classroom``.

    Parameters
    ----------
    classroom : Classroom
    on_shutdown : callable, optional
        Called when the server stops (e.g. to stop the agent's worker).
    """
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import FileResponse, JSONResponse, Response
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    def guarded(handler: Any) -> Any:
        async def endpoint(request: Request) -> Any:
            try:
                return await handler(request)
            except HTTPError as exc:
                return JSONResponse({"error": str(exc)}, status_code=exc.status)
            except IlociError as exc:
                return JSONResponse({"error": str(exc)}, status_code=_status_of(exc))
        return endpoint

    async def index(request: Request) -> Any:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def state(request: Request) -> Any:
        return JSONResponse(await asyncio.to_thread(classroom.state_json))

    async def progress(request: Request) -> Any:
        return JSONResponse({"progress": classroom.progress})

    async def observe(request: Request) -> Any:
        return JSONResponse(await classroom.observe(await _read_json(request)))

    async def feedback(request: Request) -> Any:
        return JSONResponse(await classroom.feedback(await _read_json(request)))

    async def recognize(request: Request) -> Any:
        return JSONResponse(await classroom.recognize(await _read_json(request)))

    async def rename(request: Request) -> Any:
        return JSONResponse(await classroom.rename(await _read_json(request)))

    async def arm(request: Request) -> Any:
        data = await classroom.arm_png(request.query_params.get("answer"))
        return Response(data, media_type="image/png")

    @contextlib.asynccontextmanager
    async def lifespan(app: Any):
        yield
        if on_shutdown is not None:
            on_shutdown()

    routes = [
        Route("/", index),
        Route("/api/state", guarded(state)),
        Route("/api/progress", guarded(progress)),
        Route("/api/observe", guarded(observe), methods=["POST"]),
        Route("/api/feedback", guarded(feedback), methods=["POST"]),
        Route("/api/recognize", guarded(recognize), methods=["POST"]),
        Route("/api/rename", guarded(rename), methods=["POST"]),
        Route("/api/arm.png", guarded(arm)),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    return Starlette(routes=routes, lifespan=lifespan)
