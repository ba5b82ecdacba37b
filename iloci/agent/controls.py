"""A person's controls over an agent's memory: undo, forget, start over, import.

:class:`Controls` is a base of :class:`iloci.agent.Agent`: the web
page (``iloci serve``) and any other front end reach the robot's memory
and network through these methods, never through
:mod:`iloci.concepts` (``docs/development.md``, "Architecture", forbids
``iloci.web`` importing it). Each method holds the agent's lock, so a
reader (another thread answering the page) sees the memory before or
after a change, never half of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import json
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from iloci.agent.persistence import Persistence, robot_record
from iloci.concepts.memory import Memory, load_memory
from iloci.concepts.perform import ik_joint_limits, perform
from iloci.config import memory_conflicts
from iloci.errors import InvalidInputError
from iloci.sensorimotor.frames import TeacherFrame
from iloci.validation import is_integer

if TYPE_CHECKING:
    from iloci.interfaces import Demonstration

__all__ = ["Controls", "Snapshot"]


@dataclass(frozen=True)
class Snapshot:
    """The memory and the network at one moment (:meth:`Controls.snapshot`).

    Attributes
    ----------
    what : str
        The step that led here (``"rename c3"``, ``"drawing drawing/4"``), for the page.
    arrays, meta
        The memory as :meth:`Memory.to_arrays <iloci.concepts.memory.Memory.to_arrays>`
        writes it (copies).
    encoder : SensorimotorEncoder or None
        The memory's encoder (shared: an encoder is never changed once fitted).
    network : dict of str to ndarray
        The perceptual model's ``state()`` (copies); empty before the first rehearsal.
    agent : dict
        Whose it is: the robot (as a memory file records it) and the config
        sections the memory's entries depend on; :meth:`Controls.restore`
        refuses a snapshot of another agent.
    """

    what: str
    arrays: dict[str, np.ndarray]
    meta: dict[str, Any]
    encoder: Any
    network: dict[str, np.ndarray]
    agent: dict[str, Any] = field(default_factory=dict)


class Controls(Persistence):
    """Undo, forget, start over and import for :class:`~iloci.agent.Agent` (see the module)."""

    def snapshot(self, what: str = "") -> Snapshot:
        """The memory and the network now, restored exactly by :meth:`restore`.

        Parameters
        ----------
        what : str
            A name for the step that led here (shown by an undo).
        """
        with self._lock:
            arrays, meta = self.memory.to_arrays()
            return Snapshot(
                what=what,
                arrays={k: np.array(v, copy=True) for k, v in arrays.items()},
                meta=json.loads(json.dumps(meta)),
                encoder=self.memory.encoder,
                network={k: np.array(v, copy=True)
                         for k, v in self.perceptual_model.state().items()},
                agent=self._whose())

    def _whose(self) -> dict[str, Any]:
        """What a snapshot records of this agent: its robot (as a memory file records it)
        and its config (of which :func:`~iloci.config.memory_conflicts` compares the
        settings the memory's entries depend on, as :meth:`load` does)."""
        return json.loads(json.dumps({"robot": robot_record(self.robot),
                                      "config": self.config.to_dict()}, default=str))

    def restore(self, snapshot: Snapshot) -> None:
        """Put back the memory and the network of ``snapshot`` (bit for bit).

        The memory's ``revision`` still grows (a turn observed before the
        restore sees that the memory changed).

        Raises
        ------
        InvalidInputError
            ``snapshot`` is not a :class:`Snapshot`, or one of another agent
            (another robot, network sizes or sensorimotor settings: its
            entries would not fit this agent); the agent is unchanged.
        """
        if not isinstance(snapshot, Snapshot):
            raise InvalidInputError(f"restore takes a Snapshot (agent.snapshot()), got "
                                    f"{type(snapshot).__name__}.")
        if snapshot.agent:
            theirs, mine = snapshot.agent, self._whose()["robot"]
            differ = memory_conflicts(theirs["config"], self.config)
            if theirs["robot"] != mine:
                differ.insert(0, f"robot = {theirs['robot']['name']!r} with "
                                 f"{len(theirs['robot']['joints'])} joints "
                                 f"(kinematics {theirs['robot'].get('kinematics')}), here "
                                 f"{mine['name']!r} with {len(mine['joints'])} "
                                 f"(kinematics {mine.get('kinematics')})")
            if differ:
                raise InvalidInputError(
                    "this snapshot was taken of an agent whose memory does not fit this one: "
                    + "; ".join(differ) + ". Restore snapshots of this agent, or save the "
                    "other agent and load its file (Agent.load). Nothing was changed.")
        with self._lock:
            memory = Memory.from_arrays(snapshot.arrays, snapshot.meta)
            memory.encoder = snapshot.encoder if snapshot.encoder is not None \
                else memory.encoder
            memory.revision = self.memory.revision + 1
            if snapshot.network:
                self.perceptual_model.load_state(snapshot.network)
            self.memory = memory

    def forget_concept(self, concept: str) -> None:
        """Forget every entry of ``concept``; the network is unchanged (no rehearsal).

        Raises
        ------
        InvalidInputError
            The memory holds no such concept.
        """
        with self._lock:
            mem = self.memory
            keep = [e for e in mem.entries if e.concept != concept]
            if len(keep) == len(mem.entries):
                raise InvalidInputError(f"the memory holds no concept {concept!r}; its "
                                        f"concepts are {', '.join(mem.concepts()) or 'none'}.")
            mem.entries = keep           # one assignment: readers see old or new
            mem.revision += 1

    def forget_entry(self, index: int) -> None:
        """Forget entry ``index`` of ``memory.entries`` (0-based); the network is unchanged.

        Raises
        ------
        InvalidInputError
            ``index`` is not an int, or not an entry of the memory; nothing changes.
        """
        if not is_integer(index):
            raise InvalidInputError(f"forget_entry takes an entry's index (an int, 0-based in "
                                    f"memory.entries), got {index!r}.")
        index = int(index)
        with self._lock:
            mem = self.memory
            if not 0 <= index < len(mem.entries):
                raise InvalidInputError(f"the memory has no entry {index} (it has "
                                        f"{len(mem.entries)}).")
            mem.entries = [e for j, e in enumerate(mem.entries) if j != index]
            mem.revision += 1

    def start_over(self) -> None:
        """An empty memory (no entries, no encoder); the network stays until the next rehearsal."""
        with self._lock:
            self.memory = Memory(revision=self.memory.revision + 1)

    def replace_memory(self, path: str | os.PathLike[str]) -> None:
        """Replace memory and network with a memory file's, checked as :meth:`load` checks it.

        The network must fit this agent's perceptual model, the entries its
        settings, the robot its arm; nothing is unpickled.

        Raises
        ------
        MemoryFileError, MemoryConfigError
            As :meth:`~iloci.agent.Agent.load`; the agent is then unchanged.
        """
        memory, net, _header = load_memory(path)
        self.load(path, self.config)
        with self._lock:
            memory.revision = self.memory.revision + 1
            if net:
                self.perceptual_model.load_state(net)
            self.memory = memory

    def drawing_in_frame(self, demo: Demonstration, concept: str,
                         entry: int | None = None) -> np.ndarray | None:
        """The robot's drawing of ``concept`` in the frame of ``demo`` (the person's stroke).

        Parameters
        ----------
        demo : Demonstration
            The stroke whose position, size and units the drawing takes.
        concept : str
        entry : int, optional
            The entry to perform (a recognition's ``entry``); default: the
            concept's entry of lowest generation error.

        Returns
        -------
        ndarray (T, 2) or None
            Pen positions in ``demo``'s units; None when the performance has
            no drawing in the teacher's frame.

        Raises
        ------
        InvalidInputError
            No such concept, or ``entry`` is not the index (in
            ``memory.entries``) of one of its entries.
        """
        motion = self.motion(demo)
        frame = TeacherFrame.of(demo, motion.plane_points)
        mine = self.memory.indices_of(concept) if isinstance(concept, str) else []
        if not mine:
            raise InvalidInputError(f"the memory holds no concept {concept!r}; its concepts "
                                    f"are {', '.join(self.memory.concepts()) or 'none'}.")
        if entry is None:
            index = self.memory.performer_of(concept)
        elif is_integer(entry) and int(entry) in mine:
            index = int(entry)
        else:
            raise InvalidInputError(f"entry {entry!r} is not an entry of {concept!r}: give one "
                                    f"of its indices in memory.entries ({mine}), or leave "
                                    "entry out for its best.")
        with self._lock:
            response = perform(self.memory, self.perceptual_model, index,
                               joint_limits=ik_joint_limits(self.ik_solver), frame=frame)
        return response.teacher_drawing
