"""The memory file and the undo steps of ``iloci serve``: what is saved, what an undo restores.

After every change the memory is saved atomically (under the memory's
lock, :func:`iloci.progress.memory_lock`); a failed save (disk full,
permissions, another writer) puts memory and network back as the file
holds them and is reported (507, or 423 for a lock). Each saved step keeps
a :class:`~iloci.agent.controls.Snapshot` of what came before it: an undo
restores it exactly (memory and network), and saves.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

from iloci.progress import MemoryLockedError, why_not_saved
from iloci.web.schemas import HTTPError

__all__ = ["History", "UNDO_STEPS", "save_failure"]

log = logging.getLogger("iloci.serve")

#: Undo steps kept (each a copy of the memory and the network).
UNDO_STEPS = 20


def save_failure(path: Path, exc: OSError) -> str:
    """The page's message for a save that failed with ``exc``."""
    return (f"{why_not_saved(path, exc)} The file still holds the memory shown here, from "
            "before this step; this step was not learned. Free some space or fix the "
            "permissions, then do it again.")


class History:
    """The memory file of one agent and the steps that can be undone.

    Parameters
    ----------
    agent : Agent
    memory_path : path-like
        Saved atomically after every change (a symlink is written through
        to its target).

    Attributes
    ----------
    save_error : str or None
        Why the last save failed (None: it did not).
    """

    def __init__(self, agent: Any, memory_path: str | os.PathLike[str]) -> None:
        self.agent = agent
        self.memory_path = Path(memory_path)
        self.save_error: str | None = None
        self.steps: list[Any] = []
        self.saved = agent.snapshot("start")    # what the file holds (or will)
        #: Changes saved so far (commits and undos): a page names the version it shows,
        #: so a control sent from a view another tab has since changed is refused
        self.version = 0

    @property
    def last(self) -> str | None:
        """The step an undo would take back (its name), or None."""
        return self.steps[-1].what if self.steps else None

    def commit(self, what: str) -> None:
        """Save the change just made; on failure put memory and network back as the file holds them.

        Raises HTTPError 507 (the memory then is the file's) when the save
        fails, 423 when another writer holds the memory's lock.
        """
        try:
            self.agent.save(self.memory_path)
        except OSError as exc:
            self.agent.restore(self.saved)
            self.save_error = save_failure(self.memory_path, exc)
            log.warning("%s", self.save_error)
            raise HTTPError(507, self.save_error, saved=False) from None
        except MemoryLockedError as exc:
            self.agent.restore(self.saved)
            self.save_error = str(exc)
            raise HTTPError(423, self.save_error, saved=False) from None
        self.save_error = None
        self.steps.append(self.saved)
        del self.steps[:-UNDO_STEPS]
        self.saved = self.agent.snapshot(what)
        self.version += 1

    def undo(self) -> str:
        """Restore memory and network as before the last step and save; the step's name.

        Raises HTTPError 409 with nothing to undo, 507 when the save fails
        (then nothing changed).
        """
        if not self.steps:
            raise HTTPError(409, "there is nothing to undo.")
        snap = self.steps.pop()
        current = self.saved
        self.agent.restore(snap)
        try:
            self.agent.save(self.memory_path)
        except (OSError, MemoryLockedError) as exc:
            self.agent.restore(current)
            self.steps.append(snap)
            self.save_error = (save_failure(self.memory_path, exc)
                               if isinstance(exc, OSError) else str(exc))
            raise HTTPError(507, self.save_error, saved=False) from None
        self.save_error = None
        self.saved = snap
        self.version += 1
        return current.what
