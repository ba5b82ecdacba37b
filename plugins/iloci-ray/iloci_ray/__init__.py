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
def iloci_make_executor(name, jobs, address):
    if name != "ray":
        return None
    from iloci_ray.executor import RayExecutor
    return RayExecutor(jobs, address=address)
