"""The web API's request bodies and answers: limits, parsing, JSON helpers, error messages.

Every malformed request becomes an :class:`HTTPError` (a 4xx with a
message), never a traceback: a stroke is checked here before the library
sees it, a body is read with a size limit and a deadline.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
import difflib
import json
import math
from typing import Any

import numpy as np

from iloci.errors import (FeedbackError, IlociError, InvalidInputError, NotFittedError,
                          StaleAnswerError)
from iloci.progress import MemoryLockedError

__all__ = ["HTTPError", "status_of", "parse_points", "parse_feedback", "client_id", "number",
           "polyline", "plain_words", "read_body", "read_json", "MAX_BODY", "MAX_MEMORY_BYTES",
           "BODY_SECONDS", "MAX_POINTS", "MIN_POINTS", "MAX_VALUE"]

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


class HTTPError(Exception):
    """An error answered as ``{"error": message}`` with ``status``."""

    def __init__(self, status: int, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.extra = extra


def status_of(exc: IlociError) -> int:
    """The HTTP status of a library error reaching the API."""
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


def parse_feedback(body: Any) -> tuple[int | str, int, str]:
    """``{"turn": id, "answer": id, "value": 1 | -1 | "new"}`` -> (value, turn, answer).

    Raises HTTPError (400, 422) when the body is not such an object.
    """
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
    return value, turn_id, answer_id


def known_fields(body: Any, fields: Sequence[str], path: str) -> None:
    """Refuse (HTTPError 400) a JSON object with a field outside ``fields``, naming it.

    A misspelt field (``"vaule"``) would otherwise be read as a missing one,
    or, where it is optional (``"version"``), silently not be checked. Bodies
    that are not objects are left to the endpoint's own message.
    """
    if not isinstance(body, dict):
        return
    unknown = [k for k in body if k not in fields]
    if not unknown:
        return
    hints = []
    for k in unknown:
        close = difflib.get_close_matches(str(k), fields, n=1)
        hints.append(f"{json.dumps(k)[:40]}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    raise HTTPError(400, f"{path} does not take the field(s) {', '.join(hints)}; it takes "
                         f"{', '.join(fields)}. Nothing was changed.")


def client_id(body: Any) -> str:
    """The tab's id (``"client"``: up to 64 letters, digits, ``-`` or ``_``; default ``""``)."""
    c = body.get("client", "") if isinstance(body, dict) else ""
    if not isinstance(c, str) or len(c) > 64 or not all(ch.isalnum() or ch in "-_" for ch in c):
        raise HTTPError(400, '"client" must be a short id (letters, digits, "-", "_").')
    return c


def number(value: float, digits: int = 4) -> float | None:
    """``value`` rounded, or None where it is not a finite number (JSON has no NaN)."""
    value = float(value)
    return round(value, digits) if math.isfinite(value) else None


def polyline(points: np.ndarray) -> list[list[float]]:
    """(N, 2) points -> ``[[x, y], ...]`` rounded to 4 decimals (JSON)."""
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
    if "is not waiting for a feedback" in low:   # StaleAnswerError: Answer.id is not for people
        return ("This guess was answered already (in another window or tab showing this "
                "drawing?); nothing changed. Reload the page to see what the robot waits "
                "for now.")
    if "learned nothing yet" in low:
        return ("The robot has learned nothing yet: teach it a first drawing (Teach mode), "
                "then it can recognize.")
    return message


def _too_big(limit: int) -> HTTPError:
    """413, saying what to do: a drawing's body or a memory file's, by the limit."""
    if limit >= MAX_MEMORY_BYTES:
        what = (f"a memory file is imported up to {limit // 2**20} MiB; one this large was "
                "not written by iloci")
    else:
        what = (f"a drawing is sent with at most {MAX_POINTS} points [x, y, t]; send fewer "
                "(every other sample of a long recording, say)")
    return HTTPError(413, f"the request body is over {limit:,} bytes: {what}.")


async def read_body(request: Any, limit: int) -> bytes:
    """The request's body: at most ``limit`` bytes (413), within :data:`BODY_SECONDS` (408)."""
    length = request.headers.get("content-length")
    if length is not None and not (length.isdigit() and len(length) < 16):
        raise HTTPError(400, "the Content-Length header is not a number.")
    if length is not None and int(length) > limit:
        raise _too_big(limit)
    from starlette.requests import ClientDisconnect  # the serve extra

    async def read() -> bytes:
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > limit:
                raise _too_big(limit)
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


async def read_json(request: Any) -> Any:
    """The request's body (at most :data:`MAX_BODY` bytes) as JSON; HTTPError 400 if it is not."""
    raw = await read_body(request, MAX_BODY)
    try:
        return json.loads(raw or b"null")
    except RecursionError:
        raise HTTPError(400, "the JSON is nested too deeply.") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise HTTPError(400, f"the body is not JSON ({str(exc)[:120]}).") from None
