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
what the file still holds):

``GET /api/state?client=ID``
    The memory (concepts, entries with thumbnails), the client's pending
    guess with the drawing it answers (``points``), the rehearsal in
    progress, whether the last save failed (``save_error``), whether a
    step can be undone.
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
import contextlib
import hmac
import json
import logging
import math
import os
from pathlib import Path
import secrets
import tempfile
import threading
import time
from typing import Any

import numpy as np

from iloci.errors import (FeedbackError, IlociError, InvalidDemonstrationError,
                          InvalidInputError, NotFittedError, StaleAnswerError)
from iloci.progress import MemoryLockedError

__all__ = ["Classroom", "create_app", "plain_words", "MAX_BODY", "MAX_POINTS",
           "MAX_MEMORY_BYTES", "STATIC", "TOKEN_HEADER", "LOCAL_HOSTS"]

log = logging.getLogger("iloci.serve")

#: Largest request body accepted (bytes).
MAX_BODY = 512 * 1024
#: Largest memory file accepted by ``/api/import`` (bytes).
MAX_MEMORY_BYTES = 64 * 1024 * 1024
#: A request body must arrive within this many seconds (a stalled upload is a 408).
BODY_SECONDS = 15.0
#: Most points in one stroke.
MAX_POINTS = 5000
#: Fewest points in one stroke (the default ``[sensorimotor] min_points``).
MIN_POINTS = 5
#: Largest absolute coordinate or time accepted.
MAX_VALUE = 1e7
#: Undo steps kept (each a copy of the memory and the network).
UNDO_STEPS = 20
#: Pending turns kept (one per tab or client; the oldest is dropped beyond).
MAX_TURNS = 32
#: The header carrying the server's token on every write.
TOKEN_HEADER = "X-Iloci-Token"
#: Host names always accepted (this computer).
LOCAL_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})
STATIC = Path(__file__).parent / "static"


