"""The :class:`Agent` and :func:`build`: the agent's faces joined, assembled from a config."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import pluggy

from iloci.agent.assembly import assemble
from iloci.agent.controls import Controls
from iloci.agent.inference import Inference
from iloci.agent.persistence import Persistence
from iloci.agent.stepwise import Stepwise, TeachReport
from iloci.agent.worker_process import WorkerProcess
from iloci.interfaces import Demonstration

__all__ = ["Agent", "build", "learn_and_recognize"]


class Agent(Stepwise, Inference, WorkerProcess, Controls, Persistence):
    """A robot that learns concepts by imitation.

    Built by :func:`build` from a :class:`~iloci.config.Config`. Holds one
    instance of each configured component.

    Attributes
    ----------
    config : Config
    perceptual_model : PerceptualModel
    clusterer : Clusterer
    teacher : Teacher
    ik_solver : IKSolver
    simulator : Simulator or None
    plugin_manager : pluggy.PluginManager
        Observer hooks (``iloci_on_*``) are called through it.
    memory : Memory
        The robot's Mem (entries, encoder); the network is
        ``perceptual_model``. Empty until the first :meth:`learn`.

    Notes
    -----
    The learning phase is :class:`~iloci.agent.stepwise.Stepwise`'s
    (:meth:`observe`, :meth:`feedback`, :meth:`learn`, :meth:`teach`), the
    inference phase :class:`~iloci.agent.inference.Inference`'s
    (:meth:`recognize`, :meth:`respond`), the worker process
    :class:`~iloci.agent.worker_process.WorkerProcess`'s and saving and
    loading :class:`~iloci.agent.persistence.Persistence`'s.
    """


def build(config: Any = None, *, plugin_manager: pluggy.PluginManager | None = None,
          **overrides: Any) -> Agent:
    """Assemble an :class:`Agent` from a config.

    Parameters
    ----------
    config : Config, path, mapping or None
        Anything :func:`~iloci.config.load_config` takes; ``None`` for the
        defaults (the paper's settings).
    plugin_manager : pluggy.PluginManager, optional
        Defaults to :func:`~iloci.plugins.get_plugin_manager`. Component
        names are resolved through its plugins.
    **overrides
        Component instances to use instead of building them from the config,
        by section name (``teacher=my_teacher``, ``ik=my_solver``): how an
        embedding robot stack plugs in its own objects. The configured name
        of a section given this way is never looked up, so it need not be
        registered nor its back end installed; the section is kept in
        ``agent.config`` as written, its other keys unvalidated. Each object
        must have the members of its protocol in :mod:`iloci.interfaces`.
        ``simulator=None`` leaves the simulator out.

    Raises
    ------
    InvalidInputError
        An override is not an instance with its protocol's members (one
        error naming every such override and what it lacks), or is ``None``
        for a component other than the simulator.
    ConfigError, UnknownComponentError
        Invalid config, or an unknown override name (before anything heavy
        is imported).
    MissingBackendError
        A configured back end, of a component not given as an object, is
        not installed (names the pip command).
    """
    return Agent(*assemble(config, plugin_manager, overrides))


def learn_and_recognize(config: Any, learn: Iterable[Demonstration],
                        test: Sequence[Demonstration], *,
                        plugin_manager: pluggy.PluginManager | None = None,
                        **overrides: Any) -> tuple[Agent, TeachReport, list[Any]]:
    """One learning phase then one batched inference phase, on a fresh agent.

    What an evaluation fold does: build an agent from ``config``, teach it
    ``learn`` in order with the configured teacher, then recognize ``test``.

    Returns
    -------
    agent : Agent
    report : TeachReport
    recognitions : list of Recognition
        One per test demonstration, in order.
    """
    agent = build(config, plugin_manager=plugin_manager, **overrides)
    report = agent.teach(learn)
    return agent, report, (agent.recognize(list(test)) if len(test) else [])
