"""The state of ``iloci serve``: one agent, its memory file, each client's pending turn.

The learning steps of the page (observe, feedback, recognize, rename,
undo, forget, start over, import) as async methods taking the request's
JSON and answering JSON; one step at a time (an asyncio lock), the
network in the agent's worker. The memory and the network are reached
through the :class:`~iloci.agent.Agent`'s public methods only
(:class:`~iloci.agent.controls.MemoryControls` for undo, forget, start over and
import).
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import math
import os
from pathlib import Path
import tempfile
import threading
import time
from typing import Any

import numpy as np

from iloci.errors import IlociError, InvalidDemonstrationError
from iloci.interfaces import Demonstration
from iloci.web.history import History
from iloci.web.schemas import (HTTPError, client_id, number, parse_feedback, parse_points,
                               plain_words, polyline)

__all__ = ["Classroom", "MAX_TURNS"]

#: Pending turns kept (one per tab or client; the oldest is dropped beyond).
MAX_TURNS = 32


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
        self.familiarity: float | None = None     # how like what it was taught (0..1]


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
        # why a turn no longer waits (answered, replaced, let go): its feedback is
        # refused with the reason, not a guess at it (the last 256)
        self.gone: dict[int, str] = {}
        self.lock = asyncio.Lock()
        self.progress: dict[str, Any] | None = None
        #: Drawings and answers being handled, per tab (client id): a tab reloaded while
        #: its request is handled is told to wait for it (its page had shown nothing)
        self.working: dict[str, int] = {}
        self.history = History(agent, self.memory_path)
        self._thumbs: tuple[Any, int, int, list] | None = None
        self._thumb_lock = threading.Lock()
        self.close_lock: Any = None                # released by close()
        self._next_index = 0                       # the next drawing's number (_demo)
        agent.on_progress = self._on_progress

    @property
    def save_error(self) -> str | None:
        """Why the last save failed, or None."""
        return self.history.save_error

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

    async def _commit_async(self, what: str) -> None:
        await asyncio.to_thread(self.history.commit, what)

    def _demo(self, positions: np.ndarray, times: np.ndarray) -> Any:
        # numbered as they arrive: two tabs' drawings waiting at once get two names
        # (both were "drawing/9" when numbered by the drawings learned so far)
        index = max(self.agent.memory.demonstrations_seen, self._next_index)
        try:
            demo = Demonstration(positions, times=times, shape="drawing", index=index)
        except InvalidDemonstrationError as exc:
            raise HTTPError(422, plain_words(str(exc))) from None
        self._next_index = index + 1
        return demo

    def _drop_client(self, client: str) -> None:
        for k in [k for k, t in self.turns.items() if t.client == client]:
            self._end_turn(k, "this tab drew something newer")

    def _end_turn(self, turn_id: int, why: str) -> None:
        self.turns.pop(turn_id, None)
        self.gone[turn_id] = why
        while len(self.gone) > 256:
            del self.gone[min(self.gone)]

    def _familiarity(self, turn: Any) -> float | None:
        """The drawing's familiarity (:attr:`Turn.familiarity`), None where it has none."""
        with contextlib.suppress(IlociError, ValueError, FloatingPointError):
            value = float(turn.familiarity)
            return value if math.isfinite(value) else None
        return None

    def answer_json(self, answer: Any, turn_id: int | None = None) -> dict[str, Any]:
        r = answer.response
        tid = self.turn_id if turn_id is None else turn_id
        confidence = number(answer.confidence)
        rec = self.turns.get(tid)
        # the last guess left: the robot is not "sure", it has nothing else
        # to offer; its confidence margin says nothing then (issue 26)
        last = False
        if rec is not None and not r.novel:
            concepts = set(self.agent.memory.concepts())
            last = len(concepts - set(rec.turn.tried) - {answer.concept}) == 0
        # a drawing like nothing it was taught (below [learner] unknown_below, as
        # Recognize says "unknown"): the margin between two poor matches can be 1.00,
        # which is no certainty either (issue 26: a straight line was "c2, 1.00")
        fam = rec.familiarity if rec is not None else None
        below = float(getattr(self.agent.config.learner, "unknown_below", 0.0) or 0.0)
        unsure = bool(not r.novel and fam is not None and below > 0 and fam < below)
        out = {"id": answer.id, "turn": tid, "concept": answer.concept, "novel": bool(r.novel),
               "confidence": None if (last or unsure) else confidence, "last_guess": last,
               "unsure": unsure, "familiarity": None if fam is None else round(fam, 3),
               "attempt": answer.attempt,
               "drawing": polyline(answer.drawing), "dt": answer.dt,
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
                "file": self.memory_path.name, "saved": self.memory_path.exists(),
                "save_error": self.save_error,
                "undo": self.history.last, "version": self.history.version}

    def _thumbnails(self, entries: list) -> list:
        """Each entry regenerated by the network, in the drawing plane; cached per revision."""
        mem = self.agent.memory
        key = (id(mem), mem.revision, len(entries))
        with self._thumb_lock:
            if self._thumbs is not None and self._thumbs[:3] == key:
                return self._thumbs[3]
            out: list = [polyline(p) for p in self.agent.entry_drawings(entries)]
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
                "progress": self.progress, "working": self.working.get(client, 0) > 0,
                "simulator": self.agent.simulator is not None}

    @contextlib.contextmanager
    def _working(self, client: str) -> Any:
        """Count a request of tab ``client`` as being handled while it is (:attr:`working`)."""
        self.working[client] = self.working.get(client, 0) + 1
        try:
            yield
        finally:
            self.working[client] -= 1
            if not self.working[client]:
                del self.working[client]


    def _outcome(self, outcome: Any, what: str) -> dict[str, Any]:
        self.history.commit(what)
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
        self.turns[tid].pending = list(turn.learner.queued_events)
        self.turns[tid].familiarity = await asyncio.to_thread(self._familiarity, turn)
        while len(self.turns) > MAX_TURNS:
            self._end_turn(min(self.turns), f"more than {MAX_TURNS} tabs had a guess waiting; "
                                            "the oldest was let go")
        return {"answer": self.answer_json(turn.answer, tid)}

    async def observe(self, body: Any) -> dict[str, Any]:
        positions, times = parse_points(body)
        client = client_id(body)
        with self._working(client):
            async with self.lock:
                demo = self._demo(positions, times)
                return await self._observe(demo, body["points"], client)

    async def feedback(self, body: Any) -> dict[str, Any]:
        value, turn_id, answer_id = parse_feedback(body)
        with self._working(client_id(body)):
            return await self._feedback(body, value, turn_id, answer_id)

    async def _feedback(self, body: Any, value: int | str, turn_id: int,
                        answer_id: str) -> dict[str, Any]:
        async with self.lock:
            rec = self.turns.get(turn_id)
            if rec is None or rec.turn.answer is None:
                why = self.gone.get(turn_id, "it is not one of this server's")
                raise HTTPError(409, f"no such guess is waiting for an answer ({why}); "
                                     "draw again.")
            if isinstance(body, dict) and "client" in body and client_id(body) != rec.client:
                # the page names its tab: another tab's guess is that tab's to judge
                raise HTTPError(409, "this guess is another tab's drawing: answer it in "
                                     "that tab (nothing was learned).")
            if rec.memory is not self.agent.memory or rec.revision != self.agent.memory.revision:
                # another tab taught, or an undo, a rename, a forget, a start over or an
                # import: look at the drawing again
                self._end_turn(turn_id, "the memory changed and the drawing was looked at "
                                        "again")
                out = await self._observe(rec.demo, rec.points, rec.client)
                out["notice"] = ("The memory changed since this guess (another tab taught, "
                                 "undid, renamed, forgot, started over or imported): the robot "
                                 "looked at your drawing again.")
                if "answer" in out:
                    out["answer"]["notice"] = out["notice"]
                return out
            turn = rec.turn
            learner = turn.learner
            learner.queued_events = rec.pending   # this turn's observer events only

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
                rec.pending = learner.queued_events
            if turn.done:
                self._end_turn(turn_id, "it was answered already")
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
        return {"concept": r.concept, "confidence": number(r.confidence),
                "distance": number(r.distance), "entry": r.entry, "tilt": r.tilt,
                "unknown": bool(r.unknown), "familiarity": number(r.familiarity),
                "drawing": drawing}

    def _drawing_of(self, recognition: Any, demo: Any) -> list:
        """The robot's drawing of the recognized entry, in the frame of the person's stroke."""
        drawing = self.agent.drawing_in_frame(demo, recognition.concept, recognition.entry)
        return [] if drawing is None else polyline(drawing)

    async def _same_version(self, body: Any) -> None:
        """Refuse (409, with the memory as it is) a control sent from a page that shows an
        older memory than the server's: another tab taught, undid, renamed or forgot since,
        and an undo or a forget by position would take back that tab's work instead.

        A body without ``"version"`` (a script) is not checked.
        """
        if not isinstance(body, dict) or "version" not in body:
            return
        if body["version"] != self.history.version or isinstance(body["version"], bool):
            raise HTTPError(
                409, "nothing was done: the memory changed since this page showed it "
                     "(another tab taught, undid, renamed or forgot something). The page "
                     "now shows the memory as it is; do it again if you still mean it.",
                memory=await asyncio.to_thread(self.memory_json))

    async def rename(self, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict) or not isinstance(body.get("concept"), str) \
                or not isinstance(body.get("name"), str):
            raise HTTPError(400, 'expected {"concept": "c3", "name": "circle"} (strings).')
        async with self.lock:
            await self._same_version(body)
            if body["concept"] not in self.agent.memory.concepts():
                raise HTTPError(404, f"the memory holds no concept {body['concept']!r}.")
            self.agent.rename(body["concept"], body["name"])
            await self._commit_async(f"rename {body['concept']}")
            return {"memory": await asyncio.to_thread(self.memory_json)}

    async def undo(self, body: Any) -> dict[str, Any]:
        async with self.lock:
            await self._same_version(body)
            undone = await asyncio.to_thread(self.history.undo)
            return {"undone": undone, "memory": await asyncio.to_thread(self.memory_json)}

    async def forget(self, body: Any) -> dict[str, Any]:
        if not isinstance(body, dict) or not (isinstance(body.get("concept"), str) or (
                isinstance(body.get("entry"), int) and not isinstance(body["entry"], bool))):
            raise HTTPError(400, 'expected {"concept": "c3"} or {"entry": 4}.')
        async with self.lock:
            await self._same_version(body)
            mem = self.agent.memory
            if "concept" in body and isinstance(body["concept"], str):
                if body["concept"] not in mem.concepts():
                    raise HTTPError(404, f"the memory holds no concept {body['concept']!r}.")
                self.agent.forget_concept(body["concept"])
                what = f"forget {body['concept']}"
            else:
                i = body["entry"]
                if not 0 <= i < len(mem.entries):
                    raise HTTPError(404, f"the memory has no entry {i} (it has "
                                         f"{len(mem.entries)}).")
                self.agent.forget_entry(i)
                what = f"forget entry {i}"
            await self._commit_async(what)
            return {"memory": await asyncio.to_thread(self.memory_json)}

    async def reset(self, body: Any) -> dict[str, Any]:
        async with self.lock:
            await self._same_version(body)
            self.agent.start_over()
            await self._commit_async("start over")
            return {"memory": await asyncio.to_thread(self.memory_json)}

    async def import_memory(self, data: bytes) -> dict[str, Any]:
        """Replace memory and network with those of an uploaded memory file."""
        if not data:
            raise HTTPError(400, "the upload is empty; choose a memory file (.npz).")
        async with self.lock:
            where: list[str] = []

            def load() -> None:
                with tempfile.TemporaryDirectory() as d:
                    tmp = Path(d) / "upload.npz"
                    where.append(str(tmp))
                    tmp.write_bytes(data)
                    # checked as Agent.load checks it: the network must fit this
                    # server's model, the entries its settings, the robot its arm
                    self.agent.replace_memory(tmp)
            try:
                await asyncio.to_thread(load)
            except IlociError as exc:
                # the message names the server's temporary copy: the person chose a file
                why = str(exc).replace(where[0], "the file") if where else str(exc)
                raise HTTPError(422, f"not imported: {why}") from None
            await self._commit_async("import")
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
            from PIL import Image  # the serve extra
            buf = io.BytesIO()
            image = np.ascontiguousarray(sim.render(execution, 360, 270), dtype=np.uint8)
            Image.fromarray(image).save(buf, format="PNG")
            return buf.getvalue()
        return await asyncio.to_thread(render)