class HTTPError(Exception):
    """An error answered as ``{"error": message}`` with ``status``."""

    def __init__(self, status: int, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.extra = extra


def _status_of(exc: IlociError) -> int:
    if isinstance(exc, (NotFittedError, StaleAnswerError)):
        return 409
    if isinstance(exc, MemoryLockedError):
        return 423
    if isinstance(exc, (InvalidInputError, FeedbackError)):
        return 422
    return 500


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _in_range(v: float) -> bool:
    # an int of 400 digits is a JSON number too: compare before converting to float
    if isinstance(v, int):
        return abs(v) <= MAX_VALUE
    return math.isfinite(v) and abs(v) <= MAX_VALUE


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
        if not isinstance(p, list) or len(p) != 3 or not all(_is_number(v) for v in p):
            raise HTTPError(400, f"point {i} must be [x, y, t] with three numbers, got "
                                 f"{json.dumps(p)[:60]}.")
        if not all(_in_range(v) for v in p):
            raise HTTPError(422, f"point {i} has a value that is not finite or exceeds "
                                 f"{MAX_VALUE:g}.")
    a = np.asarray(pts, dtype=np.float64)
    if np.any(np.diff(a[:, 2]) <= 0):
        i = int(np.argmax(np.diff(a[:, 2]) <= 0)) + 1
        raise HTTPError(422, f"the times must increase from point to point (point {i} does "
                             "not); send t in seconds.")
    return a[:, :2], a[:, 2]


def _client(body: Any) -> str:
    """The tab's id (``"client"``: up to 64 letters, digits, ``-`` or ``_``; default ``""``)."""
    c = body.get("client", "") if isinstance(body, dict) else ""
    if not isinstance(c, str) or len(c) > 64 or not all(ch.isalnum() or ch in "-_" for ch in c):
        raise HTTPError(400, '"client" must be a short id (letters, digits, "-", "_").')
    return c


def _number(value: float, digits: int = 4) -> float | None:
    """``value`` rounded, or None where it is not a finite number (JSON has no NaN)."""
    value = float(value)
    return round(value, digits) if math.isfinite(value) else None


def _polyline(points: np.ndarray) -> list[list[float]]:
    return [[round(float(x), 4), round(float(y), 4)] for x, y in np.asarray(points)]


def plain_words(message: str) -> str:
    """An error of the library in a person's words, for the page.

    The library's messages name settings (``[sensorimotor] min_points``)
    and demonstration keys; the page says what to do with the pen.
    """
    low = message.lower()
    if "samples once the pen" in low or "min_points" in low or "too few" in low:
        return ("The stroke is too short: draw a longer shape in one stroke "
                "(press, draw, lift).")
    if "zero extent" in low or "degenerate" in low or "all points" in low:
        return "The stroke does not move: draw a shape, not a dot."
    if "unreachable" in low or "cannot reach" in low:
        return "The robot's arm cannot draw that: draw it smaller or nearer the middle."
    return message


class _Snapshot:
    """The memory and the network at one moment: restored exactly by :meth:`restore`."""

    def __init__(self, agent: Any, what: str) -> None:
        arrays, meta = agent.memory.to_arrays()
        self.arrays = {k: np.array(v, copy=True) for k, v in arrays.items()}
        self.meta = json.loads(json.dumps(meta))
        self.encoder = agent.memory.encoder
        self.net = {k: np.array(v, copy=True)
                    for k, v in agent.perceptual_model.state().items()}
        self.what = what

    def restore(self, agent: Any) -> None:
        from iloci.concepts.memory import Memory
        with agent._lock:
            memory = Memory.from_arrays(self.arrays, self.meta)
            memory.encoder = self.encoder if self.encoder is not None else memory.encoder
            memory.revision = agent.memory.revision + 1
            if self.net:
                agent.perceptual_model.load_state(self.net)
            agent.memory = memory


class _Turn:
    """One client's pending turn: the learner's Turn, the drawing it answers."""

    def __init__(self, turn: Any, demo: Any, points: list, client: str, memory: Any) -> None:
        self.turn = turn
        self.demo = demo
        self.points = points
        self.client = client
        self.memory = memory
        self.revision = memory.revision
        self.pending: list = []      # its observer events (the learner's are per turn)


def _save_failure(path: Path, exc: OSError) -> str:
    from iloci.progress import why_not_saved
    return (f"{why_not_saved(path, exc)} The file still holds the memory shown here, from "
            "before this step; this step was not learned. Free some space or fix the "
            "permissions, then do it again.")


class Classroom:
    """The server's state: one agent, its memory file, each client's pending guess.

    Parameters
    ----------
    agent : Agent
        Its network should run in a worker (``agent.start_worker()``) so
        the server answers while a rehearsal trains.
    memory_path : path-like
        Saved atomically after every change (a symlink is written through
        to its target). The caller should hold its lock
        (:func:`iloci.progress.memory_lock`) while serving.

    One person teaches at a time: each learning step holds an asyncio
    lock; state and progress are answered meanwhile. Each client (a tab)
    has its own pending guess.
    """

    def __init__(self, agent: Any, memory_path: str | os.PathLike[str]) -> None:
        self.agent = agent
        self.memory_path = Path(memory_path)
        self.turns: dict[int, _Turn] = {}
        self.turn_id = 0
        self.lock = asyncio.Lock()
        self.progress: dict[str, Any] | None = None
        self.save_error: str | None = None
        self._thumbs: tuple[Any, int, int, list] | None = None
        self._thumb_lock = threading.Lock()
        self._undo: list[_Snapshot] = []
        self._saved = _Snapshot(agent, "start")    # what the file holds (or will)
        self.close_lock: Any = None                # released by close()
        agent.on_progress = self._on_progress

    @property
    def turn(self) -> Any:
        """The newest pending learner Turn (any client), or None."""
        if not self.turns:
            return None
        return self.turns[max(self.turns)].turn

    def close(self) -> None:
        """Stop the agent's worker and release the memory's lock."""
        try:
            self.agent.close()
        finally:
            if self.close_lock is not None:
                self.close_lock()
                self.close_lock = None

    # -- helpers -------------------------------------------------------------------
    def _on_progress(self, p: Any) -> None:  # called in the rehearsing thread
        self.progress = {"reason": p.reason, "phase": p.phase, "fraction": p.fraction,
                         "elapsed": round(p.elapsed, 3), "patterns": p.patterns,
                         "epochs": p.epochs, "since": time.time()}

    def _commit(self, what: str) -> None:
        """Save the change just made; on failure put memory and network back as the file holds them.

        Raises HTTPError 507 (the memory then is the file's) when the save fails.
        """
        try:
            self.agent.save(self.memory_path)
        except OSError as exc:
            self._saved.restore(self.agent)
            self.save_error = _save_failure(self.memory_path, exc)
            log.warning("%s", self.save_error)
            raise HTTPError(507, self.save_error, saved=False) from None
        except MemoryLockedError as exc:
            self._saved.restore(self.agent)
            self.save_error = str(exc)
            raise HTTPError(423, self.save_error, saved=False) from None
        self.save_error = None
        self._undo.append(self._saved)
        del self._undo[:-UNDO_STEPS]
        self._saved = _Snapshot(self.agent, what)

    async def _commit_async(self, what: str) -> None:
        await asyncio.to_thread(self._commit, what)

    def _demo(self, positions: np.ndarray, times: np.ndarray) -> Any:
        from iloci.interfaces import Demonstration
        index = self.agent.memory.demonstrations_seen
        try:
            return Demonstration(positions, times=times, shape="drawing", index=index)
        except InvalidDemonstrationError as exc:
            raise HTTPError(422, plain_words(str(exc))) from None

    def _drop_client(self, client: str) -> None:
        for k in [k for k, t in self.turns.items() if t.client == client]:
            del self.turns[k]

    def answer_json(self, answer: Any, turn_id: int | None = None) -> dict[str, Any]:
        r = answer.response
        tid = self.turn_id if turn_id is None else turn_id
        confidence = _number(answer.confidence)
        rec = self.turns.get(tid)
        # the last guess left: the robot is not "sure", it has nothing else
        # to offer; its confidence margin says nothing then (issue 26)
        last = False
        if rec is not None and not r.novel:
            concepts = set(self.agent.memory.concepts())
            last = len(concepts - set(rec.turn.tried) - {answer.concept}) == 0
        out = {"id": answer.id, "turn": tid, "concept": answer.concept, "novel": bool(r.novel),
               "confidence": None if last else confidence, "last_guess": last,
               "attempt": answer.attempt,
               "drawing": _polyline(answer.drawing), "dt": answer.dt,
               "joint_path": [[round(float(v), 5) for v in row] for row in answer.joint_path],
               "start_posture": [float(v) for v in answer.start_posture],
               "executed": r.execution is not None, "arm": None}
        if r.execution is not None and self.agent.simulator is not None:
            out["arm"] = f"/api/arm.png?turn={tid}&attempt={answer.attempt}"
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
                "file": self.memory_path.name, "save_error": self.save_error,
                "undo": self._undo[-1].what if self._undo else None}

    def _thumbnails(self, entries: list) -> list:
        """Each entry regenerated by the network, in the drawing plane; cached per revision."""
        mem = self.agent.memory
        key = (id(mem), mem.revision, len(entries))
        with self._thumb_lock:
            if self._thumbs is not None and self._thumbs[:3] == key:
                return self._thumbs[3]
            out: list = [_polyline(p) for p in self.agent.entry_drawings(entries)]
            self._thumbs = (*key, out)
            return out

    def state_json(self, client: str = "") -> dict[str, Any]:
        pending = None
        for tid in sorted(self.turns, reverse=True):
            rec = self.turns[tid]
            if rec.client == client and rec.turn.answer is not None:
                pending = {**self.answer_json(rec.turn.answer, tid), "points": rec.points}
                break
        return {"memory": self.memory_json(), "pending": pending,
                "progress": self.progress, "simulator": self.agent.simulator is not None}

    def _outcome(self, outcome: Any, what: str) -> dict[str, Any]:
        self._commit(what)
        self.progress = None
        return {"outcome": self.outcome_json(outcome), "memory": self.memory_json()}

    # -- actions (each under the lock) ------------------------------------------------
    async def _observe(self, demo: Any, points: list, client: str) -> dict[str, Any]:
        self._drop_client(client)                # this tab's pending guess is dropped
        turn = await self.agent.aobserve(demo)
        self.turn_id += 1
        tid = self.turn_id
        if turn.done:
            try:
                return await asyncio.to_thread(self._outcome, turn.outcome,
                                               f"drawing {demo.key}")
            finally:
                self.progress = None
        self.turns[tid] = _Turn(turn, demo, points, client, self.agent.memory)
        self.turns[tid].pending = list(turn.learner._pending)
        while len(self.turns) > MAX_TURNS:
            del self.turns[min(self.turns)]
        return {"answer": self.answer_json(turn.answer, tid)}

    async def observe(self, body: Any) -> dict[str, Any]:
        positions, times = parse_points(body)
        client = _client(body)
        async with self.lock:
            demo = self._demo(positions, times)
            return await self._observe(demo, body["points"], client)

    async def feedback(self, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict) or "value" not in body or "turn" not in body \
                or not isinstance(body.get("answer"), str):
            raise HTTPError(400, 'expected {"turn": id, "answer": "<the answer\'s id>", '
                                 '"value": 1, -1 or "new"}.')
        value, turn_id, answer_id = body["value"], body["turn"], body["answer"]
        if value != "new" and (isinstance(value, bool) or value not in (1, -1)):
            raise HTTPError(422, 'value must be 1 (yes), -1 (no) or "new" (something new), '
                                 f"got {json.dumps(value)[:40]}.")
        if isinstance(turn_id, bool) or not isinstance(turn_id, int):
            raise HTTPError(400, f'"turn" must be the id of a guess, got '
                                 f"{json.dumps(turn_id)[:40]}.")
        async with self.lock:
            rec = self.turns.get(turn_id)
            if rec is None or rec.turn.answer is None:
                raise HTTPError(409, "no such guess is waiting for an answer (it was answered, "
                                     "or this tab drew something newer); draw again.")
            if rec.memory is not self.agent.memory or rec.revision != self.agent.memory.revision:
                # another tab taught, or an undo / rename: look at the drawing again
                del self.turns[turn_id]
                out = await self._observe(rec.demo, rec.points, rec.client)
                out["notice"] = ("The memory changed since this guess (another tab taught, or "
                                 "a concept was renamed or forgotten): the robot looked at your "
                                 "drawing again.")
                if "answer" in out:
                    out["answer"]["notice"] = out["notice"]
                return out
            turn = rec.turn
            learner = turn.learner
            learner._pending = rec.pending        # this turn's observer events only

            def step() -> Any:
                # the feedback judges the answer it names (issue 30): a double
                # click or a late request for an answer since replaced is refused
                if value != "new":
                    return turn.feedback(int(value), answer_id)
                # something new: every guess left refused, the novelty answer taken
                out, named = None, answer_id
                while turn.answer is not None:
                    novel = bool(turn.answer.response.novel)
                    out = turn.feedback(1 if novel else -1, named)
                    named = turn.answer.id if turn.answer is not None else named
                return out

            try:
                result = await asyncio.to_thread(step)
            finally:
                rec.pending = learner._pending
            if turn.done:
                del self.turns[turn_id]
                try:
                    return await asyncio.to_thread(self._outcome, turn.outcome,
                                                   f"drawing {rec.demo.key}")
                finally:
                    self.progress = None
            return {"answer": self.answer_json(result, turn_id)}

    async def recognize(self, body: Any) -> dict[str, Any]:
        positions, times = parse_points(body)
        async with self.lock:
            demo = self._demo(positions, times)
            r = await asyncio.to_thread(self.agent.recognize, demo)
            drawing: list = []
            if not r.unknown and r.concept is not None:
                with contextlib.suppress(IlociError, ValueError, IndexError):
                    drawing = await asyncio.to_thread(self._drawing_of, r, demo)
        return {"concept": r.concept, "confidence": _number(r.confidence),
                "distance": _number(r.distance), "entry": r.entry, "tilt": r.tilt,
                "unknown": bool(r.unknown), "familiarity": _number(r.familiarity),
                "drawing": drawing}

    def _drawing_of(self, recognition: Any, demo: Any) -> list:
        """The robot's drawing of the recognized entry, in the frame of the person's stroke."""
        from iloci.concepts.learner import ik_joint_limits, perform
        from iloci.sensorimotor.frames import TeacherFrame
        agent = self.agent
        motion = agent.motion(demo)
        frame = TeacherFrame.of(demo, motion.plane_points)
        index = recognition.entry if isinstance(recognition.entry, int) \
            else agent.memory.performer_of(recognition.concept)
        with agent._lock:
            response = perform(agent.memory, agent.perceptual_model, index,
                               joint_limits=ik_joint_limits(agent.ik_solver), frame=frame)
        if response.teacher_drawing is None:
            return []
        return _polyline(response.teacher_drawing)

    async def rename(self, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict) or not isinstance(body.get("concept"), str) \
                or not isinstance(body.get("name"), str):
            raise HTTPError(400, 'expected {"concept": "c3", "name": "circle"} (strings).')
        async with self.lock:
            if body["concept"] not in self.agent.memory.concepts():
                raise HTTPError(404, f"the memory holds no concept {body['concept']!r}.")
            self.agent.rename(body["concept"], body["name"])
            await self._commit_async(f"rename {body['concept']}")
            return {"memory": await asyncio.to_thread(self.memory_json)}

    async def undo(self, body: Any) -> dict[str, Any]:
        async with self.lock:
            if not self._undo:
                raise HTTPError(409, "there is nothing to undo.")
            snap = self._undo.pop()
            current = self._saved

            def run() -> None:
                snap.restore(self.agent)
                try:
                    self.agent.save(self.memory_path)
                except (OSError, MemoryLockedError) as exc:
                    current.restore(self.agent)
                    self._undo.append(snap)
                    self.save_error = (_save_failure(self.memory_path, exc)
                                       if isinstance(exc, OSError) else str(exc))
                    raise HTTPError(507, self.save_error, saved=False) from None
                self.save_error = None
                self._saved = snap
            await asyncio.to_thread(run)
            self.turns.clear()
            return {"undone": current.what, "memory": await asyncio.to_thread(self.memory_json)}

    async def forget(self, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict) or not (isinstance(body.get("concept"), str) or (
                isinstance(body.get("entry"), int) and not isinstance(body["entry"], bool))):
            raise HTTPError(400, 'expected {"concept": "c3"} or {"entry": 4}.')
        async with self.lock:
            mem = self.agent.memory
            if "concept" in body and isinstance(body["concept"], str):
                keep = [e for e in mem.entries if e.concept != body["concept"]]
                if len(keep) == len(mem.entries):
                    raise HTTPError(404, f"the memory holds no concept {body['concept']!r}.")
                what = f"forget {body['concept']}"
            else:
                i = body["entry"]
                if not 0 <= i < len(mem.entries):
                    raise HTTPError(404, f"the memory has no entry {i} (it has "
                                         f"{len(mem.entries)}).")
                keep = [e for j, e in enumerate(mem.entries) if j != i]
                what = f"forget entry {i}"
            with self.agent._lock:
                mem.entries = keep           # one assignment: readers see old or new
                mem.revision += 1
            await self._commit_async(what)
            return {"memory": await asyncio.to_thread(self.memory_json)}

    async def reset(self, body: Any) -> dict[str, Any]:
        async with self.lock:
            from iloci.concepts.memory import Memory
            with self.agent._lock:
                old = self.agent.memory
                self.agent.memory = Memory(revision=old.revision + 1)
            await self._commit_async("start over")
            self.turns.clear()
            return {"memory": await asyncio.to_thread(self.memory_json)}

    async def import_memory(self, data: bytes) -> dict[str, Any]:
        """Replace memory and network with those of an uploaded memory file."""
        from iloci.agent import Agent
        from iloci.concepts.memory import load_memory
        if not data:
            raise HTTPError(400, "the upload is empty; choose a memory file (.npz).")
        async with self.lock:
            def load() -> Any:
                with tempfile.TemporaryDirectory() as d:
                    tmp = Path(d) / "upload.npz"
                    tmp.write_bytes(data)
                    memory, net, header = load_memory(tmp)   # MemoryFileError if not ours
                    # checked as Agent.load checks it: the network must fit this
                    # server's model, the entries its settings, the robot its arm
                    Agent.load(tmp, self.agent.config)
                    return memory, net
            try:
                memory, net = await asyncio.to_thread(load)
            except IlociError as exc:
                raise HTTPError(422, f"not imported: {exc}") from None
            with self.agent._lock:
                memory.revision = self.agent.memory.revision + 1
                if net:
                    self.agent.perceptual_model.load_state(net)
                self.agent.memory = memory
            await self._commit_async("import")
            self.turns.clear()
            return {"memory": await asyncio.to_thread(self.memory_json)}

    def export_bytes(self) -> bytes:
        """The memory file as saved (what the page shows)."""
        path = self.memory_path
        if not path.exists():
            raise HTTPError(404, "nothing is saved yet: teach a first drawing.")
        return path.read_bytes()

    async def arm_png(self, turn_id: str | None, attempt: str | None) -> bytes:
        sim = self.agent.simulator
        if sim is None:
            raise HTTPError(404, "no simulator is configured ([simulator] name in the config).")
        rec = self.turns.get(int(turn_id)) if turn_id and turn_id.isdigit() \
            and len(turn_id) < 12 else None
        if rec is None or rec.turn.answer is None or str(rec.turn.answer.attempt) != attempt:
            raise HTTPError(404, "no such guess is pending.")
        execution = rec.turn.answer.response.execution

        def render() -> bytes:
            import io

            from PIL import Image
            buf = io.BytesIO()
            image = np.ascontiguousarray(sim.render(execution, 360, 270), dtype=np.uint8)
            Image.fromarray(image).save(buf, format="PNG")
            return buf.getvalue()
        return await asyncio.to_thread(render)


