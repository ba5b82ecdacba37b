"""A perceptual model whose computations run in a worker process.

Training an RNNPB takes seconds and holds Python's GIL for long stretches,
so learning in a thread of a robot program stalls that program's own
threads (a 100 Hz control loop ran 43-117 ms late). :class:`WorkerModel`
moves the network into a process of its own: it is a
:class:`~iloci.interfaces.PerceptualModel` whose every method sends its
arguments over a pipe to one worker process holding the network, and waits
for the result; waiting on a pipe releases the GIL. The learner, the memory
and everything else stay in the caller, unchanged: the same code runs with
either model, and gives the same results (the worker holds a copy of the
same network, made by pickling it once, over the pipe to our own child).

``Agent.start_worker()`` installs one; ``Agent.close()`` copies its
network back and stops it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from multiprocessing.connection import Connection
import os
import pickle
import subprocess
import sys
import threading
from typing import Any

import numpy as np

from iloci.errors import IlociError

__all__ = ["WorkerModel", "WorkerError"]

#: The model methods a WorkerModel forwards.
METHODS = ("train", "recognize", "generate", "prediction_error", "state", "load_state")


class WorkerError(IlociError, RuntimeError):
    """The worker process failed or died (its exception's text is in the message)."""


class _Channel:
    """Two one-way pipes as one channel of plain pickles.

    Plain :mod:`pickle`, not ``multiprocessing``'s: torch registers
    reductions there that share tensors through a resource server this
    worker (started by ``subprocess``) cannot authenticate with.
    """

    def __init__(self, recv: Connection, send: Connection) -> None:
        self._r, self._w = recv, send

    def send(self, obj: Any) -> None:
        self._w.send_bytes(pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))

    def recv(self) -> Any:
        return pickle.loads(self._r.recv_bytes())

    def close(self) -> None:
        for c in (self._r, self._w):
            if not c.closed:
                c.close()


def _serve(conn: Any) -> None:  # pragma: no cover - runs in the worker process
    """The worker's loop: receive the model, call its methods until told to stop."""
    # never train at a real-time priority inherited from a control loop
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    try:
        model = conn.recv()
    except (EOFError, OSError):
        return
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return
        if message is None:
            return
        method, args, kwargs = message
        try:
            value = getattr(model, method)(*args, **kwargs)
            extra: dict[str, Any] = {
                "train_loss_": float(getattr(model, "train_loss_", float("nan")))}
            if method == "load_state":   # a state brings its own settings
                extra["params"] = getattr(model, "params", None)
            reply = (True, value, extra)
        except BaseException as exc:  # sent back to the caller
            try:
                pickle.dumps(exc)
                reply = (False, exc, {})
            except Exception:
                reply = (False, WorkerError(f"{type(exc).__name__}: {exc}"), {})
        try:
            conn.send(reply)
        except (OSError, BrokenPipeError):
            return


