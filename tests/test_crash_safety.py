"""``iloci teach`` survives being killed: resume without learning twice; one teacher at a time.

The kill -9 drill itself (20 SIGKILLs at random moments) is
``benchmarks/teach_kill_drill.py``; these tests pin down its parts.
"""

from __future__ import annotations

import numpy as np
import pytest

from iloci.data import load_lasa
from iloci.progress import (
    MemoryLockedError,
    item_digest,
    prefix_digest,
    progress_record,
    resume_point,
    teaching_lock,
)


def test_item_digest_is_what_the_item_teaches(tmp_path):
    g0, g1 = load_lasa(["GShape"])[:2]
    assert item_digest(g0) == item_digest(load_lasa(["GShape"])[0])
    assert item_digest(g0) != item_digest(g1)
    f = tmp_path / "a.csv"
    f.write_text("x,y\n0,0\n1,1\n2,0\n")
    d1 = item_digest(str(f))
    f.write_text("x,y\n0,0\n1,2\n2,0\n")  # edited: another demonstration
    assert item_digest(str(f)) != d1
    assert item_digest(str(tmp_path / "missing.csv"))  # an unreadable file still has one


def test_resume_point_only_for_the_same_stream_prefix():
    digests = [item_digest(d) for d in load_lasa(["GShape"])[:4]]
    record = progress_record(digests[:2], 2)
    assert record == {"items": 2, "of": 2, "digest": prefix_digest(digests, 2)}
    assert resume_point(record, digests) == 2           # same first two: resume after them
    assert resume_point(record, digests[:2]) == 2       # all done
    assert resume_point(record, digests[1:]) == 0       # another stream: from its start
    assert resume_point(record, digests[:1]) == 0       # shorter than what was done
    for bad in (None, {}, {"items": "2"}, {"items": True, "digest": "x"}, [1], {"items": -1}):
        assert resume_point(bad, digests) == 0


def test_a_second_teacher_of_one_memory_gets_a_clear_error(tmp_path, cli):
    memory = tmp_path / "m.npz"
    with teaching_lock(memory):
        with pytest.raises(MemoryLockedError, match="being taught by another process"):
            with teaching_lock(memory):
                pass
        out = cli("teach", "--memory", str(memory), "GShape/0")
        assert out.returncode == 2
        assert "being taught by another process" in out.stderr and "Traceback" not in out.stderr
        assert not memory.exists()
    with teaching_lock(memory):  # released: free again
        pass


CRASHER = """
import os
from iloci import hookimpl

@hookimpl
def iloci_on_interaction(event):
    # dies like kill -9 (no cleanup, no save) once step N is learned, before it is saved
    if event.step == int(os.environ.get("CRASH_AT_STEP", "-1")):
        os._exit(137)
"""


@pytest.mark.slow
def test_rerun_resumes_and_ends_like_an_uninterrupted_run(tmp_path, cli):
    pytest.importorskip("iloci_native")
    pytest.importorskip("iloci_pinocchio")
    from iloci.concepts.memory import entries_equal, load_memory
    site = tmp_path / "site"
    site.mkdir()
    (site / "crasher.py").write_text(CRASHER)
    info = site / "crasher-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: crasher\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[iloci]\ncrasher = crasher\n")
    config = tmp_path / "c.toml"
    config.write_text('[perceptual_model]\nname = "native-rnnpb"\nhidden = 12\nepochs = 30\n'
                      "[learner]\nrehearsal_epochs = 30\n")
    stream = ["GShape/0", "Sine/1", "GShape/2", "Sine/3"]
    whole, cut = tmp_path / "whole.npz", tmp_path / "cut.npz"

    def teach(memory, *demos, crash_at=-1, code=0):
        out = cli("teach", "--config", str(config), "--memory", str(memory), *demos,
                  env={"PYTHONPATH": str(site), "CRASH_AT_STEP": str(crash_at)})
        assert out.returncode == code, out.stderr
        return out.stdout

    teach(whole, *stream)
    # dies after learning the third demonstration, before saving it: the memory holds two
    teach(cut, *stream, crash_at=2, code=137)
    assert load_memory(cut)[0].demonstrations_seen == 2
    out = teach(cut, *stream)
    assert "resuming: the first 2 of the 4" in out
    assert "GShape/0:" not in out and "Sine/1:" not in out and "GShape/2:" in out
    a, na, _ = load_memory(whole)
    b, nb, _ = load_memory(cut)
    assert entries_equal(a.entries, b.entries)
    assert a.demonstrations_seen == b.demonstrations_seen == 4
    assert np.array_equal(a.encoder.scale_, b.encoder.scale_)
    assert all(np.array_equal(na[k], nb[k]) for k in na)
    out = teach(cut, *stream)
    assert "nothing to teach" in out and load_memory(cut)[0].demonstrations_seen == 4


def test_a_full_disk_during_teach_names_the_file_and_what_was_not_saved(tmp_path, cli):
    """`ulimit -f` below the memory's size (EFBIG, as ENOSPC on a full disk): one clear
    error naming the file, what it still holds and what was not saved; the file intact."""
    import resource
    import subprocess
    import sys

    pytest.importorskip("iloci_torch")
    pytest.importorskip("iloci_pinocchio")
    config = tmp_path / "c.toml"
    config.write_text('[perceptual_model]\nname = "torch-rnnpb"\nhidden = 12\nepochs = 30\n'
                      "[learner]\nrehearsal_epochs = 30\n")
    memory = tmp_path / "m.npz"
    assert cli("teach", "--config", str(config), "--memory", str(memory),
               "GShape/0").returncode == 0
    before = memory.read_bytes()

    def full_disk():
        resource.setrlimit(resource.RLIMIT_FSIZE, (len(before) // 2, len(before) // 2))
    out = subprocess.run([sys.executable, "-m", "iloci", "teach", "--config", str(config),
                          "--memory", str(memory), "Sine/0"], capture_output=True, text=True,
                         timeout=600, preexec_fn=full_disk)
    assert out.returncode == 2, out.stderr
    assert f"could not save the memory to {memory}: the disk is full" in out.stderr
    assert "Sine/0 was learned but not saved" in out.stderr and "still holds" in out.stderr
    assert "Traceback" not in out.stderr
    assert memory.read_bytes() == before
