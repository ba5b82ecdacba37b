"""Mistaken calls of the embedding API (docs/embedding.md) that an audit found read silently
wrong or failing inside numpy or Python: each is now one iloci error saying what to pass,
with nothing learned or changed, or the value is read as what it means."""

from __future__ import annotations

import numpy as np
import pytest

import iloci
from iloci.concepts.memory import entries_equal
from iloci.data import load_lasa
from iloci.errors import InvalidDemonstrationError, InvalidInputError, MissingBackendError
from iloci.interfaces import Demonstration

pytest.importorskip("pinocchio")

SETTINGS = {"perceptual_model": {"name": "native-rnnpb", "epochs": 30,
                                 "recognition_steps": 30},
            "learner": {"rehearsal_epochs": 30}}


@pytest.fixture(scope="module")
def lasa():
    return {d.key: d for d in load_lasa(["GShape", "Angle", "Sine"])}


@pytest.fixture
def taught(lasa):
    try:
        agent = iloci.build(SETTINGS)
    except MissingBackendError as exc:
        pytest.skip(str(exc))
    agent.learn(lasa["GShape/0"])
    turn = agent.observe(lasa["Angle/0"])
    while not turn.done:
        turn.feedback(-1, turn.answer.id)
    return agent


def test_drawing_in_frame_refuses_an_entry_of_another_concept_or_not_an_index(taught, lasa):
    """entry=0 (an entry of c1) gave c1's drawing for c2; -1 the last entry; "0" and
    np.int64(99) were ignored; 99 an IndexError."""
    agent, demo = taught, lasa["GShape/1"]
    c1, c2 = agent.memory.entries[0].concept, agent.memory.entries[1].concept
    for entry in (0, -1, 99, "1", 1.0, True):
        with pytest.raises(InvalidInputError, match=f"entry {entry!r} is not an entry of "
                                                    f"{c2!r}: give one of its indices"):
            agent.drawing_in_frame(demo, c2, entry=entry)
    with pytest.raises(InvalidInputError, match="the memory holds no concept 'c9'"):
        agent.drawing_in_frame(demo, "c9")
    drawn = agent.drawing_in_frame(demo, c2, entry=np.int64(1))
    assert np.array_equal(drawn, agent.drawing_in_frame(demo, c2))
    assert not np.array_equal(drawn, agent.drawing_in_frame(demo, c1, entry=0))


def test_forget_entry_takes_an_int_and_nothing_else(taught):
    """0.5 forgot nothing but bumped the revision (a pending turn was refused); True and
    1.0 were read as 1; "0" and None failed inside Python."""
    agent = taught
    before, revision = agent.memory.copy(), agent.memory.revision
    for index in (0.5, True, 1.0, "0", None):
        with pytest.raises(InvalidInputError, match="forget_entry takes an entry's index"):
            agent.forget_entry(index)
    assert entries_equal(agent.memory.entries, before.entries)
    assert agent.memory.revision == revision
    agent.forget_entry(np.int64(1))
    assert len(agent.memory.entries) == 1


def test_a_motion_of_another_demonstration_is_refused(taught, lasa):
    """learn(circle, motion=agent.motion(wave)) learned the wave's motion under the
    circle's key."""
    agent = taught
    before = agent.memory.copy()
    with pytest.raises(InvalidInputError, match="the motion given is that of 'Sine/0', not "
                                                "of 'GShape/1'"):
        agent.learn(lasa["GShape/1"], motion=agent.motion(lasa["Sine/0"]))
    assert entries_equal(agent.memory.entries, before.entries)


def test_teach_says_it_takes_a_sequence_of_demonstrations(taught, lasa):
    """teach(demo) and teach(5) failed inside Python; teach(one (N, 2) array) walked its
    rows, 60 skip warnings; on_change="save" learned one and dropped the rest."""
    agent = taught
    before = agent.memory.copy()
    for demos, said in ((lasa["GShape/1"], "for one demonstration, pass \\[it\\]"),
                        (lasa["GShape/1"].positions, "for one demonstration"),
                        ("GShape/1", "for one demonstration"), (5, "got int")):
        with pytest.raises(InvalidInputError, match=f"teach takes a sequence .*{said}"):
            agent.teach(demos)
    with pytest.raises(InvalidInputError, match="on_change must be a function"):
        agent.teach([lasa["GShape/1"]], on_change="save")
    assert entries_equal(agent.memory.entries, before.entries)
    with pytest.raises(iloci.errors.FeedbackError, match="does not know the concept of "
                                                         "'stream/0'"):
        agent.teach(np.stack([lasa["Sine/0"].positions]))  # (K, N, 2): K drawings, read


def test_numpy_values_in_a_config_are_read_as_the_numbers_they_hold():
    """epochs=np.int64(50) was refused as "must be an integer"."""
    config = iloci.load_config({"perceptual_model": {"epochs": np.int64(50)},
                                "learner": {"k_cutoff": np.float32(0.5),
                                            "confirm_rewards": np.bool_(True)},
                                "data": {"shapes": np.array(["GShape", "Sine"])}})
    assert config.perceptual_model.params.epochs == 50
    assert type(config.perceptual_model.params.epochs) is int
    assert config.learner.k_cutoff == 0.5 and config.learner.confirm_rewards is True
    assert config.data.shapes == ("GShape", "Sine")
    with pytest.raises(iloci.errors.ConfigError, match="epochs must be an integer"):
        iloci.load_config({"perceptual_model": {"epochs": np.float64(1.5)}})


