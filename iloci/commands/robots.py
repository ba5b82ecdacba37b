"""``iloci robots``: the robot presets available, and any robot's description.

::

    iloci robots                      # presets: name, joints, source, plane
    iloci robots --show panda         # one robot: URDF, frames, joints, limits, plane
    iloci robots --show -c my.toml    # the robot a config describes (plane placed)
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from iloci.config import load_config
from iloci.errors import InvalidInputError, MissingBackendError, PluginError
from iloci.plugins import get_plugin_manager, get_registry
from iloci.sensorimotor.robots import check_robot, robot_and_ik
from iloci.sensorimotor.robots.urdf import read_urdf


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("robots", help="list the robots available (presets) or describe one",
                       description="List the robot presets (built in and from plugins), or "
                                   "describe one robot: its URDF, frames, joints, limits and "
                                   "drawing plane (placed automatically when it has none).")
    p.add_argument("--show", nargs="?", const="", metavar="NAME",
                   help="describe robot NAME (default: the config's robot)")
    p.add_argument("--config", "-c", help="TOML config whose [robot] to describe with --show")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.show is None:
        registry = get_registry()
        rows = []
        for spec in registry.specs("robot"):  # the registry's robots, with provenance
            status = "available"
            try:
                registry.build("robot", spec.name)
            except MissingBackendError as exc:
                status = f"missing: {exc}"
            except PluginError as exc:  # one plugin's broken preset: listed, not fatal
                status = f"broken: {exc}"
            rows.append({"name": spec.name, "joints": spec.fact("joints"),
                         "source": spec.distribution or "none", "plane": spec.fact("plane"),
                         "plugin": spec.plugin, "status": status, "summary": spec.summary})
        if args.json:
            print(json.dumps(rows, indent=2))
            return 0
        cols = ("name", "joints", "source", "plane", "summary")
        widths = {c: max(len(c), *(len(str(r[c])) for r in rows)) for c in cols}
        print("  ".join(c.upper().ljust(widths[c]) for c in cols).rstrip())
        for r in rows:
            print("  ".join(str(r[c]).ljust(widths[c]) for c in cols).rstrip())
            if r["status"] != "available":
                print(f"  ({r['status']})")
        print("\nUse one with [robot] name = \"...\" in a config, or describe any arm from its "
              "URDF (see docs/robots.md).")
        return 0
    desc = describe(args.show or None, args.config)
    if args.json:
        print(json.dumps(desc, indent=2))
        return 0
    deg = np.degrees
    print(f"robot {desc['name']}: {len(desc['joints'])} joints, URDF {desc['urdf']}")
    print(f"  base frame {desc['base_frame']!r}, pen tip {desc['tip_frame']!r}")
    sliding = _prismatic(desc)
    for j, lo, hi, q in zip(desc["joints"], desc["lower"], desc["upper"], desc["q_home"]):
        if j in sliding:  # a prismatic joint moves in metres: shown in mm
            print(f"  {j:24s} [{1000 * lo:8.1f}, {1000 * hi:8.1f}] mm, start {1000 * q:7.1f}")
        else:
            print(f"  {j:24s} [{deg(lo):8.1f}, {deg(hi):8.1f}] deg, start {deg(q):7.1f}")
    p = desc["plane"]
    c = np.round(np.array(p["center"]) * 1000, 1).tolist()
    print(f"  plane: centre {c} mm, {p['width'] * 1000:.0f} x {p['height'] * 1000:.0f} mm, "
          f"normal {p['normal']}, up {p['up']}")
    rep = desc["plane_report"]
    if rep.get("method") == "auto":
        print(f"  placed automatically: every joint >= {rep['min_joint_margin_deg']:.1f} deg "
              f"inside its limits, smallest Jacobian singular value {rep['min_singular']:.3f} "
              f"m/rad ({rep['min_singular_relative']:.2f} of the best), on a 15 x 15 grid "
              f"grown by {rep['edge_m'] * 1000:.0f} mm")
    else:
        print("  plane given")
    return 0


def describe(name: str | None, config: str | None) -> dict:
    """The description of robot ``name`` (or the config's), its plane placed."""

    pm = get_plugin_manager()
    registry = get_registry(pm)
    cfg = load_config(config, registry=registry)
    robot_cfg = cfg.robot
    if name:
        import dataclasses
        robot_cfg = dataclasses.replace(robot_cfg, name=name, urdf="")
    check_robot(robot_cfg, cfg.simulator.name, pm)
    robot, _ = robot_and_ik(robot_cfg, lambda robot: registry.build(
        "ik", cfg.ik.name, cfg.ik.params, seed=cfg.seed, robot=robot), plugin_manager=pm)
    return robot.describe()


def _prismatic(desc: dict) -> set[str]:
    """The prismatic joints among ``desc``'s (their limits are in m, not rad)."""
    try:
        joints = read_urdf(desc["urdf"]).joints
    except (InvalidInputError, OSError, KeyError):
        return set()
    return {j for j in desc["joints"] if j in joints and joints[j].type == "prismatic"}
