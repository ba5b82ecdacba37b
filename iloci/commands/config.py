"""``iloci config show|check``: the resolved configuration."""

from __future__ import annotations

import argparse
from pathlib import Path

from iloci.agent import size_network
from iloci.config import check_installed, load_config, to_toml
from iloci.data.concepts import LASA_SHAPES
from iloci.errors import InvalidInputError
from iloci.sensorimotor.robots import check_robot


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("config", help="show or check a configuration file")
    csub = p.add_subparsers(dest="config_command", metavar="ACTION", required=True)
    show = csub.add_parser("show", help="print the resolved config (defaults filled in) as TOML")
    show.add_argument("file", nargs="?", help="TOML config (default: the built-in defaults)")
    show.set_defaults(func=run_show)
    check = csub.add_parser(
        "check", help="validate a config file: every key and value, and that every "
                      "configured back end is installed and loaded")
    check.add_argument("file", help="TOML config")
    check.set_defaults(func=run_check)


def run_show(args: argparse.Namespace) -> int:
    print(to_toml(load_config(args.file)), end="")
    return 0


def run_check(args: argparse.Namespace) -> int:
    cfg = load_config(args.file)
    check_installed(cfg)
    size_network(cfg, check_robot(cfg.robot, cfg.simulator.name))
    _check_data(cfg)
    names = ", ".join(f"{sec}={getattr(cfg, sec).name}" for sec in
                      ("perceptual_model", "clusterer", "teacher", "ik", "simulator"))
    print(f"{args.file}: ok ({names})")
    return 0


def _check_data(cfg) -> None:
    """What ``iloci evaluate`` would refuse of the data at its start, said by the check: a
    ``[data] path`` that does not exist; on LASA, more folds than its 7 demonstrations of
    a shape, or ``untaught`` leaving fewer than 2 shapes to teach."""
    if cfg.data.path:
        if not Path(cfg.data.path).expanduser().exists():
            raise InvalidInputError(f"[data] path {cfg.data.path!r} does not exist: give a "
                                    "folder with a sub-folder of trajectory files per concept, "
                                    "or a manifest (.csv or .json).")
        return
    shapes = len(cfg.data.shapes) or len(LASA_SHAPES)
    if cfg.evaluation.folds > 7:
        raise InvalidInputError(f"[evaluation] folds = {cfg.evaluation.folds}: LASA has 7 "
                                "demonstrations of each shape, so at most 7 folds.")
    if cfg.evaluation.untaught and cfg.evaluation.untaught > shapes - 2:
        raise InvalidInputError(f"[evaluation] untaught = {cfg.evaluation.untaught} leaves "
                                f"fewer than 2 of the {shapes} LASA shapes to learn; use at "
                                f"most {shapes - 2}.")