def test_demonstrations_of_values_numpy_would_misread_are_refused():
    """Complex positions lost their imaginary part with a ComplexWarning, booleans were
    read as 0/1, a masked array's masked rows as data, datetime64 times as seconds."""
    t = np.linspace(0.0, 1.0, 50)
    xy = np.column_stack([np.cos(3 * t), np.sin(3 * t)])
    for positions, said in ((xy + 1j, "complex numbers"), (xy > 0, "true/false values")):
        with pytest.raises(InvalidDemonstrationError, match=f"must be a numeric array of "
                                                            f"shape \\(N, 2\\), got {said}"):
            Demonstration(positions, t)
    masked = np.ma.masked_array(xy, mask=np.zeros_like(xy, dtype=bool))
    masked[3] = np.ma.masked
    with pytest.raises(InvalidDemonstrationError, match="masked array with masked values"):
        Demonstration(masked, t)
    assert np.array_equal(Demonstration(np.ma.masked_array(xy), t).positions, xy)
    stamps = np.datetime64("2026-01-01T10:00") + (t * 1000).astype("timedelta64[ms]")
    with pytest.raises(InvalidDemonstrationError, match=r"got dates \(datetime64\)\. Convert "
                                                        "time stamps to seconds first"):
        Demonstration(xy, stamps)
    seconds = (stamps - stamps[0]) / np.timedelta64(1, "s")
    assert np.allclose(Demonstration(xy, seconds).times, t, atol=1e-3)  # ms stamps


def test_a_torch_tensor_that_needs_grad_is_read_as_its_values():
    torch = pytest.importorskip("torch")
    t = np.linspace(0.0, 1.0, 50)
    xy = np.column_stack([np.cos(3 * t), np.sin(3 * t)])
    demo = Demonstration(torch.tensor(xy, requires_grad=True), torch.tensor(t))
    assert np.array_equal(demo.positions, xy) and np.array_equal(demo.times, t)


class _Faulty:
    """A caller's IK solver that wraps the default one and spoils its answer."""

    def __init__(self, inner, spoil):
        self.inner, self.spoil = inner, spoil
        self.joint_names, self.lower, self.upper = inner.joint_names, inner.lower, inner.upper

    def solve(self, points, q0=None):
        return self.spoil(np.array(self.inner.solve(points, q0=q0)))

    def forward(self, q):
        return self.inner.forward(q)


@pytest.mark.parametrize("spoil, said", [
    (lambda q: q[:, :3], r"returned a joint path of shape \(\d+, 3\) for 'Angle/0'; it must "
                         r"be \(\d+, 4\): one row per target, one column per joint"),
    (lambda q: np.where(np.arange(len(q))[:, None] == 5, np.nan, q),
     "returned NaN or inf for 'Angle/0' \\(first at target 5\\)"),
    (lambda q: q + np.array([0.0, 0.0, 10.0, 0.0]),
     "returned a joint path beyond its own limits for 'Angle/0': joint 'RElbowYaw'"),
    (lambda q: "no", "returned str, not a joint path of numbers")])
def test_a_custom_ik_solvers_faulty_answer_is_said_as_its_own(taught, lasa, spoil, said):
    """An audit's IK returning 3 columns for 4 joints failed later as a network input of
    the wrong width; NaN as a "(T, D) array" error naming neither; angles 10 rad past its
    own limits were learned. Each is now an UnreachableTargetError naming the solver, and
    teach skips that demonstration."""
    from iloci.errors import UnreachableTargetError

    agent = taught
    agent.ik_solver = _Faulty(agent.ik_solver, spoil)
    agent.motion_cache = None
    before = agent.memory.copy()
    with pytest.raises(UnreachableTargetError, match=f"the IK solver .*_Faulty {said}"):
        agent.learn(lasa["Angle/0"].__class__(lasa["Angle/0"].positions, shape="Angle",
                                              index=0, true_concept="Angle"))
    with pytest.warns(iloci.agent.SkippedDemonstrationWarning, match="_Faulty"):
        report = agent.teach([lasa["Angle/1"]])
    assert report.skipped and entries_equal(agent.memory.entries, before.entries)


def test_wrong_kinds_of_arguments_are_said_as_such(taught, lasa):
    """feedback naming its answer by an array, recognize(None), entry_drawings([1, 2])
    failed inside numpy or Python."""
    from iloci.errors import FeedbackError

    agent = taught
    turn = agent.observe(lasa["GShape/1"])
    with pytest.raises(FeedbackError, match="by its id, a str .* got ndarray"):
        turn.feedback(1, np.array([turn.answer.id, "x"]))
    assert not turn.done
    for bad in (None, 5, "GShape/1", lasa["GShape/1"].positions, [None]):
        with pytest.raises(InvalidInputError, match="recognize takes"):
            agent.recognize(bad)
    with pytest.raises(InvalidInputError, match="entry_drawings takes memory entries"):
        agent.entry_drawings([1, 2])
    assert len(agent.entry_drawings(agent.memory.entries[:1])) == 1


