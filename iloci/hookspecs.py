"""Every pluggy hook specification of iloci.

Three families, all prefixed ``iloci_``:

* **Registration hooks**, one per kind of the registry
  (:data:`iloci.interfaces.ALL_KINDS`: the five components, fold executors,
  robot presets). Each receives a registry view for that kind and adds named
  entries to it; a config (or ``--executor``) then picks one by name. Called
  once each time a plugin manager builds its registry (see
  :func:`iloci.plugins.get_registry`).
* **Observer hooks**, broadcast while learning and evaluating, for progress
  bars, logging, figures and robot-side bookkeeping. Their return values
  are ignored; an exception raised in an observer propagates (observers
  must not fail silently).
* **Extension hooks**: subcommands of the ``iloci`` command line, and the
  deprecated ``iloci_make_executor`` (executors now register like components).

A plugin implements any subset::

    from iloci import hookimpl

    @hookimpl
    def iloci_register_teachers(registry):
        registry.add("replay", "my_pkg.teacher:ReplayTeacher",
                     params=ReplayParams, summary="replays recorded feedback")

Specs may grow new arguments; pluggy passes an implementation only the
arguments it names, so old plugins keep working.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:  # pragma: no cover - for annotations only
    import argparse

    from iloci.events import FoldEvent, InteractionEvent, RehearsalEvent
    from iloci.interfaces import FoldExecutor
    from iloci.registry import KindRegistry

PROJECT = "iloci"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


# -- registration -----------------------------------------------------------

@hookspec
def iloci_register_perceptual_models(registry: KindRegistry) -> None:
    """Register PerceptualModel (RNNPB) implementations.

    Called when the registry is built. ``registry.add(name, factory, ...)``
    registers one; the config section ``[perceptual_model]`` picks it by
    ``name``. See :class:`iloci.interfaces.PerceptualModel`.
    """


@hookspec
def iloci_register_clusterers(registry: KindRegistry) -> None:
    """Register Clusterer implementations (config section ``[clusterer]``).

    See :class:`iloci.interfaces.Clusterer`.
    """


@hookspec
def iloci_register_teachers(registry: KindRegistry) -> None:
    """Register Teacher implementations (config section ``[teacher]``).

    See :class:`iloci.interfaces.Teacher`.
    """


@hookspec
def iloci_register_ik_solvers(registry: KindRegistry) -> None:
    """Register IKSolver implementations (config section ``[ik]``).

    See :class:`iloci.interfaces.IKSolver`.
    """


@hookspec
def iloci_register_simulators(registry: KindRegistry) -> None:
    """Register Simulator implementations (config section ``[simulator]``).

    See :class:`iloci.interfaces.Simulator`.
    """


@hookspec
def iloci_register_executors(registry: KindRegistry) -> None:
    """Register fold executors (``iloci evaluate --executor NAME``).

    ``registry.add(name, factory, requires=..., install=..., summary=...)``
    as for components; the factory is called with ``jobs`` (folds at once)
    and ``address`` (where the executor's engine runs, None: start one on
    this machine) and returns a :class:`iloci.interfaces.FoldExecutor`.
    The kernel registers ``local``; ``iloci-ray`` registers ``ray``.
    """


@hookspec
def iloci_register_robots(registry: KindRegistry, robots: dict) -> None:
    """Register robot presets (config ``[robot] name``; ``iloci robots`` lists them).

    ``registry.add(name, factory, summary=..., joints=J, plane="given" | "auto",
    requires=..., install=...)``, as for components: ``factory`` (a
    ``"module:function"`` string or a callable) returns a
    :class:`iloci.sensorimotor.robots.Robot` (see
    :func:`iloci.sensorimotor.robots.describe_robot`); ``joints`` is its
    ``J``; ``plane`` ``"auto"`` when the drawing plane is placed by the search
    when an agent is built. The kernel registers ``nao-v32-right-arm``;
    ``iloci-robots`` registers ``panda`` and ``ur5``.

    ``robots`` is the old form, deprecated (a DeprecationWarning names the
    plugin): an implementation naming ``robots`` instead of ``registry``
    receives an empty dict, adds ``RobotPreset`` objects to it, and each is
    registered as by ``registry.add``.
    """


# -- observers --------------------------------------------------------------

@hookspec
def iloci_on_interaction(event: InteractionEvent) -> None:
    """Called after each teacher feedback during the learning phase.

    ``event`` says which demonstration was shown, which concept was guessed
    and answered, the feedback, and what the learner did with it.
    """


@hookspec
def iloci_on_rehearsal(event: RehearsalEvent) -> None:
    """Called after each memory rehearsal (retraining of the network).

    ``event`` gives the number of entries, epochs, final loss and seconds.
    """


@hookspec
def iloci_on_fold_finished(event: FoldEvent) -> None:
    """Called when one evaluation fold has finished (learning and inference).

    ``event`` gives the fold index and its metrics.
    """


# -- extensions ---------------------------------------------------------------

@hookspec
def iloci_add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Add subcommands to the ``iloci`` command line.

    Called once when the command line builds its parser, after the
    kernel's own commands. ``subparsers.add_parser(name, help=...)`` adds
    one; set ``func(args) -> int`` on it with ``set_defaults`` (the exit
    code; raise an :class:`~iloci.errors.IlociError` for a user error, exit
    2). A name the kernel or another plugin already uses is an error.
    """


@hookspec(firstresult=True)
def iloci_make_executor(name: str, jobs: int, address: str | None) -> FoldExecutor | None:
    """Return the fold executor called ``name``, or None when this plugin has none.

    Deprecated: register executors with :func:`iloci_register_executors`
    (listed by ``iloci plugins``, with provenance and install hints); this
    hook is still asked first.

    Called by :func:`iloci.evaluation.executors.make_executor` (``iloci
    evaluate --executor NAME``) before the kernel's own ``local``; the
    first non-None result is used. ``jobs`` is the number of folds to run at
    once, ``address`` where the executor's engine runs (None: start one on
    this machine). The result follows
    :class:`iloci.interfaces.FoldExecutor`.
    """
