"""The agent's memory on disk: :meth:`~Persistence.save` and :meth:`~Persistence.load`.

One ``.npz`` file holds the memory, the network's state, the config, the
robot and what each use of the memory needs (format:
:mod:`iloci.concepts.storage`). Loading assembles the agent's parts from the
saved (or a given) config through :func:`~iloci.agent.assembly.assemble`, as
:func:`~iloci.agent.build` does, then checks the memory fits them (same
robot, no conflicting setting, the network's sizes).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Self


import pluggy

from iloci._version import __version__, is_newer
from iloci.agent.assembly import PURPOSES, NotLoaded, assemble
from iloci.agent.base import AgentBase
from iloci.concepts.memory import load_memory, save_memory
from iloci.concepts.storage import RESERVED, check_header_extra, memory_path
from iloci.config import memory_conflicts
from iloci.sensorimotor.robots.urdf import kinematics_fingerprint
from iloci.errors import (ConfigError, InvalidInputError, MemoryConfigError, MemoryFileError,
                          UnknownComponentError)
from iloci.progress import saving

__all__ = ["Persistence", "robot_record", "upgrade_config", "check_same_robot"]


#: Header keys :meth:`Persistence.save` writes beside the memory's (not for ``extra``).
SAVED_KEYS = frozenset({"config", "robot", "needs"})


class Persistence(AgentBase):
    """Saving and loading :class:`~iloci.agent.Agent` (see the module)."""

    # -- persistence --------------------------------------------------------------------
    def save(self, path: str | os.PathLike[str], *,
             extra: dict[str, Any] | None = None) -> Path:
        """Save the memory, the network and the config to one ``.npz`` file, atomically.

        See :mod:`iloci.concepts.memory` for the format. ``extra``: more
        JSON-able header values (``iloci teach`` keeps its progress through
        a stream there). Returns the path (a symlink's target is written
        through, the link kept).

        Raises
        ------
        InvalidInputError
            ``path`` is empty, or ``extra`` is not a mapping of JSON values
            or names a key the file's header holds itself (``format``,
            ``version``, ``iloci``, ``checksum``, ``memory``, ``config``,
            ``robot``, ``needs``); nothing is written.
        MemoryFileError
            ``path`` is a directory; nothing is written.
        MemoryLockedError
            Another process (``iloci serve``, ``iloci teach``) holds the
            memory's lock (:func:`iloci.progress.memory_lock`); nothing is
            written.
        OSError
            The file cannot be written (disk full, permissions); the file
            on disk is the previous one, untouched.
        """
        memory_path(path)
        extra = check_header_extra(extra, RESERVED | {"memory", *SAVED_KEYS})
        with self._lock, saving(path):
            return save_memory(path, self.memory, self.perceptual_model.state(),
                               extra={**extra, "config": self.config.to_dict(),
                                      "robot": robot_record(self.robot),
                                      "needs": self.needs()})

    def needs(self) -> dict[str, dict[str, dict[str, str | None]]]:
        """What each use of this agent's memory needs: purpose -> section -> component.

        ``{"recognize": {...}, "learn": {...}}``; each component as
        ``{"name": ..., "distribution": ...}`` (the distribution that
        registered it, None for an object passed to :func:`build`).
        :meth:`save` records it in the memory file, and :meth:`load` with
        ``purpose="recognize"`` builds only the sections listed there (see
        :data:`PURPOSES`).
        """
        out: dict[str, dict[str, dict[str, str | None]]] = {}
        for purpose, sections in PURPOSES.items():
            out[purpose] = {}
            for sec in sections:
                name = getattr(self.config, sec).name
                if name == "none":
                    continue
                dist = None
                if sec not in self.config._supplied and (sec, name) in self.registry:
                    dist = self.registry.get(sec, name).distribution
                out[purpose][sec] = {"name": name, "distribution": dist}
        return out

    @classmethod
    def load(cls, path: str | os.PathLike[str], config: Any = None, *,
             plugin_manager: pluggy.PluginManager | None = None, purpose: str = "learn",
             **overrides: Any) -> Self:
        """An agent with a saved memory, ready to recognize and to keep learning.

        Parameters
        ----------
        path : path-like
            A file written by :meth:`save`.
        config : Config, path, mapping, optional
            Config to build the components from; by default the one saved
            with the memory. Its perceptual model must have the saved
            network's sizes.
        plugin_manager : pluggy.PluginManager, optional
        purpose : {"learn", "recognize"}
            ``"learn"`` (default) builds every configured component.
            ``"recognize"`` builds only what recognition needs, as the memory
            file records it (:meth:`needs`; by default the perceptual model
            and the IK solver, :data:`PURPOSES`): the teaching-only
            components (clusterer, teacher) are not built, so their plugins
            need not be installed, and there is no simulator
            (:meth:`respond` is then not executed). Using the clusterer or
            the teacher raises :class:`~iloci.errors.NotLoadedError`, which
            says to load for learning.
        **overrides
            Component instances, as for :func:`build`.

        Raises
        ------
        InvalidInputError
            ``purpose`` is neither ``"learn"`` nor ``"recognize"``.
        MemoryFileError
            Missing, truncated, tampered with or written by a newer iloci.
        MemoryConfigError
            ``config`` changes a setting the memory's entries depend on
            (see :func:`~iloci.config.memory_conflicts`), such as
            ``[sensorimotor] steps`` or the network's sizes.
        """
        if purpose not in PURPOSES:
            raise InvalidInputError(f"purpose must be one of {', '.join(map(repr, PURPOSES))}, "
                                    f"got {purpose!r}.")
        memory, net_state, header = load_memory(memory_path(path))
        saved = header.get("config")
        own_config = config is None
        if config is None:
            config = saved
            if not isinstance(config, dict):
                raise MemoryFileError(f"{path} holds no config; pass config= to load it.")
            config = upgrade_config(config)
        if purpose != "learn":
            needed = set(PURPOSES[purpose])
            recorded = (header.get("needs") or {}).get(purpose)
            if isinstance(recorded, dict):
                needed = set(recorded) | {"perceptual_model", "ik"}
            for sec in PURPOSES["learn"]:
                if sec not in needed and sec not in overrides:
                    # recognition executes nothing: no simulator (respond() is not executed)
                    overrides[sec] = (None if sec == "simulator"
                                      else NotLoaded(sec, purpose, str(path)))
        try:
            agent = cls(*assemble(config, plugin_manager, overrides))
        except (ConfigError, UnknownComponentError) as exc:
            written = header.get("iloci")
            if own_config and is_newer(written):
                raise MemoryFileError(
                    f"{path} was written by iloci {written}, this is iloci {__version__}: "
                    f"upgrade iloci (and its plugins) to {written} or later to load it; its "
                    f"saved config holds what this version does not know ({exc}). The file "
                    "is unchanged.") from None
            if own_config and exc.args and isinstance(exc.args[0], str):
                # the saved config is a mapping ("<dict>" in the message): name the file
                exc.args = (exc.args[0].replace("<dict>", f"{path} (its saved config)", 1),
                            *exc.args[1:])
            raise
        saved_robot = header.get("robot") or {
            "name": "nao-v32-right-arm",
            "joints": list(agent.robot.joint_names) if agent.robot.name == "nao-v32-right-arm"
            else []}
        check_same_robot(path, saved_robot, agent.robot, memory)
        if isinstance(saved, dict) and config is not saved:
            conflicts = memory_conflicts(saved, agent.config)
            if conflicts:
                raise MemoryConfigError(str(path), conflicts, source=agent.config.source)
        if net_state:
            try:
                agent.perceptual_model.load_state(net_state)
            except (ValueError, KeyError, InvalidInputError) as exc:
                raise MemoryFileError(f"the network saved in {path} does not fit the "
                                      f"configured perceptual model: {exc}") from None
        agent.memory = memory
        return agent


def robot_record(robot: Any) -> dict[str, Any]:
    """What a memory file records of its robot (JSON): names, frames, the URDF's path
    and the fingerprint of its arm's kinematics (:func:`_kinematics`)."""
    return {"name": robot.name, "joints": list(robot.joint_names),
            "tip_frame": robot.end_effector_frame, "base_frame": robot.base_frame,
            "urdf": str(robot.urdf_path), "kinematics": _kinematics(robot)}


