"""The robot draws one of its concepts: regenerated, executed in a simulator, pictured.

Free functions of the parts they use, in the style of Pinocchio's
``algorithm(model, data)``: :func:`draw` takes a memory (the data), the
network and IK solver it was taught with (the model) and a simulator. An
:class:`~iloci.agent.Agent` has all of them; :func:`load_drawing_parts`
builds only these from a memory file, so drawing needs neither the
clusterer nor the teacher the memory was taught with::

    parts = load_drawing_parts("memory.npz")
    result = draw(*parts, "GShape", simulator)
    write_png("gshape.png", simulator.render(result.execution))

``iloci draw`` is this, on the command line.
"""

from __future__ import annotations

from dataclasses import dataclass
import io
import os
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from iloci.agent.persistence import upgrade_config
from iloci.concepts.learner import ik_joint_limits, perform
from iloci.concepts.memory import load_memory
from iloci.config import DEFAULT_NAMES, EvaluationConfig, RobotConfig, SensorimotorConfig
from iloci.data.concepts import concept_of_key, majority_names
from iloci.data.files import write_atomic
from iloci.errors import (ConfigError, InvalidInputError, MemoryFileError, MissingBackendError,
                          UnknownComponentError, did_you_mean)
from iloci.interfaces import Execution, IKSolver, PerceptualModel, Response, Simulator
from iloci.plugins import get_registry
from iloci.registry import validate_dataclass, validate_params
from iloci.sensorimotor.robots import get_robot, robot_and_ik

__all__ = ["DrawResult", "DrawingParts", "draw", "gif_frames", "load_drawing_parts",
           "resolve_concept", "write_gif", "write_png"]

#: Frames of a GIF at most; longer motions skip steps evenly.
MAX_GIF_FRAMES = 60


def resolve_concept(memory: Any, name: str) -> str:
    """The robot's concept label meant by ``name``.

    Parameters
    ----------
    memory : Memory
    name : str
        A robot concept label present in the memory (``"c3"``), or a true
        concept (``"GShape"``) naming the robot concept whose entries'
        source demonstrations mostly have it (by an oracle's knowledge of
        LASA); when several robot concepts have it, the one with the most
        numSamples.

    Returns
    -------
    str
        A robot concept label of ``memory``.

    Raises
    ------
    InvalidInputError
        The memory is empty, or ``name`` is neither (lists what is known).
    """
    labels = memory.concepts()
    if not labels:
        raise InvalidInputError("the memory holds no concept yet: teach the robot first "
                                "(`iloci teach`).")
    if name in labels:
        return name

    named = majority_names(memory.concept_members(concept_of_key))
    matches = [label for label, true in named.items() if true == name]
    if matches:
        return max(matches, key=memory.num_samples_of)
    known = [f"{label} ({named[label]})" if named.get(label) else label for label in labels]
    choices = labels + sorted({t for t in named.values() if t})
    raise InvalidInputError(
        f"the memory holds no concept {name!r}; its concepts are {', '.join(known)}."
        f"{did_you_mean(name, choices)}")


@dataclass(frozen=True)
class DrawResult:
    """What :func:`draw` produced.

    Attributes
    ----------
    concept : str
        The robot's concept label drawn.
    response : Response
        The regenerated answer (generated pen path and joint path).
    execution : Execution
        What the simulator executed.
    clipped_rad : float
        Largest amount (rad) by which the generated joint path left the
        robot's joint limits and was clipped back before execution (0 when
        it did not).
    tracking_error_m : float
        Largest distance (m) between the pen tip the simulated arm reached
        and the one the commanded joint path puts it at (the IK solver's
        forward kinematics): the simulator's tracking error.
    sensory_gap_m : float
        Largest distance (m), in the drawing plane, between the drawn path
        and the pen path the network generated alongside the joints. The
        network predicts both; nothing forces them to agree.
    """

    concept: str
    response: Response
    execution: Execution
    clipped_rad: float
    tracking_error_m: float
    sensory_gap_m: float


