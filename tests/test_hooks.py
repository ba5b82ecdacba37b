"""Every hook spec is called: one plugin implements all of them and runs a fold.

The plugin registers a stand-in for each of the five interfaces (numpy only,
so this runs in every tox env, the bare kernel included), a config names
them, and a one-fold evaluation on two LASA shapes drives the learning
phase. The test of each hook is parametrized over the specs found in
``iloci.hookspecs``: a new spec fails here until the recorder implements it
and the run reaches it.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest

from iloci import hookimpl, hookspecs
from iloci.events import FoldEvent, InteractionEvent, RehearsalEvent
from iloci.interfaces import Execution
from iloci.cli import make_parser
from iloci.plugins import get_plugin_manager, get_registry


def hookspec_names() -> list[str]:
    """Names of every hook specification in :mod:`iloci.hookspecs`."""
    marker = f"{hookspecs.PROJECT}_spec"
    return sorted(n for n, f in vars(hookspecs).items()
                  if callable(f) and hasattr(f, marker))


# -- stand-in components ---------------------------------------------------------

class MeanRNNPB:
    """A deterministic "RNNPB": the PB of a sequence is the mean of its first channels."""

    input_size = 6
    pb_size = 2

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed

    def _pbs(self, sequences):
        return np.array([np.asarray(s, float)[:, :self.pb_size].mean(axis=0)
                         for s in sequences])

    def train(self, sequences, pbs_init=None, epochs=None):
        return self._pbs(sequences)

    def recognize(self, sequences, candidate_pbs=None):
        return self._pbs(sequences)

    def generate(self, pbs, initial_inputs, lengths):
        out = []
        for pb, x0, n in zip(np.asarray(pbs, float), np.asarray(initial_inputs, float), lengths):
            row = np.asarray(x0, float).copy()
            row[:self.pb_size] = pb
            out.append(np.vstack([x0, np.tile(row, (int(n) - 1, 1))]))
        return out

    def prediction_error(self, sequences, pbs):
        gen = self.generate(pbs, [s[0] for s in sequences], [len(s) for s in sequences])
        return np.array([float(np.mean((g - s) ** 2)) for g, s in zip(gen, sequences)])

    def state(self):
        return {"seed": np.array(self.seed)}

    def load_state(self, state):
        self.seed = int(state["seed"])


class EachAloneClusterer:
    """Every point its own cluster: valid labels, never merges."""

    def cluster(self, points, distance_threshold):
        return np.arange(len(np.asarray(points)))


class SameShapeTeacher:
    """Rewards an answer whose source demonstration has the shown one's shape."""

    def feedback(self, demo, response):
        return 1 if response.source.rsplit("/", 1)[0] == demo.shape else -1


class LinearIK:
    """Joint angles linear in the pen-tip target: enough for the sensorimotor path."""

    joint_names = ("a", "b", "c", "d")
    lower = np.full(4, -10.0)
    upper = np.full(4, 10.0)

    def solve(self, points, q0=None):
        p = np.asarray(points, float)
        return np.column_stack([p[:, 1], p[:, 2], p[:, 1] + p[:, 2], p[:, 1] - p[:, 2]])

    def forward(self, q):
        q = np.asarray(q, float)
        return np.stack([np.zeros(q.shape[:-1]), q[..., 0], q[..., 1]], axis=-1)


class EchoSimulator:
    """Reaches every commanded posture exactly."""

    def execute(self, joint_path, dt):
        q = np.asarray(joint_path, float)
        return Execution(q, LinearIK().forward(q), float(dt))

    def render(self, execution, width=480, height=360):
        return np.zeros((height, width, 3), np.uint8)

    def close(self):
        pass


