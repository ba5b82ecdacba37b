"""The teacher's interface: +1 or -1 on each of the robot's responses, and its check."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from iloci.errors import FeedbackError
from iloci.interfaces.values import Demonstration, Response
from iloci.validation import is_integer

__all__ = ["Teacher", "check_feedback"]


@runtime_checkable
class Teacher(Protocol):
    """Judges the robot's response to a demonstration."""

    def feedback(self, demo: Demonstration, response: Response) -> int:
        """Return +1 (reward) or -1 (punishment).

        Anything else is a broken teacher: callers check the answer with
        :func:`check_feedback`, which raises :class:`~iloci.errors.FeedbackError`.
        """
        ...


def check_feedback(value: object, teacher: object) -> int:
    """``value`` as an int if it is a valid :meth:`Teacher.feedback`, +1 or -1.

    Part of the Teacher contract: whoever calls a teacher checks its answer
    with this before acting on it.

    Raises
    ------
    FeedbackError
        ``value`` is anything else (a bool, a float, 0, ...); the message
        names the teacher's class, or ``teacher`` itself when it is a string
        naming where the feedback came from (e.g. ``"Turn.feedback()"``).
    """
    if not is_integer(value) or int(value) not in (1, -1):
        if isinstance(teacher, str):
            raise FeedbackError(f"{teacher} got {value!r}; feedback must be +1 (reward) or "
                                "-1 (punishment).")
        raise FeedbackError(
            f"teacher {type(teacher).__name__} returned {value!r}; feedback must be "
            "+1 (reward) or -1 (punishment). Fix the teacher plugin's feedback().")
    return int(value)
