"""Saving and loading the robot's memory: format, atomicity, corruption, round trip."""

from __future__ import annotations

import json
import os
from pathlib import Path
import zipfile

import numpy as np
import pytest

from conftest import needs_default_back_ends

import iloci
from iloci.concepts import memory as memory_module
from iloci.concepts import storage
from iloci.concepts.memory import (FORMAT_VERSION, Entry, Memory, entries_equal, load_memory,
                                   save_memory)
from iloci.errors import MemoryFileError
from iloci.sensorimotor.encoding import SensorimotorEncoder


def small_memory(n: int = 3) -> tuple[Memory, dict[str, np.ndarray]]:
    rng = np.random.default_rng(n)
    enc = SensorimotorEncoder.from_state({"scale": rng.uniform(0.01, 0.1, 6),
                                          "limit": np.array(0.9)})
    entries = [Entry(pb=rng.uniform(-1, 1, 4), pb_rec=rng.uniform(-1, 1, 4),
                     num_samples=i + 1, num_steps=49, initial_input=rng.normal(size=6),
                     start=rng.normal(size=6), dt=0.1, concept=f"c{i % 2 + 1}",
                     generation_error=float(rng.random()), source=f"GShape/{i}",
                     sources=tuple(f"GShape/{j}" for j in range(i + 1)), prototype=i == 2)
               for i in range(n)]
    net = {"w_in": rng.normal(size=(60, 35)), "b": rng.normal(size=60),
           "hidden": np.array(60)}
    return Memory(entries, enc, concept_count=2, demonstrations_seen=n + 2), net


def test_round_trip_without_pickle(tmp_path):
    mem, net = small_memory()
    path = save_memory(tmp_path / "m.npz", mem, net, extra={"config": {"a": 1}})
    with np.load(path, allow_pickle=False) as z:      # no object arrays inside
        assert "__header__" in z.files and all(z[k].dtype != object for k in z.files)
    back, net2, header = load_memory(path)
    assert entries_equal(back.entries, mem.entries)
    assert (back.concept_count, back.demonstrations_seen) == (2, 5)
    np.testing.assert_array_equal(back.encoder.scale_, mem.encoder.scale_)
    assert set(net2) == set(net)
    for k in net:
        np.testing.assert_array_equal(net2[k], net[k])
    assert header["version"] == FORMAT_VERSION and header["config"] == {"a": 1}
    assert header["format"] == "iloci-memory"


def test_empty_memory_round_trip(tmp_path):
    path = save_memory(tmp_path / "m.npz", Memory(), {})
    back, net, _ = load_memory(path)
    assert len(back) == 0 and back.encoder is None and net == {}


def test_interrupted_save_leaves_the_previous_memory_loadable(tmp_path, monkeypatch):
    path = tmp_path / "m.npz"
    old, net = small_memory(2)
    save_memory(path, old, net)
    before = path.read_bytes()
    new, net_new = small_memory(3)

    def crash(src, dst):  # the process dies after writing, before the rename
        raise KeyboardInterrupt("simulated crash")

    monkeypatch.setattr(memory_module.os, "replace", crash)
    with pytest.raises(KeyboardInterrupt):
        save_memory(path, new, net_new)
    monkeypatch.undo()
    assert path.read_bytes() == before
    back, _, _ = load_memory(path)
    assert entries_equal(back.entries, old.entries)
    assert [p.name for p in tmp_path.iterdir()] == ["m.npz"]  # no temporary file left


def test_a_crash_leftover_temp_file_does_not_hide_the_memory(tmp_path):
    path = tmp_path / "m.npz"
    mem, net = small_memory()
    save_memory(path, mem, net)
    (tmp_path / ".m.npz.abc.tmp").write_bytes(path.read_bytes()[:100])  # a dead writer's
    back, _, _ = load_memory(path)
    assert entries_equal(back.entries, mem.entries)


def test_missing_file(tmp_path):
    with pytest.raises(MemoryFileError, match="not found.*iloci teach"):
        load_memory(tmp_path / "nothing.npz")


def test_truncated_file(tmp_path):
    path = tmp_path / "m.npz"
    save_memory(path, *small_memory())
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(MemoryFileError, match="truncated"):
        load_memory(path)