class Recorder:
    """A plugin implementing every hook: registers the stand-ins, records every call."""

    def __init__(self) -> None:
        self.calls: dict[str, list] = defaultdict(list)

    @hookimpl
    def iloci_register_perceptual_models(self, registry):
        self.calls["iloci_register_perceptual_models"].append(registry.kind)
        registry.add("mean-rnnpb", MeanRNNPB, summary="test stand-in")

    @hookimpl
    def iloci_register_clusterers(self, registry):
        self.calls["iloci_register_clusterers"].append(registry.kind)
        registry.add("each-alone", EachAloneClusterer, summary="test stand-in")

    @hookimpl
    def iloci_register_teachers(self, registry):
        self.calls["iloci_register_teachers"].append(registry.kind)
        registry.add("same-shape", SameShapeTeacher, summary="test stand-in")

    @hookimpl
    def iloci_register_ik_solvers(self, registry):
        self.calls["iloci_register_ik_solvers"].append(registry.kind)
        registry.add("linear", LinearIK, summary="test stand-in")

    @hookimpl
    def iloci_register_simulators(self, registry):
        self.calls["iloci_register_simulators"].append(registry.kind)
        registry.add("echo", EchoSimulator, summary="test stand-in")

    @hookimpl
    def iloci_register_executors(self, registry):
        self.calls["iloci_register_executors"].append(registry.kind)

    @hookimpl
    def iloci_register_robots(self, registry):
        from iloci.sensorimotor.robots.presets import nao_v32_right_arm
        self.calls["iloci_register_robots"].append(registry.kind)
        registry.add("recorded-arm", nao_v32_right_arm, summary="test stand-in", joints=4,
                     plane="given")

    @hookimpl
    def iloci_on_interaction(self, event):
        self.calls["iloci_on_interaction"].append(event)

    @hookimpl
    def iloci_on_rehearsal(self, event):
        self.calls["iloci_on_rehearsal"].append(event)

    @hookimpl
    def iloci_on_fold_finished(self, event):
        self.calls["iloci_on_fold_finished"].append(event)

    @hookimpl
    def iloci_add_commands(self, subparsers):
        self.calls["iloci_add_commands"].append(subparsers)
        p = subparsers.add_parser("recorded", help="test stand-in")
        p.set_defaults(func=lambda args: 0)

    @hookimpl
    def iloci_make_executor(self, name, jobs, address):
        self.calls["iloci_make_executor"].append((name, jobs, address))
        return None  # not ours: the kernel's local executor runs the fold


CONFIG = {
    "perceptual_model": {"name": "mean-rnnpb"},
    "clusterer": {"name": "each-alone"},
    "teacher": {"name": "same-shape"},
    "ik": {"name": "linear"},
    "simulator": {"name": "echo"},
    "learner": {"num_threshold": 1},
    "data": {"shapes": ["GShape", "Sine"]},
    "evaluation": {"folds": 2, "seed": 0},
}


@pytest.fixture(scope="module")
def run():
    """(recorder, metrics, results) of a one-fold evaluation with the stand-ins."""
    from iloci.config import load_config
    from iloci.evaluation.evaluate import evaluate

    recorder = Recorder()
    pm = get_plugin_manager(autoload=False, plugins=[recorder])
    # names resolved against pm's registry: evaluate() given a mapping would
    # resolve them against the installed plugins only
    config = load_config(CONFIG, registry=get_registry(pm))
    metrics, results = evaluate(config, jobs=1, folds=[0], baseline=False,
                                plugin_manager=pm)
    make_parser(plugin_manager=pm)  # the command line asks plugins for their commands
    return recorder, metrics, results


def test_the_recorder_implements_every_hookspec():
    implemented = {n for n in dir(Recorder) if n.startswith("iloci_")}
    assert implemented == set(hookspec_names())


@pytest.mark.parametrize("hook", hookspec_names())
def test_hook_is_called(run, hook):
    recorder, _, _ = run
    assert recorder.calls[hook], f"{hook} was never called"


def test_registration_hooks_register_through_a_bound_view(run):
    recorder, _, _ = run
    pm = get_plugin_manager(autoload=False, plugins=[recorder])
    registry = get_registry(pm)
    for kind, name in [("perceptual_model", "mean-rnnpb"), ("clusterer", "each-alone"),
                       ("teacher", "same-shape"), ("ik", "linear"),
                       ("simulator", "echo"), ("robot", "recorded-arm")]:
        spec = registry.get(kind, name)
        assert spec.plugin == pm.get_name(recorder) and spec.kind == kind
    assert set(recorder.calls["iloci_register_teachers"]) == {"teacher"}
    assert set(recorder.calls["iloci_register_robots"]) == {"robot"}
    assert dict(registry.get("robot", "recorded-arm").facts) == {"joints": 4, "plane": "given"}


