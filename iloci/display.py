"""Progress bars for the command line (rich): a terminal, a log file, a notebook.

* On a terminal, live bars redrawn in place (one per fold or one per sweep,
  with elapsed time and the estimate of what remains).
* In a Jupyter notebook, the same bars as a live output cell (rich detects
  the notebook).
* Written to a file or a pipe (a log), no bars and no terminal codes: one
  plain line at each milestone (a fold started, each quarter of it, done
  with its result), so ``tail -f`` shows the run advancing.

:class:`Bars` is the building block; :class:`FoldProgress` turns the
progress messages of :func:`iloci.evaluation.evaluate.evaluate` into bars.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

from rich.console import Console
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn,
                           TimeElapsedColumn, TimeRemainingColumn)

__all__ = ["Bars", "FoldProgress"]


class Bars:
    """Named progress bars on ``stream`` (default stderr); a context manager.

    Parameters
    ----------
    stream : file, optional
        Where to draw. A terminal (or a notebook) gets live bars; anything
        else gets a plain line per :meth:`update` that passes a quarter of
        the bar, and per :meth:`log`.
    unit : str
        What the bars count ("demos", "runs"), shown after ``n/total``.
    """

    def __init__(self, stream: TextIO | None = None, *, unit: str = "") -> None:
        self.console = Console(file=stream if stream is not None else sys.stderr,
                               highlight=False)
        self.live = self.console.is_terminal or self.console.is_jupyter
        self.unit = unit
        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
            TextColumn(unit), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
            TextColumn("{task.fields[status]}"), console=self.console,
            disable=not self.live, refresh_per_second=4)
        self._tasks: dict[Any, TaskID] = {}
        self._quarter: dict[Any, int] = {}

    def __enter__(self) -> Bars:
        self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._progress.stop()

    def add(self, key: Any, description: str, total: int, *, start: bool = True) -> None:
        """A bar for ``key`` (once; later calls change its total)."""
        if key in self._tasks:
            self._progress.update(self._tasks[key], total=max(1, total))
            if start:
                self._progress.start_task(self._tasks[key])
            return
        self._tasks[key] = self._progress.add_task(description, total=max(1, total),
                                                   status="", start=start)

    def total(self, key: Any) -> int:
        """The total of ``key``'s bar."""
        task = self._tasks[key]
        return int(self._progress.tasks[self._progress.task_ids.index(task)].total or 0)

    def update(self, key: Any, completed: int, status: str = "", *,
               milestone: bool = False) -> None:
        """Set ``key``'s bar to ``completed``.

        A log gets a line when a quarter of the bar is passed, or when
        ``milestone`` is true (e.g. a fold's result).
        """
        task = self._tasks[key]
        self._progress.update(task, completed=completed, status=status)
        if not self.live:
            t = self._progress.tasks[self._progress.task_ids.index(task)]
            quarter = int(4 * completed / (t.total or 1))
            if milestone or quarter != self._quarter.get(key, -1):
                self._quarter[key] = quarter
                self.log(f"{t.description}: {completed}/{int(t.total or 0)} {self.unit}"
                         + (f"  {status}" if status else ""))

    def log(self, line: str) -> None:
        """A line of text: above the live bars, or as a line of the log."""
        self.console.print(line, markup=False, highlight=False, soft_wrap=True)


class FoldProgress(Bars):
    """A bar per evaluation fold, fed by evaluate()'s progress messages.

    Call it with each message dict (``kind``: ``fold_queued``,
    ``fold_start``, ``interaction``, ``rehearsal``, ``recognition``,
    ``recognized``, ``fold_done``). The recognition of a fold's test set
    (a minute or more on a few hundred drawings) gets a line when it
    starts (``fold 2: recognizing 256 test drawings ...``) and one when it,
    or each part of it run in another worker, ends.
    """

    def __init__(self, stream: TextIO | None = None) -> None:
        super().__init__(stream, unit="demos")
        self._recognizing: set[Any] = set()  # folds whose recognition was announced

    def __call__(self, msg: dict) -> None:
        k, kind = msg["fold"], msg["kind"]
        if kind == "fold_queued":
            self.add(k, f"fold {k}", msg["total"], start=False)
            self._progress.update(self._tasks[k], status="waiting for a worker")
        elif kind == "fold_start":
            self.add(k, f"fold {k}", msg["total"])
            self.update(k, 0, "learning")
        elif kind == "interaction":
            self.update(k, msg["step"] + 1, "learning")
        elif kind == "recognition" and k not in self._recognizing:
            self._recognizing.add(k)  # the first part to start: the parts run at once
            parts = f" in {msg['parts']} parts" if msg["parts"] > 1 else ""
            self.update(k, self.total(k), f"recognizing {msg['total']} test drawings")
            self.log(f"fold {k}: recognizing {msg['total']} test drawings{parts} ...")
        elif kind == "recognized":
            what = (f"part {msg['part'] + 1} of {msg['parts']} ({msg['drawings']} drawings)"
                    if msg["parts"] > 1 else f"{msg['drawings']} test drawings")
            self.log(f"fold {k}: recognized {what} in {msg['seconds']:.0f} s")
        elif kind == "fold_done":
            self.update(k, self.total(k), f"done in {msg['seconds']:.0f} s, "
                                          f"CCR {100 * msg['ccr']:.1f} %", milestone=True)