def _rewrite(path: Path, change) -> None:
    """Rewrite an npz member-by-member, letting ``change(arrays)`` edit it."""
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def test_tampered_array_fails_the_checksum(tmp_path):
    path = tmp_path / "m.npz"
    save_memory(path, *small_memory())

    def edit(arrays):
        arrays["mem/num_samples"] = arrays["mem/num_samples"] + 1

    _rewrite(path, edit)
    with pytest.raises(MemoryFileError, match="checksum"):
        load_memory(path)


def test_tampered_header_fails_the_checksum(tmp_path):
    path = tmp_path / "m.npz"
    save_memory(path, *small_memory())

    def edit(arrays):
        header = json.loads(arrays["__header__"].tobytes())
        header["memory"]["concepts"][0] = "c9"
        arrays["__header__"] = np.frombuffer(json.dumps(header).encode(), np.uint8)

    _rewrite(path, edit)
    with pytest.raises(MemoryFileError, match="checksum"):
        load_memory(path)


def test_a_cut_header_is_said_to_be_damaged_not_foreign(tmp_path):
    """A header cut mid-way was called "not an iloci memory file" with json's message."""
    path = tmp_path / "m.npz"
    save_memory(path, *small_memory())

    def edit(arrays):
        arrays["__header__"] = arrays["__header__"][:len(arrays["__header__"]) // 2]

    _rewrite(path, edit)
    before = path.read_bytes()
    with pytest.raises(MemoryFileError, match=r"m.npz: its header \(the memory's settings "
                                              r"and checksum\) is damaged and cannot be "
                                              r"read \(Unterminated"):
        load_memory(path)
    assert path.read_bytes() == before


def test_a_small_file_that_unpacks_to_gigabytes_is_refused_unpacked(tmp_path):
    """An audit's 1.5 MB upload to the teaching page unpacked to 1.6 GB of zeros before
    its checksum refused it (3.3 GB of the server's memory; every tab stalled 22 s)."""
    path = tmp_path / "bomb.npz"
    np.savez_compressed(path, w=np.zeros(80 * 2**20 // 8))   # 80 MiB of zeros, ~80 kB
    assert path.stat().st_size < 2**20
    with pytest.raises(MemoryFileError, match=r"bomb.npz would unpack [\d,]+ bytes into "
                                              r"83,886,\d+ \([\d,]+ times as many\).*a zip "
                                              r"bomb\); nothing was unpacked"):
        load_memory(path)


def test_flipped_byte_is_detected(tmp_path):
    path = tmp_path / "m.npz"
    save_memory(path, *small_memory())
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("mem/pb.npy")
    data[info.header_offset + 30 + len(info.filename) + 140] ^= 0xFF  # inside the array
    path.write_bytes(bytes(data))
    with pytest.raises(MemoryFileError):
        load_memory(path)


def test_newer_version_is_refused_with_upgrade_advice(tmp_path):
    path = tmp_path / "m.npz"
    mem, net = small_memory()
    save_memory(path, mem, net)

    def edit(arrays):
        header = json.loads(arrays["__header__"].tobytes())
        header["version"] = FORMAT_VERSION + 1
        rest = {k: v for k, v in arrays.items() if k != "__header__"}
        header["checksum"] = storage._checksum(header, rest)
        arrays["__header__"] = np.frombuffer(json.dumps(header).encode(), np.uint8)

    _rewrite(path, edit)
    with pytest.raises(MemoryFileError, match="newer iloci.*Upgrade"):
        load_memory(path)


def test_other_npz_is_not_a_memory(tmp_path):
    path = tmp_path / "other.npz"
    np.savez(path, a=np.zeros(3))
    with pytest.raises(MemoryFileError, match="not an iloci memory"):
        load_memory(path)
    path.write_text("hello")
    with pytest.raises(MemoryFileError):
        load_memory(path)


def test_object_arrays_are_refused_on_save(tmp_path):
    mem, _ = small_memory()
    with pytest.raises(iloci.errors.InvalidInputError, match="no pickle"):
        save_memory(tmp_path / "m.npz", mem, {"bad": np.array([{"a": 1}], dtype=object)})
    assert not any(tmp_path.iterdir())


def test_save_creates_parent_directories_and_overwrites(tmp_path):
    path = tmp_path / "a" / "b" / "m.npz"
    mem, net = small_memory(2)
    save_memory(path, mem, net)
    mem3, net3 = small_memory(3)
    save_memory(path, mem3, net3)
    assert len(load_memory(path)[0]) == 3
    assert os.listdir(path.parent) == ["m.npz"]


# -- with a real network -------------------------------------------------------------

#: The RNNPB back end under test (ILOCI_TEST_RNNPB=jax-rnnpb runs these on JAX).
RNNPB = os.environ.get("ILOCI_TEST_RNNPB", "native-rnnpb")

SMALL_TOML = f"""
[perceptual_model]
name = "{RNNPB}"
epochs = 30
recognition_steps = 30
[learner]
rehearsal_epochs = 30
[evaluation]
seed = 0
"""


@pytest.fixture(scope="module")
def taught(tmp_path_factory):
    """An agent taught two concepts, saved to a file."""
    pytest.importorskip({"native-rnnpb": "iloci_native", "torch-rnnpb": "torch",
                     "jax-rnnpb": "jax"}[RNNPB])
    pytest.importorskip("pinocchio")
    from iloci.data import load_lasa
    from iloci.errors import MissingBackendError
    cfg = tmp_path_factory.mktemp("cfg") / "small.toml"
    cfg.write_text(SMALL_TOML)
    try:
        agent = iloci.build(cfg)
    except MissingBackendError as exc:
        pytest.skip(str(exc))
    demos = {d.key: d for d in load_lasa(["GShape", "Angle", "Sine"])}
    agent.teach([demos["GShape/0"], demos["Angle/0"]])
    path = agent.save(tmp_path_factory.mktemp("mem") / "memory.npz")
    return agent, path, demos, cfg


def test_save_load_recognize_gives_identical_answers(taught):
    agent, path, demos, _ = taught
    test = [demos["GShape/5"], demos["Angle/5"], demos["Sine/5"]]
    before = agent.recognize(test)
    loaded = iloci.Agent.load(path)
    assert entries_equal(loaded.memory.entries, agent.memory.entries)
    assert loaded.config.to_dict() == agent.config.to_dict()
    after = loaded.recognize(test)
    for a, b in zip(before, after):
        assert (a.concept, a.entry, a.source) == (b.concept, b.entry, b.source)
        assert a.confidence == pytest.approx(b.confidence, abs=1e-12)
        assert a.distance == pytest.approx(b.distance, abs=1e-12)
        np.testing.assert_allclose(a.pb_obs, b.pb_obs, atol=1e-12)


def test_learning_continues_after_loading(taught, tmp_path):
    _, path, demos, _ = taught
    loaded = iloci.Agent.load(path)
    outcome = loaded.learn(demos["Sine/0"])
    assert outcome.action == "new_concept" and outcome.concept == "c3"
    assert loaded.memory.demonstrations_seen == 3 and len(loaded.memory) == 3
    again = iloci.Agent.load(loaded.save(tmp_path / "m2.npz"))
    assert again.memory.concepts() == ["c1", "c2", "c3"]
    assert again.recognize(demos["Sine/1"]).concept in ("c1", "c2", "c3")


def test_save_refuses_an_extra_that_would_break_the_file_and_a_path_that_is_none(taught,
                                                                                   tmp_path):
    """An audit: save(extra={"memory": {}}) (or "format", "version", ...) wrote a file
    that could not be loaded; an extra value json cannot hold, a path that is a folder,
    None or "" failed inside json, os or the lock. Each is one error, nothing written."""
    from iloci.errors import InvalidInputError

    agent, path, _, _ = taught
    target = tmp_path / "m.npz"
    for extra in ({"memory": {}}, {"format": "junk"}, {"version": 99}, {"config": {}},
                  {"checksum": "0"}):
        with pytest.raises(InvalidInputError, match=f"extra may not hold '{next(iter(extra))}'"
                                                    ": the memory file's own header holds it"):
            agent.save(target, extra=extra)
    with pytest.raises(InvalidInputError, match=r"extra\['x'\] cannot be written .* \.item\(\)"):
        agent.save(target, extra={"x": np.float32(1.5)})
    with pytest.raises(InvalidInputError, match="extra must be a mapping"):
        agent.save(target, extra=[1, 2])
    for bad in (None, ""):
        with pytest.raises(InvalidInputError, match="a memory file needs a path"):
            agent.save(bad)
        with pytest.raises(InvalidInputError, match="a memory file needs a path"):
            iloci.Agent.load(bad)
    with pytest.raises(MemoryFileError, match="is a directory; give a file name in it"):
        agent.save(tmp_path)
    assert not list(tmp_path.iterdir())
    agent.save(target, extra={"note": "kept", "progress": {"items": 2}})
    assert iloci.Agent.load(target).memory.n_entries == agent.memory.n_entries


def test_restore_refuses_a_snapshot_of_an_agent_whose_memory_does_not_fit(taught):
    """An audit: a snapshot of a 3-joint arm's agent restored into the Nao's agent was
    taken; every later call failed and the file it saved could not be loaded."""
    from iloci.errors import InvalidInputError

    agent, _, demos, cfg = taught
    other = iloci.build(iloci.load_config(cfg).replace(perceptual_model={"pb": 3}))
    other.learn(demos["Sine/0"])
    before = agent.memory.copy()
    with pytest.raises(InvalidInputError, match="does not fit this one: perceptual_model.pb "
                                                "= 3 in the memory, 4 in the config"):
        agent.restore(other.snapshot())
    with pytest.raises(InvalidInputError, match="restore takes a Snapshot"):
        agent.restore(None)
    assert entries_equal(agent.memory.entries, before.entries)
    agent.restore(agent.snapshot())                    # its own: as before
    assert entries_equal(agent.memory.entries, before.entries)


def test_the_oracle_of_a_later_session_knows_what_the_memory_learned_before(taught):
    """An audit: `iloci teach --memory m.npz GShape/0`, then `... GShape/2` in a second
    command: the oracle had not seen GShape/0 in that session, said "no" to the right
    guess and a duplicate concept was founded. The memory keeps the data's labels of what
    it learned (Memory.labels), and the oracle of any later session recalls them."""
    agent, path, demos, cfg = taught
    later = iloci.Agent.load(path, cfg)
    assert later.memory.labels == {"GShape/0": "GShape", "Angle/0": "Angle"}
    gshape = agent.memory.entries[0].concept
    outcome = later.learn(demos["GShape/1"])
    assert outcome.concept == gshape and outcome.action != "new_concept"
    assert outcome.feedbacks[-1] == 1 and later.memory.labels["GShape/1"] == "GShape"
    assert len(later.memory.concepts()) == 2


def test_cli_teach_then_recognize(taught, tmp_path, cli):
    _, _, _, cfg = taught
    memory = tmp_path / "robot.npz"
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n1,2\n")
    out = cli("teach", "--config", str(cfg), "--memory", str(memory), "--teacher", "oracle",
              "GShape/0", str(bad), "Angle/0")
    assert out.returncode == 0, out.stderr
    assert "GShape/0: no concept to guess -> new concept c1" in out.stdout
    assert "Angle/0: guessed c1 (-1) -> new concept c2" in out.stdout
    assert "skipped demonstration" in out.stderr and "bad.csv" in out.stderr
    assert memory.is_file() and len(load_memory(memory)[0]) == 2
    from iloci.data import load_lasa
    npy = tmp_path / "mine.npy"
    np.save(npy, load_lasa(["Angle"])[4].positions)
    out = cli("recognize", "--memory", str(memory), "GShape/4", str(npy), "--json")
    assert out.returncode == 0, out.stderr
    answers = [json.loads(line) for line in out.stdout.splitlines()]
    assert [a["demo"] for a in answers] == ["GShape/4", "mine/0"]
    assert all(a["concept"] in ("c1", "c2") and 0 <= a["confidence"] <= 1 for a in answers)
    # teaching again continues from the saved memory
    out = cli("teach", "--memory", str(memory), "GShape/1")
    assert out.returncode == 0, out.stderr
    assert "continuing from" in out.stdout and load_memory(memory)[0].demonstrations_seen == 3
    # the same strokes in another stream: recognized as learned, not learned again
    before = memory.read_bytes()
    out = cli("teach", "--memory", str(memory), "GShape/0", "GShape/1")
    assert out.returncode == 0, out.stderr
    assert "already learned, not learned again" in out.stdout and "GShape/0, GShape/1" in out.stdout
    assert "memory unchanged" in out.stdout and memory.read_bytes() == before


def test_cli_errors(tmp_path, cli):
    needs_default_back_ends()
    out = cli("recognize", "--memory", str(tmp_path / "none.npz"), "GShape/0")
    assert out.returncode == 2 and "memory file not found" in out.stderr
    out = cli("teach", "--memory", str(tmp_path / "m.npz"), "GShap/1")
    assert out.returncode == 2 and "Did you mean 'GShape'" in out.stderr
    out = cli("teach", "--memory", str(tmp_path / "m.npz"), "GShape/9")
    assert out.returncode == 2 and "0..6" in out.stderr
    assert not (tmp_path / "m.npz").exists()


def test_default_teaching_stream_is_seeded():
    needs_default_back_ends()
    from iloci.data import default_stream
    from iloci.config import load_config
    cfg = load_config({"data": {"shapes": ["GShape", "Angle", "Sine"]},
                       "evaluation": {"seed": 3, "train_fraction": 0.3}})
    a, b = default_stream(cfg), default_stream(cfg)
    assert [d.key for d in a] == [d.key for d in b]
    assert len(a) == 3 * 2 and {d.shape for d in a} == {"GShape", "Angle", "Sine"}
    other = default_stream(cfg.replace(evaluation={"seed": 4}))
    assert [d.key for d in other] != [d.key for d in a]


class _HdbscanLike:
    """A third-party clusterer plugin object, there at teaching time only."""

    @iloci.hookimpl
    def iloci_register_clusterers(self, registry):
        registry.add("hdbscan-like", "iloci_scipy.clusterer:ScipyClusterer",
                     summary="stands in for a clusterer the recognizing machine lacks")


def test_a_memory_recognizes_without_its_teaching_only_plugins(tmp_path):
    """Taught with a clusterer plugin that is then not installed: recognition still loads."""
    pytest.importorskip("iloci_scipy")
    pytest.importorskip({"native-rnnpb": "iloci_native", "torch-rnnpb": "torch",
                         "jax-rnnpb": "jax"}[RNNPB])
    pytest.importorskip("pinocchio")
    from iloci.data import load_lasa
    from iloci.errors import NotLoadedError, UnknownComponentError
    from iloci.plugins import get_plugin_manager

    demos = {d.key: d for d in load_lasa(["GShape", "Angle"])}
    settings = {"perceptual_model": {"name": RNNPB, "epochs": 30, "recognition_steps": 30},
                "learner": {"rehearsal_epochs": 30}, "evaluation": {"seed": 0},
                "clusterer": {"name": "hdbscan-like"}}
    agent = iloci.build(settings, plugin_manager=get_plugin_manager(plugins=[_HdbscanLike()]))
    agent.teach([demos["GShape/0"], demos["Angle/0"]])
    path = agent.save(tmp_path / "m.npz")
    needs = load_memory(path)[2]["needs"]
    assert set(needs["recognize"]) == {"perceptual_model", "ik"}
    assert needs["learn"]["clusterer"] == {"name": "hdbscan-like", "distribution": None}
    assert needs["learn"]["perceptual_model"]["distribution"] == f"iloci-{RNNPB[:-6]}"

    with pytest.raises(UnknownComponentError, match="hdbscan-like"):
        iloci.Agent.load(path)                      # learning needs the clusterer
    loaded = iloci.Agent.load(path, purpose="recognize")
    test = [demos["GShape/3"], demos["Angle/3"]]
    for a, b in zip(agent.recognize(test), loaded.recognize(test)):
        assert (a.concept, a.source) == (b.concept, b.source)
        assert a.distance == pytest.approx(b.distance, abs=1e-12)
    with pytest.raises(NotLoadedError, match=r"(teacher|clusterer) was not loaded.*'learn'"):
        loaded.learn(demos["GShape/1"])
    assert "clusterer=NotLoaded" in repr(loaded) and loaded.simulator is None
    with pytest.raises(NotLoadedError, match="clusterer was not loaded"):
        loaded.clusterer.cluster(np.zeros((3, 2)), 1.0)
    with pytest.raises(iloci.errors.InvalidInputError, match="purpose must be one of"):
        iloci.Agent.load(path, purpose="teach")


def test_cli_recognize_needs_no_clusterer_plugin(taught, cli):
    """`iloci recognize` with the clusterer's plugin blocked; `iloci teach` says what is missing."""
    _, path, _, _ = taught
    blocked = {"ILOCI_BLOCK_PLUGINS": "scipy"}
    out = cli("recognize", "--memory", str(path), "GShape/4", "--json", env=blocked)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["concept"] in ("c1", "c2")
    out = cli("teach", "--memory", str(path), "GShape/1", env=blocked)
    assert out.returncode == 2 and "blocked" in out.stderr