class WorkerModel:
    """A :class:`~iloci.interfaces.PerceptualModel` computed in one worker process.

    Parameters
    ----------
    model : PerceptualModel
        Copied into the worker (pickled over the pipe); the worker's copy
        is the network from then on: read it back with :meth:`state`.

    The worker is a fresh interpreter (``python -m iloci.worker``) talking
    over two private pipes: safe with threads and with JAX or torch loaded,
    and it never re-imports the caller's main script (so a script needs no
    ``if __name__ == "__main__"`` guard). The model's class must be
    importable there (the first-party back ends are).

    Attributes
    ----------
    input_size, pb_size : int
        As the model's.
    params : object
        The model's ``params`` (when it has them), as the worker's model
        holds them after the last :meth:`load_state`.
    train_loss_ : float
        The worker model's ``train_loss_`` after the last call.

    Calls are serialised (one at a time, any thread). An exception raised
    in the worker is raised in the caller as itself (iloci errors pickle);
    if the worker dies, :class:`WorkerError`.
    """

    def __init__(self, model: Any) -> None:
        self.input_size = int(model.input_size)
        self.pb_size = int(model.pb_size)
        self.params = getattr(model, "params", None)
        self.train_loss_ = float(getattr(model, "train_loss_", float("nan")))
        self._name = type(model).__name__
        to_child_r, to_child_w = os.pipe()
        to_parent_r, to_parent_w = os.pipe()
        env = dict(os.environ)
        # the child imports what this process imports (a source tree, a test path)
        env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
        try:
            self._proc = subprocess.Popen(
                # not ``-m iloci.worker``: ``import iloci`` imports this module, and
                # runpy then warns ("found in sys.modules ... prior to execution")
                # on every start, on the person's terminal
                [sys.executable, "-c", "import sys; from iloci.worker import _main; "
                 "_main(sys.argv[1:])", str(to_child_r), str(to_parent_w)],
                pass_fds=(to_child_r, to_parent_w), env=env, stdin=subprocess.DEVNULL)
        finally:
            os.close(to_child_r)
            os.close(to_parent_w)
        self._conn = _Channel(Connection(to_parent_r, writable=False),
                              Connection(to_child_w, readable=False))
        self._lock = threading.Lock()
        self._closed = False
        try:
            self._conn.send(model)
        except Exception as exc:
            self.close()
            raise WorkerError(f"cannot copy {self._name} into the worker process ({exc}); "
                              "run without a worker.") from None

    def __repr__(self) -> str:
        return f"WorkerModel({self._name}, pid={self._proc.pid})"

    @property
    def pid(self) -> int | None:
        """Process id of the worker."""
        return self._proc.pid

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            if self._closed:
                raise WorkerError("the worker process was closed; start a new one "
                                  "(Agent.start_worker()).")
            try:
                self._conn.send((method, args, kwargs))
                ok, value, extra = self._conn.recv()
            except (EOFError, OSError, BrokenPipeError) as exc:
                self._closed = True
                raise WorkerError(f"the worker process running {self._name} died "
                                  f"(exit code {self._proc.poll()}; {exc!r}). The memory "
                                  "is as it was before the call; restart the worker.") from None
        if not ok:
            raise value
        self.train_loss_ = extra.get("train_loss_", float("nan"))
        if "params" in extra:
            self.params = extra["params"]
        return value

    # -- PerceptualModel -----------------------------------------------------------
    def train(self, sequences: Sequence[np.ndarray], pbs_init: np.ndarray | None = None,
              epochs: int | None = None, *, learning_rate: float | None = None
              ) -> np.ndarray:
        # ``learning_rate`` (RNNPB back ends, a rehearsal's rate) is passed on
        # only when given: a model without that argument trains as before
        if learning_rate is None:
            return self._call("train", list(sequences), pbs_init, epochs)
        return self._call("train", list(sequences), pbs_init, epochs,
                          learning_rate=learning_rate)

    def recognize(self, sequences: Sequence[np.ndarray],
                  candidate_pbs: np.ndarray | None = None) -> np.ndarray:
        return self._call("recognize", list(sequences), candidate_pbs=candidate_pbs)

    def generate(self, pbs: np.ndarray, initial_inputs: np.ndarray,
                 lengths: Sequence[int]) -> list[np.ndarray]:
        return self._call("generate", pbs, initial_inputs, list(lengths))

    def prediction_error(self, sequences: Sequence[np.ndarray],
                         pbs: np.ndarray) -> np.ndarray:
        return self._call("prediction_error", list(sequences), pbs)

    def state(self) -> dict[str, np.ndarray]:
        return self._call("state")

    def load_state(self, state: Mapping[str, np.ndarray]) -> None:
        self._call("load_state", dict(state))

    # -- lifetime --------------------------------------------------------------------
    def close(self, timeout: float = 10.0) -> None:
        """Stop the worker process (idempotent)."""
        with self._lock:
            if not self._closed:
                self._closed = True
                try:
                    self._conn.send(None)
                except (OSError, BrokenPipeError):
                    pass
            try:
                self._proc.wait(timeout)
            except subprocess.TimeoutExpired:  # pragma: no cover - a stuck back end
                self._proc.terminate()
                self._proc.wait(timeout)
            self._conn.close()

    def __del__(self) -> None:  # pragma: no cover - best effort at interpreter exit
        try:
            if not self._closed:
                self._conn.send(None)
        except Exception:
            pass


def _main(argv: list[str]) -> None:  # pragma: no cover - the worker process
    """The worker process: ``argv`` = [the fd it reads from, the fd it writes to]."""
    _serve(_Channel(Connection(int(argv[0]), writable=False),
                    Connection(int(argv[1]), readable=False)))


if __name__ == "__main__":  # pragma: no cover - the worker process
    _main(sys.argv[1:])
