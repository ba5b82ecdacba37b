"""The example plugin passes iloci's conformance suite and works end to end."""

from __future__ import annotations

import numpy as np
import pytest

from iloci.errors import ConfigError, FeedbackError
from iloci.interfaces import Demonstration, Response
from iloci.testing import check_component, registry_factory


@pytest.fixture
def feedback_file(tmp_path):
    p = tmp_path / "feedback.csv"
    p.write_text("demo,attempt,feedback\nGShape/0,1,1\nSine/3,1,-1\nSine/3,2,1\n")
    return p


def test_conformance(feedback_file):
    check_component(registry_factory("teacher", "replay", file=str(feedback_file),
                                     default=-1), "teacher")


def test_replays_records(feedback_file):
    from iloci_replay.teacher import ReplayTeacher
    t = ReplayTeacher(str(feedback_file))
    demo = Demonstration(np.array([[0, 0], [1, 0], [1, 1.0]]), shape="Sine", index=3)
    r1 = Response("c0", np.zeros((3, 2)), attempt=1)
    r2 = Response("c1", np.zeros((3, 2)), attempt=2)
    assert (t.feedback(demo, r1), t.feedback(demo, r2)) == (-1, 1)
    with pytest.raises(FeedbackError, match="no recorded feedback"):
        t.feedback(demo, Response("c2", np.zeros((3, 2)), attempt=3))


def test_bad_file(tmp_path):
    from iloci_replay.teacher import ReplayTeacher
    with pytest.raises(ConfigError, match="not found"):
        ReplayTeacher(str(tmp_path / "none.csv"))
    p = tmp_path / "bad.csv"
    p.write_text("demo,attempt,feedback\nGShape/0,1,2\n")
    with pytest.raises(ConfigError, match="bad.csv:2"):
        ReplayTeacher(str(p))
