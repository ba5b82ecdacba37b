"""Where folds run: the local executor (joblib's loky pool), executor names, progress."""

from __future__ import annotations

import io
import os
from pathlib import Path
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from iloci.errors import InvalidInputError, MissingBackendError, UnknownComponentError
from iloci.evaluation.executors import LocalExecutor, make_executor
from iloci.plugins import get_plugin_manager
from iloci.display import FoldProgress

# Worker functions live in a module the workers import by name.
WORKER = '''
import os, time
from iloci.errors import UnknownComponentError

def nap(x, queue):
    time.sleep(x)
    return x

def square(x, queue):
    queue.put({"kind": "note", "x": x, "pid": os.getpid()})
    return x * x

def fail(x, queue):
    raise UnknownComponentError("teacher", "nope", ["oracle"])

def mark(path, queue):
    open(os.path.join(path, f"warm-{os.getpid()}"), "w").close()

def sleep_forever(path, queue):
    open(os.path.join(path, str(os.getpid())), "w").close()
    time.sleep(120)


def children(pid):
    """Process ids whose parent is ``pid`` (Linux /proc)."""
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as fh:
                    if int(fh.read().rsplit(")", 1)[1].split()[1]) == pid:
                        out.append(int(d))
            except (OSError, IndexError, ValueError):
                pass
    return out
'''


@pytest.fixture
def worker_module(tmp_path, monkeypatch):
    (tmp_path / "iloci_test_worker.py").write_text(WORKER)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])]))
    import iloci_test_worker
    return iloci_test_worker


def test_local_executor_runs_every_call_in_workers_and_relays_messages(worker_module):
    notes = []
    out = sorted(LocalExecutor(2).run(worker_module.square, [(k,) for k in range(5)],
                                      notes.append))
    assert out == [0, 1, 4, 9, 16]
    assert sorted(n["x"] for n in notes) == [0, 1, 2, 3, 4]
    assert os.getpid() not in {n["pid"] for n in notes}


def test_follow_up_tasks_run_after_the_tasks_queued_before_them(worker_module):
    sq = worker_module.square
    asked = []

    def then(result):
        asked.append(result)
        return [(sq, (result,))] if result in (4, 9) else []

    # one worker: tasks run in the order they were queued
    out = list(LocalExecutor(1).run_then([(sq, (2,)), (sq, (3,))], lambda m: None, then))
    assert out == [4, 9, 16, 81] and asked == out


def test_an_iloci_error_in_a_worker_reaches_the_caller_as_itself(worker_module):
    with pytest.raises(UnknownComponentError, match="nope"):
        list(LocalExecutor(2).run(worker_module.fail, [(1,), (2,)], lambda m: None))


def test_workers_started_ahead_warm_up_and_then_run_the_calls(tmp_path, worker_module):
    runner, notes = LocalExecutor(2), []
    runner.start(5, warm_up=(worker_module.mark, (str(tmp_path),)))
    out = sorted(runner.run(worker_module.square, [(k,) for k in range(5)], notes.append))
    assert out == [0, 1, 4, 9, 16]
    warm = {int(p.name.split("-")[1]) for p in tmp_path.glob("warm-*")}
    # the warm-up ran in the pool's workers, the ones that ran the calls
    assert warm and os.getpid() not in warm and warm & {n["pid"] for n in notes}


def test_calls_stopped_midway_leave_no_thread_traceback(worker_module, monkeypatch):
    """Ctrl-C (or any error) while calls are still queued kills the workers without
    loky's manager thread printing "Exception in thread ExecutorManagerThread ...
    KeyError" (it did on every Ctrl-C of an evaluation: a fresh user's trial)."""
    import threading

    seen = []
    monkeypatch.setattr(threading, "excepthook", seen.append)
    for _ in range(3):  # the race is loky's: a few tries, as a user pressing Ctrl-C
        runner = LocalExecutor(2)
        calls = runner.run(worker_module.nap, [(0.3,)] * 12, lambda m: None)
        next(calls)              # workers busy, ids still queued
        calls.close()            # what KeyboardInterrupt in the caller's loop does
    assert not seen, [f"{a.thread.name}: {a.exc_type.__name__}" for a in seen]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc is Linux's")
