"""``iloci show``: a demonstration through the sensorimotor path, as a figure; or a memory.

``iloci show MEMORY.npz`` prints what a taught memory holds (entries,
exemplars, prototypes and concepts, counted as every other output counts
them). ``iloci show SHAPE/INDEX`` draws three panels: the raw pen path
(teacher's frame), the path fitted into the robot's drawing plane with the
forward kinematics of the IK solution over it, and the joint angles over
time.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from iloci.concepts.memory import load_memory
from iloci.config import load_config
from iloci.data.files import TRAJECTORY_SUFFIXES, writable_file, write_atomic
from iloci.data.lasa import DEMOS_PER_SHAPE
from iloci.data.streams import resolve_demo
from iloci.errors import InvalidInputError, MissingBackendError
from iloci.plugins import get_plugin_manager, get_registry
from iloci.sensorimotor.pipeline import to_motion
from iloci.sensorimotor.robots import get_robot, robot_and_ik

__all__ = ["plot_motion", "register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "show", help="plot one demonstration: pen path, fitted path + FK of the IK, joints",
        description="Plot a LASA demonstration (or a trajectory file: .npy, .csv, .inkml, "
                    ".xml) as the robot sees it: the raw pen path, the path fitted into the "
                    "drawing plane with the forward kinematics of the IK solution over it, "
                    "and the joint angles over time.")
    p.add_argument("shape", metavar="DEMO",
                   help="LASA demonstration as SHAPE/INDEX (e.g. GShape/3) or SHAPE (its "
                        "first, or --demo), or a trajectory file (.npy, .csv, .inkml, .xml); "
                        "or a memory file (.npz) written by `iloci teach`, to print what it holds")
    p.add_argument("--demo", type=int, default=None, metavar="I",
                   help="demonstration index of a LASA SHAPE, 0..6 (default 0)")
    p.add_argument("--out", metavar="FILE.png",
                   help="image to write (default: SHAPE-I.png in the current directory)")
    p.add_argument("--config", metavar="FILE",
                   help="TOML config whose [ik] and [sensorimotor] sections are used "
                        "(default: the pinocchio IK solver and default settings)")
    p.set_defaults(func=run)


def _load_demo(token: str, demo: int | None):
    """The demonstration ``SHAPE/INDEX``, ``SHAPE`` with ``--demo`` (default 0), or a file."""

    if demo is None:
        return resolve_demo(token)
    if Path(token).suffix.lower() in TRAJECTORY_SUFFIXES or Path(token).is_file():
        raise InvalidInputError(f"--demo picks a demonstration of a LASA shape; {token!r} "
                                "is a trajectory file (drop --demo).")
    if "/" in token:
        raise InvalidInputError(f"give the demonstration once: {token!r} or --demo {demo}, "
                                "not both.")
    if not 0 <= demo < DEMOS_PER_SHAPE:
        raise InvalidInputError(f"--demo must be 0..{DEMOS_PER_SHAPE - 1} for a LASA "
                                f"shape, got {demo}.")
    return resolve_demo(f"{token}/{demo}")


def _components(config_file: str | None):
    """The configured IK solver, sensorimotor settings and robot (plane placed)."""

    pm = get_plugin_manager()
    registry = get_registry(pm)
    cfg = load_config(config_file, registry=registry)
    robot, ik = robot_and_ik(cfg.robot, lambda robot: registry.build(
        "ik", cfg.ik.name, cfg.ik.params, seed=cfg.seed, robot=robot), plugin_manager=pm)
    return ik, cfg.sensorimotor, robot


#: What ``--out`` may be: the formats matplotlib's Agg backend writes.
IMAGE_SUFFIXES = frozenset({".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps",
                            ".tif", ".tiff", ".webp"})


def run(args: argparse.Namespace) -> int:
    if Path(args.shape).suffix.lower() == ".npz":
        return _show_memory(args)

    if args.out and Path(args.out).suffix.lower() not in IMAGE_SUFFIXES:
        raise InvalidInputError(
            f"--out {args.out}: an image's name ends in "
            f"{', '.join(sorted(IMAGE_SUFFIXES))} (the format follows it), e.g. "
            f"{Path(args.out).with_suffix('.png')}.")
    demo = _load_demo(args.shape, args.demo)
    out = writable_file(args.out if args.out else f"{demo.shape}-{demo.index}.png", "--out")
    ik, sm, robot = _components(args.config)
    motion = to_motion(demo, sm, ik, robot)
    reached = np.asarray(ik.forward(motion.joint_path))
    err = np.linalg.norm(reached - motion.targets, axis=1)
    plot_motion(demo, motion, reached, robot, out, y_axis=sm.y_axis)
    q = motion.joint_path
    inside = bool(np.all((q >= ik.lower) & (q <= ik.upper)))
    print(f"{demo.key}: {len(demo)} pen points -> {len(motion)} steps, dt {motion.dt:.3f} s; "
          f"FK error max {err.max() * 1000:.4f} mm; joints within limits: "
          f"{'yes' if inside else 'NO'}")
    print(f"wrote {out}")
    return 0


def _show_memory(args: argparse.Namespace) -> int:
    if args.demo is not None or args.out or args.config:
        raise InvalidInputError("--demo, --out and --config apply to a demonstration, not to "
                                f"a memory file ({args.shape}).")
    memory, _, header = load_memory(args.shape)
    saved = header.get("config")
    config: dict = saved if isinstance(saved, dict) else {}
    names = ", ".join(f"{sec} = {v['name']}" for sec, v in config.items()
                      if isinstance(v, dict) and "name" in v)
    print(f"{args.shape}: {names or 'no saved config'}")
    print(memory.summary())
    return 0


def plot_motion(demo, motion, reached: np.ndarray, robot: Any, out: str | Path,
                y_axis: str = "up") -> Path:
    """Draw the three panels of ``iloci show`` and write them atomically to ``out``.

    Parameters
    ----------
    demo : Demonstration
    motion : Motion
    reached : ndarray, shape (T, 3)
        Forward kinematics of ``motion.joint_path``.
    robot : Robot or str
        The robot (or a preset's name); its drawing plane is drawn, with the
        automatic search's margins when it placed the plane.
    out : path
        Image file; the format follows its suffix (``.png`` by default).
    y_axis : str
        The teacher's y axis, as ``[sensorimotor] y_axis`` reads it: ``"down"``
        (screen coordinates) draws the pen path with y growing downwards, as
        it was drawn, not upside down.

    Returns
    -------
    Path
    """
    try:
        import matplotlib
    except ImportError as exc:
        raise MissingBackendError("command", "show", ["matplotlib"],
                                  "pip install matplotlib") from exc
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    if isinstance(robot, str):
        robot = get_robot(robot)
    plane = robot.plane
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.3))

    ax = axes[0]
    p = demo.positions
    ax.plot(p[:, 0], p[:, 1], "-", color="0.3", lw=1.2)
    ax.plot(*p[0], "o", color="tab:green", label="start")
    ax.plot(*p[-1], "s", color="tab:red", label="end")
    ax.set_title(f"pen path {demo.key} ({len(p)} points)")
    ax.set_xlabel("x (teacher)")
    ax.set_ylabel(f"y (teacher, pointing {'down' if y_axis == 'down' else 'up'})")
    ax.set_aspect("equal", adjustable="datalim")
    if y_axis == "down":
        ax.invert_yaxis()
    ax.legend(fontsize=8)

    ax = axes[1]
    mm = 1000.0
    y0, z0 = plane.corners[0]
    report = robot.plane_report
    label = "drawing plane"
    if report.get("method") == "auto":
        label += (f" (auto: joints >= {report['min_joint_margin_deg']:.0f}° from limits, "
                  f"σmin {report['min_singular_relative']:.2f} of best)")
        grown = plane.grown(report["edge_m"])
        g0 = grown.corners[0]
        ax.add_patch(Rectangle((g0[0] * mm, g0[1] * mm), grown.width * mm, grown.height * mm,
                               fill=False, ls=":", color="0.75", label="checked margin"))
    ax.add_patch(Rectangle((y0 * mm, z0 * mm), plane.width * mm, plane.height * mm,
                           fill=False, ls="--", color="0.6", label=label))
    pp = motion.plane_points * mm
    fk = plane.to_2d(reached) * mm
    ax.plot(pp[:, 0], pp[:, 1], "-", color="tab:blue", lw=1.5, label="fitted path (targets)")
    ax.plot(fk[:, 0], fk[:, 1], "x", color="tab:orange", ms=5, label="FK of IK solution")
    ax.plot(*pp[0], "o", color="tab:green")
    err = np.linalg.norm(reached - motion.targets, axis=1).max()
    ax.set_title(f"{robot.name}: plane {plane.distance * mm:.0f} mm ahead, "
                 f"{plane.width * mm:.0f} x {plane.height * mm:.0f} mm "
                 f"(max FK error {err * 1e6:.2f} µm)", fontsize=10)
    ax.set_xlabel(f"u (mm, {robot.base_frame} frame)")
    ax.set_ylabel(f"up (mm, {robot.base_frame} frame)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=3)

    ax = axes[2]
    t = np.arange(len(motion)) * motion.dt
    for j, name in enumerate(robot.joint_names):
        ax.plot(t, np.rad2deg(motion.joint_path[:, j]), label=name)
    ax.set_title("joint angles")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("angle (deg)")
    ax.legend(fontsize=8)
    fig.tight_layout()

    out = Path(out)
    fmt = out.suffix.lstrip(".").lower() or "png"
    try:
        # a file object has no suffix to infer the format from, hence format=
        write_atomic(out, lambda fh: fig.savefig(fh, format=fmt, dpi=110), mkdir=True)
    finally:
        plt.close(fig)
    return out
