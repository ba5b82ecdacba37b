"""The fold executor's interface: evaluation folds (or any picklable calls) run in parallel."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol, runtime_checkable



__all__ = ["FoldExecutor"]


@runtime_checkable
class FoldExecutor(Protocol):
    """Runs evaluation folds (or any picklable calls) in parallel: ``iloci_make_executor``'s result.

    :mod:`iloci.evaluation.executors` has the kernel's (``local``); ``iloci-ray`` adds ``ray``.
    """

    #: Short name, as ``iloci evaluate --executor`` takes it.
    name: str

    def run(self, fn: Callable[..., Any], calls: Sequence[tuple],
            emit: Callable[[dict], None]) -> Iterator[Any]:
        """Call ``fn(*args, queue)`` for each ``args`` of ``calls``; yield results.

        Results come in the order the calls finish. ``queue.put(msg)`` in a
        call passes ``msg`` (a picklable dict) to ``emit`` in the caller.
        An exception raised by a call is raised here, after the other calls
        are cancelled; so is ``KeyboardInterrupt``.
        """
        ...
