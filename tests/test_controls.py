"""A person's controls on the Agent (iloci.agent.controls): undo, forget, start over, import.

What the web page uses, called as a library user calls it: real agent
(native-rnnpb, few epochs; Pinocchio IK), real LASA drawings.
"""

from __future__ import annotations

import numpy as np
import pytest

from iloci.errors import InvalidInputError, MemoryFileError

from conftest import agent_state, assert_same_state


@pytest.fixture
def taught(small_agent, lasa):
    agent = small_agent()
    agent.teach([lasa["GShape/0"], lasa["Angle/0"], lasa["GShape/1"]])
    assert agent.memory.concepts() == ["c1", "c2"]
    return agent


def test_restore_puts_memory_and_network_back_exactly(taught, lasa):
    before = agent_state(taught)
    snap = taught.snapshot("three drawings")
    assert snap.what == "three drawings"
    taught.teach([lasa["Angle/1"]])                       # a rehearsal changes the network
    with pytest.raises(AssertionError):
        assert_same_state(before, agent_state(taught))
    revision = taught.memory.revision
    taught.restore(snap)
    assert_same_state(before, agent_state(taught))
    assert taught.memory.revision > revision             # a turn made before sees the change
    taught.restore(snap)                                 # a snapshot restores more than once
    assert_same_state(before, agent_state(taught))


def test_forget_a_concept_an_entry_and_start_over(taught):
    net = taught.perceptual_model.state()
    n = len(taught.memory.entries)
    with pytest.raises(InvalidInputError, match="no concept 'c9'.*c1, c2"):
        taught.forget_concept("c9")
    with pytest.raises(InvalidInputError, match=f"no entry {n} .it has {n}"):
        taught.forget_entry(n)
    with pytest.raises(InvalidInputError, match="no entry -1"):
        taught.forget_entry(-1)
    assert len(taught.memory.entries) == n               # refused: nothing forgotten
    taught.forget_entry(0)
    assert len(taught.memory.entries) == n - 1
    taught.forget_concept("c2")
    assert taught.memory.concepts() == ["c1"]
    for k, v in taught.perceptual_model.state().items():  # the network is not retrained
        np.testing.assert_array_equal(v, net[k])
    revision = taught.memory.revision
    taught.start_over()
    assert taught.memory.entries == [] and taught.memory.encoder is None
    assert taught.memory.revision == revision + 1


def test_replace_memory_checks_the_file_as_load_does(taught, small_agent, tmp_path):
    path = taught.save(tmp_path / "m.npz")
    other = small_agent()
    other.replace_memory(path)
    assert_same_state(agent_state(taught), agent_state(other))
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 not a memory file")
    before = agent_state(other)
    with pytest.raises(MemoryFileError):
        other.replace_memory(bad)
    assert_same_state(before, agent_state(other))      # refused: unchanged


def test_the_drawing_in_the_frame_of_the_persons_stroke(taught, lasa):
    demo = lasa["GShape/2"]
    drawing = taught.drawing_in_frame(demo, "c1")
    assert drawing is not None and drawing.ndim == 2 and drawing.shape[1] == 2
    # in the stroke's units and place (LASA's, about 48 x 46 around 0; the plane's
    # would be centimetres): the drawing's box is the stroke's within a tenth of its size
    lo, hi = demo.positions.min(axis=0), demo.positions.max(axis=0)
    size = (hi - lo).max()
    assert np.all(np.abs(drawing.min(axis=0) - lo) < 0.1 * size)
    assert np.all(np.abs(drawing.max(axis=0) - hi) < 0.1 * size)
    entry = taught.memory.indices_of("c1")[-1]
    assert taught.drawing_in_frame(demo, "c1", entry) is not None