def test_plugins_and_configs_given_wrongly_in_code_are_said_as_such():
    """A class instead of an instance (every learn then raised "missing self"), one
    instance twice (pluggy's ValueError), a plugin not in a list, a hook method without
    @iloci.hookimpl (silently never called), a non-str config key (difflib's TypeError),
    a plugin_manager that is not one."""
    from iloci.errors import ConfigError, PluginError
    from iloci.plugins import get_plugin_manager

    class Observer:
        @iloci.hookimpl
        def iloci_on_interaction(self, event):
            pass

    class Unmarked:
        def iloci_on_interaction(self, event):
            pass

    one = Observer()
    for plugins, said in (([Observer], "is the class .*Observer, not an instance of it"),
                          ([one, one], "is given twice"),
                          (one, "plugins must be a list of plugin objects"),
                          ([Unmarked()], "has iloci_on_interaction without @iloci.hookimpl")):
        with pytest.raises(PluginError, match=said):
            get_plugin_manager(autoload=False, plugins=plugins)
    assert get_plugin_manager(autoload=False, plugins=[one]).is_registered(one)
    with pytest.raises(ConfigError, match="section names are strings, got 1"):
        iloci.load_config({1: {}})
    with pytest.raises(ConfigError, match=r"keys in \[learner\] are strings, got 2"):
        iloci.load_config({"learner": {2: 3}})
    with pytest.raises(InvalidInputError, match="plugin_manager must be a pluggy"):
        iloci.build(SETTINGS, plugin_manager="x")


def test_a_demonstrations_key_parts_are_checked():
    """shape=None, index=None gave the key 'None/None'; index=1.5 the key 'demo/1.5'."""
    t = np.linspace(0.0, 1.0, 50)
    xy = np.column_stack([np.cos(3 * t), np.sin(3 * t)])
    for kwargs, said in (({"shape": None}, "shape must be a non-empty str"),
                         ({"shape": ""}, "shape must be a non-empty str"),
                         ({"index": None}, "index must be an int >= 0"),
                         ({"index": 1.5}, "index must be an int >= 0"),
                         ({"index": -1}, "index must be an int >= 0"),
                         ({"index": True}, "index must be an int >= 0"),
                         ({"true_concept": 3}, "true_concept must be a str or None")):
        with pytest.raises(InvalidDemonstrationError, match=said):
            Demonstration(xy, t, **kwargs)
    assert Demonstration(xy, t, shape="circle", index=np.int64(2)).key == "circle/2"


def test_a_failed_conformance_check_is_an_iloci_error_and_an_assertion():
    """The guide says every error iloci raises on purpose derives from IlociError;
    ConformanceError derived from AssertionError only."""
    import pickle

    from iloci.errors import IlociError
    from iloci.testing import CheckResult, ConformanceError

    error = ConformanceError("ik solver", [CheckResult("forward", False, "wrong shape")])
    assert isinstance(error, IlociError) and isinstance(error, AssertionError)
    again = pickle.loads(pickle.dumps(error))      # from a worker process, as itself
    assert again.kind == "ik solver" and str(again) == str(error)


def test_a_component_whose_method_cannot_be_called_as_its_kind_says_is_refused_at_build():
    """A teacher with feedback(self, response) passed build, then every learn raised
    Python's TypeError about a missing argument."""
    class OneArgument:
        def feedback(self, response):
            return 1

    class Flexible:
        def feedback(self, demo, response, *more, **options):
            return 1

    with pytest.raises(InvalidInputError, match=r"teacher=.* is not a teacher: it lacks "
                                                r"feedback taking \(demo, response\)"):
        iloci.build(SETTINGS, teacher=OneArgument())
    assert isinstance(iloci.build(SETTINGS, teacher=Flexible()).teacher, Flexible)


def test_an_ik_solver_whose_limits_do_not_describe_the_arm_is_refused_at_build():
    """Limits with lower > upper, or 3 limits for 4 joints, were accepted by build; the
    second failed at the first learning inside numpy."""
    from iloci_pinocchio.ik import PinocchioIK

    class Short(PinocchioIK):
        def __init__(self):
            super().__init__()
            self.lower = self.lower[:3]

    class Crossed(PinocchioIK):
        def __init__(self):
            super().__init__()
            self.lower = self.lower.copy()
            self.lower[1] = self.upper[1] + 1.0

    with pytest.raises(InvalidInputError, match="with 3 lower and 4 upper limit.s., but "
                                                "robot 'nao-v32-right-arm' has 4"):
        iloci.build(SETTINGS, ik=Short())
    with pytest.raises(InvalidInputError, match="joint 'RShoulderRoll' has lower limit .* "
                                                "above its upper limit"):
        iloci.build(SETTINGS, ik=Crossed())
