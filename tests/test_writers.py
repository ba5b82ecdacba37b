"""One writer per memory file, under every name of it, and a memory path checked before anything.

Real processes: the holder of a lock is another Python process, and
``iloci serve`` runs as a command in its own process group, stopped as a
service manager or ``timeout`` stops it (a signal to the whole group).
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import time

import pytest

from iloci.errors import InvalidInputError
from iloci.data.writes import check_memory_path
from iloci.progress import MemoryLockedError, acquire_memory_lock

HOLD = ("import sys; from iloci.progress import acquire_memory_lock; "
        "acquire_memory_lock(sys.argv[1], 'iloci serve'); print('held', flush=True); "
        "sys.stdin.read()")


def holder(path: Path) -> subprocess.Popen:
    """Another process holding ``path``'s memory lock until its stdin closes."""
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(path)], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    return p


def test_a_hard_link_to_a_memory_being_taught_is_refused(tmp_path):
    memory = tmp_path / "m.npz"
    memory.write_bytes(b"a memory")
    other_name = tmp_path / "h.npz"
    os.link(memory, other_name)                          # the same file, another name
    p = holder(memory)
    try:
        with pytest.raises(MemoryLockedError, match=f"another name .*pid {p.pid}"):
            acquire_memory_lock(other_name, "iloci teach")
        with pytest.raises(MemoryLockedError, match="iloci serve"):
            acquire_memory_lock(memory, "iloci teach")
    finally:
        p.stdin.close()
        p.wait(30)
    release = acquire_memory_lock(other_name, "iloci teach")   # free once the holder ends
    release()
    # a copy is another file: taught separately while the original is held
    copy = tmp_path / "copy.npz"
    shutil.copy(memory, copy)
    p = holder(memory)
    try:
        acquire_memory_lock(copy, "iloci teach")()
    finally:
        p.stdin.close()
        p.wait(30)


def test_a_memory_path_that_cannot_be_a_memory_is_refused_before_anything(tmp_path):
    loop_a, loop_b = tmp_path / "a.npz", tmp_path / "b.npz"
    loop_a.symlink_to(loop_b.name)
    loop_b.symlink_to(loop_a.name)
    with pytest.raises(InvalidInputError, match="leads back to itself"):
        check_memory_path(loop_a)
    (tmp_path / "dir.npz").mkdir()
    with pytest.raises(InvalidInputError, match="is a directory"):
        check_memory_path(tmp_path / "dir.npz")
    link = tmp_path / "link.npz"
    link.symlink_to(tmp_path / "dir.npz")
    with pytest.raises(InvalidInputError, match="a link to.*is a directory"):
        check_memory_path(link)
    assert check_memory_path(tmp_path / "new" / "m.npz") == tmp_path / "new" / "m.npz"
    assert (tmp_path / "new").is_dir()                     # its folder made, as teach does


def test_serve_refuses_a_symlink_loop_and_teach_says_the_same(tmp_path, cli):
    (tmp_path / "a.npz").symlink_to("b.npz")
    (tmp_path / "b.npz").symlink_to("a.npz")
    serve_installed = all(importlib.util.find_spec(m) for m in ("starlette", "uvicorn"))
    commands = [["teach", "GShape/0"]] + ([["serve", "--port", "1"]] if serve_installed else [])
    for command in commands:                    # serve needs iloci[serve] (not in tox's bare)
        r = cli(command[0], "--memory", str(tmp_path / "a.npz"), *command[1:])
        assert r.returncode == 2, r.stderr
        assert "leads back to itself" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.usefixtures("default_back_ends")
def test_serve_stopped_with_its_process_group_says_so_without_a_traceback(tmp_path):
    """``timeout``, systemd and a closed terminal signal the whole group: the worker
    process stops first. The person sees a line, no traceback, no runpy warning."""
    pytest.importorskip("uvicorn")
    pytest.importorskip("starlette")
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    exe = Path(sys.executable).with_name("iloci")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "iloci"]
    p = subprocess.Popen([*cmd, "serve", "--memory", str(tmp_path / "m.npz"), "--port",
                          str(port)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True, start_new_session=True)
    lines = []
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline:
        line = p.stdout.readline()
        if not line:
            break
        lines.append(line)
        if "teach the robot at" in line:
            break
    assert any("teach the robot at" in x for x in lines), "".join(lines)
    os.killpg(p.pid, signal.SIGTERM)
    rest, _ = p.communicate(timeout=60)
    out = "".join(lines) + rest
    assert "Traceback" not in out, out
    assert "RuntimeWarning" not in out, out
    assert not (tmp_path / "m.npz.lock.json").exists()            # released