def test_observers_see_the_whole_learning_phase(run):
    recorder, metrics, results = run
    fold = results[0]
    interactions = recorder.calls["iloci_on_interaction"]
    assert all(isinstance(e, InteractionEvent) for e in interactions)
    # every learning demonstration ends in exactly one final action, in stream order
    final = [e for e in interactions if e.action != "next_guess"]
    assert [e.demo for e in final] == fold.learn
    assert [e.step for e in final] == list(range(len(fold.learn)))
    # the feedbacks the observer saw are the fold's reinforcement signal
    assert [e.feedback for e in interactions if e.feedback] == fold.feedbacks
    rehearsals = recorder.calls["iloci_on_rehearsal"]
    assert all(isinstance(e, RehearsalEvent) for e in rehearsals)
    assert len(rehearsals) == fold.rehearsals > 0
    assert {e.reason for e in rehearsals} <= {"new_concept", "new_exemplar", "clustering"}
    (done,) = recorder.calls["iloci_on_fold_finished"]
    assert isinstance(done, FoldEvent)
    assert done.fold == 0 and done.metrics["ccr"] == metrics["ccr_folds"][0]


@pytest.mark.filterwarnings("ignore:iloci plugin .* implements iloci_make_executor")
def test_extension_hooks_add_a_command_and_are_asked_for_the_executor(run):
    recorder, _, _ = run
    assert recorder.calls["iloci_make_executor"] == [("local", 1, None)]
    pm = get_plugin_manager(autoload=False, plugins=[recorder])
    args = make_parser(plugin_manager=pm).parse_args(["recorded"])
    assert args.func(args) == 0


def test_a_plugin_command_named_like_a_kernel_command_is_a_plugin_error():
    from iloci.errors import PluginError

    class Clash:
        @hookimpl
        def iloci_add_commands(self, subparsers):
            subparsers.add_parser("evaluate")

    with pytest.raises(PluginError, match="clashes"):
        make_parser(plugin_manager=get_plugin_manager(autoload=False, plugins=[Clash()]))


# -- observer faults -------------------------------------------------------------

class FaultyObserver:
    """An observer plugin whose interaction hook raises after the first event."""

    def __init__(self) -> None:
        self.seen = 0

    @hookimpl
    def iloci_on_interaction(self, event):
        self.seen += 1
        raise RuntimeError("observer broke")


def _agent_with(*plugins):
    import iloci
    from iloci.config import load_config
    pm = get_plugin_manager(autoload=False, plugins=[Recorder(), *plugins])
    return iloci.build(load_config(CONFIG, registry=get_registry(pm)), plugin_manager=pm)


def test_observer_fault_leaves_learning_committed_and_names_hook_and_plugin():
    from iloci.data import load_lasa
    from iloci.errors import ObserverError

    faulty = FaultyObserver()
    agent = _agent_with(faulty)
    recorder = agent.plugin_manager.get_plugins() - {faulty}
    recorder = next(p for p in recorder if isinstance(p, Recorder))
    demos = load_lasa(["GShape", "Sine"])
    saved = []
    with pytest.raises(ObserverError) as e:
        agent.teach(demos[:3], on_change=saved.append)
    err = e.value
    assert err.hook == "iloci_on_interaction" and err.plugin == "extra-1"
    assert "iloci_on_interaction" in str(err) and "'extra-1'" in str(err)
    assert "observer broke" in str(err) and "do not teach it again" in str(err)
    # committed, not half: the first demonstration is learned, once, and was saved
    assert agent.memory.demonstrations_seen == 1 and len(agent.memory) == 1
    assert err.outcome.demo == demos[0].key and saved == [err.outcome]
    # every other observer was told everything about it
    assert [ev.demo for ev in recorder.calls["iloci_on_interaction"]] == [demos[0].key]
    assert len(recorder.calls["iloci_on_rehearsal"]) == 1
    assert faulty.seen == 1
    # the caller goes on after the learned demonstration: nothing is learned twice
    agent.plugin_manager.unregister(faulty)
    report = agent.teach(demos[1:3])
    assert agent.memory.demonstrations_seen == 3
    assert [o.demo for o in report.outcomes] == [d.key for d in demos[1:3]]


def test_an_observer_fault_in_an_evaluation_says_the_evaluation_stopped():
    """A plugin audit: in `iloci evaluate` the fault's advice was the teach's ("do not teach
    it again"), which means nothing there: the evaluation stops."""
    from iloci.data import load_lasa
    from iloci.errors import ObserverError
    from iloci.evaluation.fold import run_fold

    pm = get_plugin_manager(autoload=False, plugins=[Recorder(), FaultyObserver()])
    demos = load_lasa(["GShape", "Sine"])
    with pytest.raises(ObserverError, match=r"observer hook iloci_on_interaction of plugin "
                       r"'extra-1' raised RuntimeError: observer broke in fold 3's learning "
                       r"\(at 'GShape/0'\); the evaluation stopped there\.") as e:
        run_fold(CONFIG, 3, demos[:2], demos[2:4], baseline=False, details=False,
                 plugin_manager=pm)
    assert "do not teach it again" not in str(e.value)