def draw(memory: Any, perceptual_model: PerceptualModel, ik_solver: IKSolver,
         sensorimotor: Any, concept: str, simulator: Simulator) -> DrawResult:
    """Regenerate ``concept`` from a memory and execute it in ``simulator``.

    The concept's entry of lowest generation error is performed (the answer
    the robot gives a teacher, :meth:`~iloci.agent.Agent.respond`), its
    joint path clipped to the robot's joint limits and executed.

    Parameters
    ----------
    memory : Memory
        With a fitted encoder.
    perceptual_model : PerceptualModel
        The memory's network (its state loaded).
    ik_solver : IKSolver
        The memory's IK solver: its joint limits clip the generated path,
        its forward kinematics measure the tracking error.
    sensorimotor : SensorimotorConfig
        The memory's ``[sensorimotor]`` settings. The robot and its plane are
        the IK solver's ``robot`` (the Nao preset when it has none).
    concept : str
        A robot concept label or a true concept (see :func:`resolve_concept`).
    simulator : Simulator

    Returns
    -------
    DrawResult

    Raises
    ------
    InvalidInputError
        No such concept in the memory.
    """

    label = resolve_concept(memory, concept)
    response = perform(memory, perceptual_model, memory.performer_of(label),
                       joint_limits=ik_joint_limits(ik_solver))
    entry = memory.entries[response.extra["entry"]]
    robot = getattr(ik_solver, "robot", None) or get_robot()
    q = np.asarray(response.joint_path, dtype=np.float64)
    # the network may generate a little past a joint limit; the arm stops there
    q_safe = np.clip(q, robot.lower, robot.upper)
    clipped = float(np.abs(q - q_safe).max()) if q.size else 0.0
    execution = simulator.execute(q_safe, entry.dt)
    reached = np.asarray(execution.end_effector)
    commanded = np.asarray(ik_solver.forward(q_safe))
    tracking = float(np.linalg.norm(reached - commanded, axis=1).max())
    drawn = robot.plane.to_2d(reached)
    gap = float(np.linalg.norm(drawn - np.asarray(response.motion), axis=1).max())
    return DrawResult(label, response, execution, clipped, tracking, gap)


def gif_frames(simulator: Simulator, execution: Execution, width: int, height: int,
               max_frames: int = MAX_GIF_FRAMES) -> tuple[list[np.ndarray], float]:
    """Pictures of the drawing unfolding, and the seconds between two of them.

    At most ``max_frames`` prefixes of ``execution``, evenly spaced, the
    last being the whole drawing; each rendered (height, width, 3) uint8.
    """
    T = len(execution.joint_path)
    stride = max(1, int(np.ceil(T / max_frames)))
    ends = list(range(1, T, stride)) + [T]
    frames = [simulator.render(Execution(execution.joint_path[:k], execution.end_effector[:k],
                                         execution.dt), width, height) for k in ends]
    return frames, execution.dt * stride


def _pillow(what: str):
    try:
        from PIL import Image
    except ImportError:
        raise MissingBackendError("image writer", what, ["Pillow"],
                                  "pip install pillow  (or: pip install 'iloci[plot]')") from None
    return Image


def _rgb(image: Any) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InvalidInputError(f"an RGB image has shape (H, W, 3), got {img.shape}.")
    return np.ascontiguousarray(img, dtype=np.uint8)


def write_png(path: str | os.PathLike[str], image: np.ndarray) -> Path:
    """Write an RGB image to a PNG file, atomically (Pillow).

    Parameters
    ----------
    path : path-like
        Parent directories are created.
    image : ndarray, shape (H, W, 3), uint8

    Raises
    ------
    InvalidInputError
        Not an (H, W, 3) image.
    MissingBackendError
        Pillow is not installed.
    """
    Image = _pillow("png")
    buf = io.BytesIO()
    Image.fromarray(_rgb(image)).save(buf, format="PNG")
    data = buf.getvalue()
    return write_atomic(path, lambda fh: fh.write(data), mkdir=True)


def write_gif(path: str | os.PathLike[str], frames: list[np.ndarray],
              frame_seconds: float) -> Path:
    """Write RGB frames as a looping GIF, atomically (Pillow).

    Parameters
    ----------
    frames : list of ndarray, each (H, W, 3) uint8
    frame_seconds : float
        Time between frames (s), rounded to GIF's 10 ms units, at least
        20 ms (browsers show shorter delays as 100 ms). The last frame is
        held for at least 1.5 s.
    """
    Image = _pillow("gif")
    images = [Image.fromarray(_rgb(f)) for f in frames]
    ms = max(20, round(frame_seconds * 1000 / 10) * 10)
    durations = [ms] * (len(images) - 1) + [max(ms, 1500)]  # hold the finished drawing
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:],
                   duration=durations, loop=0, optimize=False)
    data = buf.getvalue()
    return write_atomic(path, lambda fh: fh.write(data), mkdir=True)


class DrawingParts(NamedTuple):
    """What :func:`draw` needs of a memory file (see :func:`load_drawing_parts`)."""

    memory: Any
    perceptual_model: PerceptualModel
    ik_solver: IKSolver
    sensorimotor: Any


