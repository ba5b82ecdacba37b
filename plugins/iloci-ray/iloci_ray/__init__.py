"""iloci plugin: Ray, a distributed execution engine, for many runs at once.

* ``iloci sweep SPEC.toml``: a grid or random search over config values x
  seeds x folds on Ray, resumable (:mod:`iloci_ray.sweep`).
* ``iloci evaluate --executor ray``: an evaluation's folds as Ray tasks
  (:class:`iloci_ray.executor.RayExecutor`).

Both run on Ray started on this machine, or on a running cluster given by
its address (``ray start --head`` prints it).
"""

from iloci import hookimpl


@hookimpl
def iloci_add_commands(subparsers) -> None:
    from iloci_ray.command import register
    register(subparsers)


@hookimpl
def iloci_register_executors(registry) -> None:
    registry.add("ray", "iloci_ray.executor:RayExecutor", requires=("ray",),
                 install="pip install ./plugins/iloci-ray  (from a checkout of iloci)",
                 summary="folds as Ray tasks, on this machine or a running cluster (--address)")
