"""The agent's network in a worker process, so the embedding program keeps its timing.

:meth:`~WorkerProcess.start_worker` moves recognition, generation and every
rehearsal of the perceptual model into one process of its own
(:class:`~iloci.worker.WorkerModel`); :meth:`~WorkerProcess.close` copies the
network back and stops it.
"""

from __future__ import annotations

from typing import Any, Self



from iloci.agent.base import AgentBase
from iloci.worker import WorkerModel

__all__ = ["WorkerProcess"]


class WorkerProcess(AgentBase):
    """Starting and stopping the worker process of :class:`~iloci.agent.Agent`."""

    # -- worker process ------------------------------------------------------------
    def start_worker(self) -> Self:
        """Run the network's computations in a worker process from now on.

        Recognition, generation and every rehearsal then run in one
        process of their own (:class:`~iloci.worker.WorkerModel`): the
        calling thread waits on a pipe without holding the GIL, so the rest
        of the embedding program (a control loop, an asyncio server) keeps
        its timing while the robot learns. Results are identical to
        in-process ones (the worker holds the same network). Preprocessing
        and IK stay in the caller. Idempotent; returns the agent.

        The perceptual model must pickle (both first-party back ends do).
        Stop it with :meth:`close` (or use the agent as a context manager);
        the worker's network is copied back first.
        """
        with self._lock:
            if self._worker is None:
                self._worker = WorkerModel(self.perceptual_model)
                self._local_model = self.perceptual_model
                self.perceptual_model = self._worker
        return self

    def close(self) -> None:
        """Stop the worker process, if any, keeping its network (idempotent)."""
        with self._lock:
            worker, self._worker = self._worker, None
            if worker is None:
                return
            try:
                self._local_model.load_state(worker.state())
            finally:
                self.perceptual_model = self._local_model
                worker.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