def test_workers_started_for_no_call_are_stopped_by_close(tmp_path, worker_module):
    def pool_workers():
        return [p for p in worker_module.children(os.getpid())
                if b"LokyProcess" in Path(f"/proc/{p}/cmdline").read_bytes()]

    runner = LocalExecutor(2)
    runner.start(2, warm_up=(worker_module.mark, (str(tmp_path),)))
    deadline = time.monotonic() + 120
    while len(list(tmp_path.glob("warm-*"))) < 1 and time.monotonic() < deadline:
        time.sleep(0.1)
    started = pool_workers()
    assert started, "no worker started"
    runner.close()
    runner.close()  # idempotent
    deadline = time.monotonic() + 20
    while set(started) & set(pool_workers()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not set(started) & set(pool_workers()), "close() left the workers running"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_workers_die_with_a_parent_killed_outright(tmp_path, worker_module):
    pids_dir = tmp_path / "pids"
    pids_dir.mkdir()
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        import iloci_test_worker
        from iloci.evaluation.executors import LocalExecutor
        list(LocalExecutor(2).run(iloci_test_worker.sleep_forever,
                                  [({str(pids_dir)!r},), ({str(pids_dir)!r},)], print))
    """)
    parent = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 120
        while len(list(pids_dir.iterdir())) < 2 and time.monotonic() < deadline:
            time.sleep(0.2)
        workers = [int(p.name) for p in pids_dir.iterdir()]
        assert len(workers) == 2, "the workers did not start"
        # and every other process it started (the message queue's server)
        workers += [p for p in worker_module.children(parent.pid) if p not in workers]
        assert len(workers) >= 3
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait()
    deadline = time.monotonic() + 20
    alive = workers
    while alive and time.monotonic() < deadline:
        alive = [p for p in workers if Path(f"/proc/{p}").exists()
                 and "zombie" not in Path(f"/proc/{p}/status").read_text().lower()]
        time.sleep(0.2)
    assert not alive, f"workers {alive} outlived their parent"


def test_executor_names_are_checked():
    pm = get_plugin_manager(autoload=False)
    assert isinstance(make_executor("local", 2, plugin_manager=pm), LocalExecutor)
    with pytest.raises(InvalidInputError, match="unknown executor 'dask'"):
        make_executor("dask", 2, plugin_manager=pm)
    with pytest.raises(InvalidInputError, match="--address"):
        make_executor("local", 2, address="10.0.0.1:6379", plugin_manager=pm)
    # ray is the iloci-ray plugin's: without it, the error says what to install (or, when
    # it is installed but not loaded, why)
    with pytest.raises(MissingBackendError, match=r"pip install \./plugins/iloci-ray|"
                       r"distribution iloci-ray\) is installed but was not loaded"):
        make_executor("ray", 2, plugin_manager=pm)
    with pytest.raises(InvalidInputError, match="jobs must be >= 1"):
        LocalExecutor(0)


def test_unknown_executor_on_the_command_line_exits_2(cli):
    pytest.importorskip("iloci_jax")  # the default config's back ends
    pytest.importorskip("iloci_scipy")
    pytest.importorskip("iloci_pinocchio")
    r = cli("evaluate", "--executor", "dask", "--folds", "0")
    assert r.returncode == 2 and "unknown executor 'dask'" in r.stderr
    assert "Traceback" not in r.stderr


def test_progress_in_a_log_is_plain_lines_at_milestones():
    log = io.StringIO()
    with FoldProgress(log) as bars:
        bars({"kind": "fold_queued", "fold": 0, "total": 8})
        bars({"kind": "fold_start", "fold": 0, "total": 8})
        for step in range(8):
            bars({"kind": "interaction", "fold": 0, "step": step, "total": 8})
        bars({"kind": "fold_done", "fold": 0, "ccr": 0.875, "seconds": 12.0})
    text = log.getvalue()
    assert "\x1b" not in text and "\r" not in text  # no terminal codes in a log
    lines = text.splitlines()
    assert lines[0] == "fold 0: 0/8 demos  learning"
    assert [ln.split()[2] for ln in lines[:-1]] == ["0/8", "2/8", "4/8", "6/8", "8/8"]
    assert lines[-1] == "fold 0: 8/8 demos  done in 12 s, CCR 87.5 %"