async def _read_body(request: Any, limit: int) -> bytes:
    length = request.headers.get("content-length")
    if length is not None and not (length.isdigit() and len(length) < 16):
        raise HTTPError(400, "the Content-Length header is not a number.")
    if length is not None and int(length) > limit:
        raise HTTPError(413, f"request body over {limit} bytes.")
    from starlette.requests import ClientDisconnect

    async def read() -> bytes:
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > limit:
                raise HTTPError(413, f"request body over {limit} bytes.")
            chunks.append(chunk)
        return b"".join(chunks)
    try:
        return await asyncio.wait_for(read(), BODY_SECONDS)
    except TimeoutError:
        raise HTTPError(408, f"the request body did not arrive within {BODY_SECONDS:g} s.") \
            from None
    except ClientDisconnect:
        raise HTTPError(400, "the client went away before sending its request body.") \
            from None


async def _read_json(request: Any) -> Any:
    raw = await _read_body(request, MAX_BODY)
    try:
        return json.loads(raw or b"null")
    except RecursionError:
        raise HTTPError(400, "the JSON is nested too deeply.") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise HTTPError(400, f"the body is not JSON ({str(exc)[:120]}).") from None


def _host_name(host: str) -> str:
    """``"127.0.0.1:8000"`` -> ``"127.0.0.1"``, ``"[::1]:8000"`` -> ``"::1"`` (lower case)."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host
    if host.count(":") == 1:
        return host.split(":", 1)[0]
    return host


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
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import HTMLResponse, JSONResponse, Response
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    token = token or secrets.token_urlsafe(32)
    allowed = set(LOCAL_HOSTS) | {_host_name(h) for h in hosts if h}
    any_host = "*" in allowed
    page = (STATIC / "index.html").read_text(encoding="utf-8").replace(
        "__ILOCI_TOKEN__", token)

    def refuse(status: int, message: str) -> Any:
        return JSONResponse({"error": message}, status_code=status)

    def foreign(request: Request) -> str | None:
        """Why the request comes from another site, or None."""
        site = request.headers.get("sec-fetch-site")
        if site is not None and site not in ("same-origin", "none"):
            return f"a request from another site (Sec-Fetch-Site: {site[:20]})"
        origin = request.headers.get("origin")
        if origin is not None:
            host = request.headers.get("host", "")
            if origin.lower() not in (f"http://{host}".lower(), f"https://{host}".lower()):
                return f"a request from another page (Origin {origin[:80]})"
        return None

    def guarded(handler: Any, write: bool = True, body: str = "json") -> Any:
        async def endpoint(request: Request) -> Any:
            why = foreign(request)
            if why is not None:
                return refuse(403, f"refused {why}: only the iloci page itself may use "
                                   "this server.")
            if write:
                given = request.headers.get(TOKEN_HEADER.lower(), "")
                if not hmac.compare_digest(given.encode(), token.encode()):
                    return refuse(403, f"refused: a write needs the server's token in the "
                                       f"{TOKEN_HEADER} header (the page has it; reload the "
                                       "page after a restart of iloci serve).")
                ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
                want = "application/json" if body == "json" else "application/octet-stream"
                if ctype != want:
                    return refuse(415, f"refused: the body must be sent as {want}, got "
                                       f"{ctype or 'no Content-Type'}.")
            try:
                return await handler(request)
            except HTTPError as exc:
                out = {"error": str(exc), **exc.extra}
                if exc.status == 507:
                    out["memory"] = await asyncio.to_thread(classroom.memory_json)
                return JSONResponse(out, status_code=exc.status)
            except IlociError as exc:
                return refuse(_status_of(exc), plain_words(str(exc)))
        return endpoint

    async def index(request: Request) -> Any:
        return HTMLResponse(page, headers={"Cache-Control": "no-store"})

    async def state(request: Request) -> Any:
        client = request.query_params.get("client", "")
        return JSONResponse(await asyncio.to_thread(
            classroom.state_json, _client({"client": client})))

    async def progress(request: Request) -> Any:
        return JSONResponse({"progress": classroom.progress})

    def action(method: Any) -> Any:
        async def run(request: Request) -> Any:
            return JSONResponse(await method(await _read_json(request)))
        return run

    async def import_(request: Request) -> Any:
        data = await _read_body(request, MAX_MEMORY_BYTES)
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
    async def lifespan(app: Any):
        yield
        if on_shutdown is not None:
            on_shutdown()

    routes = [
        Route("/", index),
        Route("/api/state", guarded(state, write=False)),
        Route("/api/progress", guarded(progress, write=False)),
        Route("/api/export", guarded(export, write=False)),
        Route("/api/arm.png", guarded(arm, write=False)),
        Route("/api/observe", guarded(action(classroom.observe)), methods=["POST"]),
        Route("/api/feedback", guarded(action(classroom.feedback)), methods=["POST"]),
        Route("/api/recognize", guarded(action(classroom.recognize)), methods=["POST"]),
        Route("/api/rename", guarded(action(classroom.rename)), methods=["POST"]),
        Route("/api/undo", guarded(action(classroom.undo)), methods=["POST"]),
        Route("/api/forget", guarded(action(classroom.forget)), methods=["POST"]),
        Route("/api/reset", guarded(action(classroom.reset)), methods=["POST"]),
        Route("/api/import", guarded(import_, body="file"), methods=["POST"]),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    inner = Starlette(routes=routes, lifespan=lifespan)
    inner.state.token = token
    headers = [(b"x-frame-options", b"DENY"),
               (b"content-security-policy",
                b"default-src 'self'; img-src 'self' data: blob:; frame-ancestors 'none'; "
                b"form-action 'none'; base-uri 'none'"),
               (b"cross-origin-resource-policy", b"same-origin"),
               (b"x-content-type-options", b"nosniff"),
               (b"referrer-policy", b"no-referrer")]

    class Guard:
        """Host check (DNS rebinding) and safety headers around every response."""

        state = inner.state

        async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
            await guard(scope, receive, send)

    async def guard(scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] == "http":
            host = dict(scope.get("headers") or []).get(b"host", b"").decode("latin-1")
            if not any_host and _host_name(host) not in allowed:
                body = json.dumps({"error": (
                    f"refused: the Host {host[:80]!r} is not an address this server "
                    "listens on. Open it as http://127.0.0.1:PORT/, or start iloci serve "
                    "with --allow-host NAME to allow that name.")}).encode()
                await send({"type": "http.response.start", "status": 403,
                            "headers": [(b"content-type", b"application/json"),
                                        (b"content-length", str(len(body)).encode()),
                                        *headers]})
                await send({"type": "http.response.body", "body": body})
                return

            async def send_with_headers(message: Any) -> None:
                if message["type"] == "http.response.start":
                    message = {**message, "headers": [*message.get("headers", []), *headers]}
                await send(message)
            await inner(scope, receive, send_with_headers)
            return
        await inner(scope, receive, send)

    return Guard()