def test_events_of_a_step_that_fails_are_not_sent():
    """A teacher fault leaves the memory as it was, and observers hear nothing of it."""
    from iloci.data import load_lasa
    from iloci.errors import FeedbackError

    agent = _agent_with()
    recorder = next(p for p in agent.plugin_manager.get_plugins() if isinstance(p, Recorder))
    demos = load_lasa(["GShape", "Sine"])
    agent.teach(demos[:1])
    before = len(recorder.calls["iloci_on_interaction"])

    class Bad:
        def feedback(self, demo, response):
            return 0

    agent.teacher = Bad()
    with pytest.raises(FeedbackError):
        agent.learn(demos[8])
    assert len(recorder.calls["iloci_on_interaction"]) == before
    assert agent.memory.demonstrations_seen == 1


# -- a memory refuses settings that change what its entries mean ----------------------

@pytest.mark.parametrize("change, conflict", [
    ({"sensorimotor": {"steps": 80}}, "sensorimotor.steps = 50 in the memory, 80 in the config"),
    ({"sensorimotor": {"resample": "time"}}, "sensorimotor.resample"),
    ({"sensorimotor": {"smoothing_window": 11}}, "sensorimotor.smoothing_window"),
])
def test_memory_refuses_a_config_that_changes_its_meaning(tmp_path, change, conflict):
    import iloci
    from iloci.config import load_config
    from iloci.data import load_lasa
    from iloci.errors import ConfigError, MemoryConfigError

    agent = _agent_with()
    agent.teach(load_lasa(["GShape"])[:2])
    path = agent.save(tmp_path / "m.npz")
    before = path.read_bytes()
    pm = agent.plugin_manager
    registry = get_registry(pm)
    changed = {**CONFIG, **{k: {**CONFIG.get(k, {}), **v} for k, v in change.items()}}
    with pytest.raises(MemoryConfigError, match=conflict) as e:
        iloci.Agent.load(path, load_config(changed, registry=registry), plugin_manager=pm)
    assert isinstance(e.value, ConfigError) and "unchanged" in str(e.value)
    assert path.read_bytes() == before
    # settings that only steer learning may change
    fine = {**CONFIG, "learner": {"num_threshold": 5, "k_cutoff": 0.3},
            "teacher": CONFIG["teacher"]}
    again = iloci.Agent.load(path, load_config(fine, registry=registry), plugin_manager=pm)
    assert again.memory.demonstrations_seen == 2


def test_memory_conflicts_cover_component_memory_keys():
    from iloci.config import load_config, memory_conflicts
    from iloci.errors import MissingBackendError
    from iloci.params import RNNPBParams

    assert {"hidden", "context", "pb", "pb_bound", "input_size"} == set(RNNPBParams.MEMORY_KEYS)
    registry = get_registry()
    models = registry.names("perceptual_model")
    if not models:
        pytest.skip("no perceptual model installed")
    try:
        saved = load_config({"perceptual_model": {"name": models[0]}}).to_dict()
    except MissingBackendError as exc:  # a tox env without the default clusterer or IK
        pytest.skip(str(exc))
    cfg = load_config({"perceptual_model": {"name": models[0], "pb": 3, "epochs": 9}})
    assert memory_conflicts(saved, cfg) == [
        "perceptual_model.pb = 4 in the memory, 3 in the config"]  # epochs may change
    del saved["perceptual_model"]["pb"]  # a key the saved config leaves out: its default
    assert memory_conflicts(saved, cfg) == [
        "perceptual_model.pb = 4 in the memory, 3 in the config"]


def test_teach_gives_files_of_one_name_distinct_keys(tmp_path):
    import math
    agent = _agent_with()
    paths = []
    for person, r in (("s01", 1.0), ("s02", 2.0)):
        (tmp_path / person).mkdir()
        p = tmp_path / person / "circle.csv"
        p.write_text("x,y\n" + "\n".join(f"{r * math.cos(a)},{r * math.sin(a)}"
                                          for a in np.linspace(0, 6, 40)))
        paths.append(str(p))
    report = agent.teach(paths)
    assert [o.demo for o in report.outcomes] == ["circle/0", "circle/1"]