def _kinematics(robot: Any) -> str | None:
    """The fingerprint of the robot's chain (:attr:`Robot.kinematics
    <iloci.sensorimotor.robots.Robot>`, as read when it was described; else
    :func:`~iloci.sensorimotor.robots.urdf.kinematics_fingerprint` of its URDF file), or
    None for a robot without a readable URDF (an object passed to ``build``)."""
    known = getattr(robot, "kinematics", None)
    if isinstance(known, str):
        return known
    try:
        return kinematics_fingerprint(robot.urdf_path, robot.base_frame,
                                      robot.end_effector_frame)
    except (InvalidInputError, OSError, AttributeError, TypeError):
        return None


def upgrade_config(config: dict[str, Any]) -> dict[str, Any]:
    """A saved config from before the ``[robot]`` section: its robot moves there."""
    sm = config.get("sensorimotor")
    if isinstance(sm, dict) and "robot" in sm:
        config = {**config, "sensorimotor": {k: v for k, v in sm.items() if k != "robot"}}
        config.setdefault("robot", {"name": sm["robot"]})
        for sec in ("ik", "simulator"):
            if isinstance(config.get(sec), dict) and "robot" in config[sec]:
                config[sec] = {k: v for k, v in config[sec].items() if k != "robot"}
    return config


def check_same_robot(path: Any, saved: dict[str, Any], robot: Any, memory: Any) -> None:
    """Refuse a memory learned by another robot (its patterns hold that robot's joints)."""
    joints = list(saved.get("joints") or [])
    width = 2 + len(robot.joint_names)
    enc = memory.encoder
    enc_width = None if enc is None or enc.scale_ is None else len(enc.scale_)
    if (joints and joints != list(robot.joint_names)) or \
            (enc_width is not None and enc_width != width):
        n_saved = len(joints) if joints else (enc_width or 2) - 2
        raise MemoryFileError(
            f"{path} was learned by robot {saved.get('name')!r} with {n_saved} joints "
            f"({', '.join(joints) or 'unnamed'}); the configured robot {robot.name!r} has "
            f"{len(robot.joint_names)} ({', '.join(robot.joint_names)}). A memory's patterns "
            "are that robot's joint motions: load it with its own robot (leave out config= "
            "or use the [robot] it was saved with), or teach the new robot afresh.")
    was = saved.get("kinematics")
    if was:
        now = _kinematics(robot)
        if now is not None and now != was:
            raise MemoryFileError(
                f"{path} was learned by robot {saved.get('name')!r} as its URDF "
                f"({saved.get('urdf')}) was then; the arm's joints from "
                f"{robot.base_frame!r} to {robot.end_effector_frame!r} in "
                f"{robot.urdf_path} have changed since (a link's length, an axis, a limit): "
                "the memory's patterns are the old arm's joint motions. Restore the URDF it "
                "was taught with, or teach the changed arm afresh (another --memory). The "
                "file is unchanged.")


