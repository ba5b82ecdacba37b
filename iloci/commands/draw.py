"""``iloci draw``: the robot draws one of its concepts in a simulator; a PNG or GIF of it.

A thin layer over :mod:`iloci.drawing`: the concept's entry of lowest
generation error is regenerated from its PB, executed on the simulated arm
and rendered (the arm in its last posture with the pen path it drew, or,
with ``--gif``, the drawing unfolding at the motion's own pace). Only the
memory's network and IK solver and the simulator are built.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from iloci.concepts.memory import load_memory
from iloci.data.files import writable_file
from iloci.errors import InvalidInputError
from iloci.plugins import get_registry

__all__ = ["register", "run"]

#: Simulators ``--simulator`` offers (any registered simulator name is accepted).
SIMULATORS = ("pybullet", "mujoco")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "draw", help="let the robot draw a learned concept in a simulator (PNG or GIF)",
        description="Regenerate a concept from a taught memory (its entry of lowest "
                    "generation error), execute the joint path on the simulated Nao arm "
                    "and write an image of the arm and the path its pen drew.")
    p.add_argument("--memory", metavar="FILE", required=True,
                   help="memory file written by `iloci teach`")
    p.add_argument("--concept", metavar="NAME", required=True,
                   help="the robot's concept label (e.g. c3) or, for LASA-taught memories, "
                        "a true LASA concept (e.g. GShape): the robot concept whose "
                        "demonstrations mostly were that shape")
    p.add_argument("--simulator", metavar="NAME",
                   help=f"simulator to draw in ({' or '.join(SIMULATORS)}; default: the "
                        "memory config's simulator, else pybullet)")
    p.add_argument("--out", metavar="FILE", required=True,
                   help="image to write (.png, or .gif with --gif)")
    p.add_argument("--gif", action="store_true",
                   help="write an animated GIF of the drawing")
    p.add_argument("--size", metavar="WxH", default="480x360",
                   help="image size in pixels (default 480x360)")
    p.set_defaults(func=run)


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InvalidInputError(f"--size must be WIDTHxHEIGHT in pixels, e.g. 480x360; got "
                                f"{text!r}.") from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise InvalidInputError(f"--size must be 16..4096 pixels per side, got {text!r}.")
    return w, h


def _simulator_name(args: argparse.Namespace, saved: dict) -> str:
    if args.simulator:
        return args.simulator
    name = (saved.get("simulator") or {}).get("name", "none")
    return name if name != "none" else "pybullet"


def run(args: argparse.Namespace) -> int:
    # drawing imports the learner, hence scipy: loaded when the command runs
    from iloci.drawing import (draw, gif_frames, load_drawing_parts, resolve_concept,
                               saved_section, write_gif, write_png)

    width, height = _parse_size(args.size)
    out = Path(args.out)
    suffix = out.suffix.lower()
    if args.gif and suffix != ".gif":
        raise InvalidInputError(f"--gif writes a GIF: give --out a .gif name, got {out}.")
    if not args.gif and suffix != ".png":
        raise InvalidInputError(f"--out must be a .png file (or use --gif with a .gif), got "
                                f"{out}.")
    writable_file(out, "--out")
    loaded = load_memory(args.memory)
    header = loaded[2]
    config = header.get("config")
    saved: dict = config if isinstance(config, dict) else {}
    name = _simulator_name(args, saved)
    registry = get_registry()
    # resolve the names before loading the network: a typo fails fast, with "did you mean"
    spec = registry.get("simulator", name)
    sim_params = None
    if (saved.get("simulator") or {}).get("name") == name:
        sim_params = saved_section(saved, "simulator", registry, str(args.memory))[1]
    resolve_concept(loaded[0], args.concept)
    parts = load_drawing_parts(args.memory, registry=registry, loaded=loaded)
    # the memory's arm, as its IK solver was built with it (placed plane, start posture)
    robot = getattr(parts.ik_solver, "robot", None)
    simulator = registry.build("simulator", spec.name, sim_params,
                               **({"robot": robot} if robot is not None else {}))
    if not callable(getattr(simulator, "render", None)):
        simulator.close()
        raise InvalidInputError(f"simulator {spec.name!r} renders no images (an executor of a "
                                "real arm); choose one that does with --simulator.")
    try:
        result = draw(*parts, args.concept, simulator)
        ex = result.execution
        if args.gif:
            write_gif(out, *gif_frames(simulator, ex, width, height))
        else:
            write_png(out, simulator.render(ex, width, height))
    finally:
        simulator.close()
    r = result.response
    print(f"concept {result.concept}: entry {r.extra['entry']} (stands for "
          f"{', '.join(r.sources) or r.source or '?'}; generation error "
          f"{r.extra['generation_error']:.3g}), {len(ex.joint_path)} steps of "
          f"{ex.dt:.3f} s in {name}")
    if result.clipped_rad > 0:
        print(f"the generated joint path left the joint limits by up to "
              f"{np.degrees(result.clipped_rad):.1f} deg and was clipped to them")
    print(f"tracking error (reached vs commanded pen tip): max "
          f"{result.tracking_error_m * 1000:.2f} mm; drawn vs the network's generated pen "
          f"path: max {result.sensory_gap_m * 1000:.1f} mm")
    print(f"wrote {out}")
    return 0
