"""Sdists and wheels of the kernel and every plugin: build, install, smoke test.

``tox -e wheels`` runs the three steps (CI runs that env)::

    python .ci/wheels.py build DIST      # python -m build for each distribution
    python .ci/wheels.py install DIST    # pip install the wheels (and nothing editable)
    python .ci/wheels.py smoke           # from outside the source tree: imports, plugins,
                                         # a one-fold tiny evaluation

A distribution is every directory with a ``pyproject.toml``: the repository
root (the kernel), ``plugins/*`` and ``docs/examples/*``. ``python -m build``
makes the sdist and then the wheel *from the sdist*, so a file missing from an
sdist fails here.
"""

from __future__ import annotations

import json
from pathlib import Path
import subprocess
import sys
import tempfile

ROOT = Path(__file__).resolve().parent.parent


def distributions() -> list[Path]:
    """The kernel first, then every plugin and example plugin, sorted."""
    found = sorted(p.parent for pattern in ("plugins/*/pyproject.toml",
                                            "docs/examples/*/pyproject.toml")
                   for p in ROOT.glob(pattern))
    return [ROOT, *found]


def build(dist: Path) -> None:
    dist.mkdir(parents=True, exist_ok=True)
    for src in distributions():
        print(f"== build {src.relative_to(ROOT.parent)}", flush=True)
        subprocess.run([sys.executable, "-m", "build", "--outdir", str(dist), str(src)],
                       check=True, stdout=subprocess.DEVNULL)
    made = sorted(p.name for p in dist.iterdir())
    wheels = [n for n in made if n.endswith(".whl")]
    sdists = [n for n in made if n.endswith(".tar.gz")]
    print("\n".join(made))
    if len(wheels) != len(distributions()) or len(sdists) != len(distributions()):
        sys.exit(f"expected {len(distributions())} wheels and sdists, got {len(wheels)} "
                 f"wheels and {len(sdists)} sdists in {dist}")


def install(dist: Path) -> None:
    wheels = sorted(str(p) for p in dist.glob("*.whl"))
    kernel = next(w for w in wheels if Path(w).name.startswith("iloci-0"))
    # example-robot-data (130 MB of meshes) only where the presets are used
    # (tox -e robots): iloci-robots' wheel goes in without its dependencies
    robots = [w for w in wheels if Path(w).name.startswith("iloci_robots-")]
    # the kernel's extras that the plugins' tests and the smoke test use
    args = [f"iloci[report] @ file://{kernel}"] + [w for w in wheels
                                                   if w != kernel and w not in robots]
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", *args,
                    "torch==2.13.0"], check=True)
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", *robots],
                   check=True)


def smoke() -> None:
    import importlib.metadata as md

    names = [md.distribution(n) for n in ("iloci", "iloci-native", "iloci-torch", "iloci-jax",
                                          "iloci-scipy", "iloci-sklearn", "iloci-pinocchio",
                                          "iloci-pybullet", "iloci-mujoco", "iloci-ray",
                                          "iloci-robots", "iloci-ros")]
    for d in names:
        direct = d.read_text("direct_url.json")
        if direct and json.loads(direct).get("dir_info", {}).get("editable"):
            sys.exit(f"{d.metadata['Name']} is an editable install, not the wheel")
    with tempfile.TemporaryDirectory() as tmp:
        # outside the source tree, so `import iloci` finds the installed wheel
        code = ("import iloci, iloci_native, sys; "
                "assert 'site-packages' in iloci.__file__, iloci.__file__; "
                "print('iloci', iloci.__version__, 'from', iloci.__file__)")
        subprocess.run([sys.executable, "-c", code], cwd=tmp, check=True)
        subprocess.run(["iloci", "plugins"], cwd=tmp, check=True)
        # a plugin's command is on the command line
        subprocess.run(["iloci", "sweep", "--help"], cwd=tmp, check=True,
                       stdout=subprocess.DEVNULL)
        subprocess.run(["iloci", "ros", "--help"], cwd=tmp, check=True,
                       stdout=subprocess.DEVNULL)
        # a plugin's robot presets are listed (their meshes need example-robot-data)
        listed = subprocess.run(["iloci", "robots", "--json"], cwd=tmp, check=True,
                                capture_output=True, text=True).stdout
        robot_names = {r["name"] for r in json.loads(listed)}
        if not {"nao-v32-right-arm", "panda", "ur5"} <= robot_names:
            sys.exit(f"iloci robots lists {sorted(robot_names)}: the iloci-robots presets "
                     "are missing")
        subprocess.run(["iloci", "evaluate", "--config", str(ROOT / "docs/examples/tiny.toml"),
                        "--folds", "0", "--jobs", "1", "--no-baseline", "--quiet",
                        "--out", str(Path(tmp) / "run")], cwd=tmp, check=True)
        metrics = json.loads((Path(tmp) / "run/metrics.json").read_text())
        print(f"smoke evaluation: fold 0 CCR {100 * metrics['ccr_mean']:.1f} %")


if __name__ == "__main__":
    step = sys.argv[1] if len(sys.argv) > 1 else ""
    if step == "build" and len(sys.argv) == 3:
        build(Path(sys.argv[2]))
    elif step == "install" and len(sys.argv) == 3:
        install(Path(sys.argv[2]))
    elif step == "smoke":
        smoke()
    else:
        sys.exit(__doc__)
