"""The Agent: assembled components plus the robot's memory; the library's face.

::

    agent = iloci.build("my.toml")
    report = agent.teach(iloci.data.load_lasa(["GShape", "Angle"]))  # with feedback
    answers = agent.recognize(test_demos)                           # batched inference
    agent.save("memory.npz")
    agent = iloci.Agent.load("memory.npz")                          # and keep teaching

Where each part lives (each module imports only those above it):

- :mod:`~iloci.agent.assembly`: :func:`~iloci.agent.assembly.assemble`, the
  one assembly of an agent's parts from a config (the robot's plane placed
  once), :func:`preload`, :data:`PURPOSES`;
- :mod:`~iloci.agent.base`: the components, memory, lock and the plumbing
  every phase shares (a demonstration as a motion, encoded; the learner);
- :mod:`~iloci.agent.stepwise`: the learning phase (``observe``,
  ``feedback``, ``aobserve``, ``learn``, ``teach``);
- :mod:`~iloci.agent.inference`: the inference phase (``recognize``,
  ``entry_drawings``, ``respond``);
- :mod:`~iloci.agent.worker_process`: the network in a worker process;
- :mod:`~iloci.agent.persistence`: ``save``, ``load``;
- :mod:`~iloci.agent.controls`: a person's controls over the memory
  (``snapshot``, ``restore``, ``forget_concept``, ``forget_entry``,
  ``start_over``, ``replace_memory``, ``drawing_in_frame``), what the web
  page uses;
- :mod:`~iloci.agent.core`: :class:`Agent`, joining them, and :func:`build`.
"""

from iloci.agent.assembly import PURPOSES, NotLoaded, preload, size_network
from iloci.agent.core import Agent, build, learn_and_recognize
from iloci.agent.stepwise import SkippedDemonstrationWarning, TeachReport

__all__ = ["Agent", "build", "preload", "NotLoaded", "PURPOSES", "TeachReport",
           "SkippedDemonstrationWarning", "learn_and_recognize", "size_network"]