#: Why drawing needs each component it builds from a memory (besides the simulator).
_NEEDED = {
    "perceptual_model": "holds the network of perceptual model {!r}, which regenerates the "
                        "concept",
    "ik": "was taught with IK solver {!r}, whose forward kinematics measure the tracking "
          "error",
}


def saved_section(saved: dict, section: str, registry: Any, source: str) -> tuple[Any, Any]:
    """``(spec, validated params)`` of component ``section`` in a memory's saved config.

    Only this section is resolved: a back end the memory names elsewhere
    (its clusterer, say) or a default one need not be installed.

    Raises
    ------
    ConfigError
        The section is not a table or names no component.
    UnknownComponentError, MissingBackendError
        Its component is not installed.
    """

    values = saved.get(section) or {}
    if not isinstance(values, dict):
        raise ConfigError(f"[{section}] of the saved config must be a table, got {values!r}.",
                          source=source, key=section)
    values = dict(values)
    name = values.pop("name", DEFAULT_NAMES[section])  # as load_config reads it
    if not isinstance(name, str) or name == "none":
        raise ConfigError(f"{section}.name of the saved config must name a component, got "
                          f"{name!r}.", source=source, key=f"{section}.name")
    spec = registry.get(section, name)
    return spec, validate_params(spec, values, source=source)


def _saved_name(saved: dict, section: str) -> object:

    values = saved.get(section)
    return (values if isinstance(values, dict) else {}).get("name", DEFAULT_NAMES[section])


def load_drawing_parts(memory_path: str | os.PathLike[str], *, registry: Any = None,
                       loaded: tuple | None = None) -> DrawingParts:
    """The memory of a file with its network and IK solver, and nothing else.

    Parameters
    ----------
    memory_path : path-like
        A file written by ``iloci teach`` (:meth:`~iloci.agent.Agent.save`).
    registry : Registry, optional
        Defaults to the installed plugins'.
    loaded : tuple, optional
        What :func:`~iloci.concepts.memory.load_memory` returned for the
        file, when the caller has read it already.

    Returns
    -------
    DrawingParts
        ``(memory, perceptual_model, ik_solver, sensorimotor)``, the
        first arguments of :func:`draw`.

    Raises
    ------
    MissingBackendError, UnknownComponentError
        The memory's perceptual model or IK solver is not installed; the
        message says why drawing needs it, then what to install.
    MemoryFileError
        The file holds no config, or its network does not fit the model.
    """

    source = str(memory_path)
    if registry is None:
        registry = get_registry()
    memory, net_state, header = loaded if loaded is not None else load_memory(memory_path)
    saved = header.get("config")
    if not isinstance(saved, dict):
        raise MemoryFileError(f"{source} holds no config: it names no perceptual model to "
                              "regenerate its concepts with.")
    saved = upgrade_config(saved)
    robot_cfg = validate_dataclass(RobotConfig, dict(saved.get("robot") or {}),
                                   section="robot", source=source)

    def why(section: str, name: object) -> str:
        return f"{source} {_NEEDED[section].format(name)}, so drawing needs it: "

    specs = {}
    for section in _NEEDED:
        try:
            specs[section] = saved_section(saved, section, registry, source)
        except (MissingBackendError, UnknownComponentError) as exc:
            raise exc.with_context(why(section, _saved_name(saved, section))) from None
    sensorimotor = validate_dataclass(SensorimotorConfig, dict(saved.get("sensorimotor") or {}),
                                      section="sensorimotor", source=source)
    seed = validate_dataclass(EvaluationConfig, dict(saved.get("evaluation") or {}),
                              section="evaluation", source=source).seed
    def build(section: str, robot: Any = None) -> Any:
        spec, params = specs[section]
        try:
            # the IK solver draws with the memory's robot
            extra = {"robot": robot} if section == "ik" else {}
            return registry.build(spec.kind, spec.name, params, seed=seed, **extra)
        except MissingBackendError as exc:  # registered, but its library is missing
            raise exc.with_context(why(section, spec.name)) from None

    components = {section: build(section) for section in specs if section != "ik"}
    _, components["ik"] = robot_and_ik(robot_cfg, lambda robot: build("ik", robot))
    model = components["perceptual_model"]
    if net_state:
        try:
            model.load_state(net_state)
        except (ValueError, KeyError, InvalidInputError) as exc:
            raise MemoryFileError(f"the network saved in {source} does not fit the "
                                  f"configured perceptual model: {exc}") from None
    return DrawingParts(memory, model, components["ik"], sensorimotor)
