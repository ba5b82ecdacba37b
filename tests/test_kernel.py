"""The kernel: plugin manager, registry, config, errors, CLI basics."""

from __future__ import annotations

import dataclasses
from pathlib import Path
import subprocess
import sys
import textwrap
from typing import Literal

import pytest

import iloci
from iloci import hookimpl
from iloci.config import Config, load_config, to_toml
from iloci.errors import (ConfigError, InvalidInputError, MissingBackendError, PluginError,
                          UnknownComponentError)
from iloci.plugins import get_plugin_manager, get_registry
from iloci.teachers import OracleTeacher


HEAVY = ("torch", "jax", "pinocchio", "pybullet", "mujoco", "sklearn")


def test_import_iloci_imports_no_heavy_library():
    code = textwrap.dedent(f"""
        import sys
        import iloci, iloci.cli, iloci.config, iloci.plugins, iloci.interfaces
        from iloci.plugins import get_registry
        get_registry()            # loads every installed plugin module
        iloci.cli.make_parser()   # and every CLI subcommand
        heavy = [m for m in {HEAVY!r} if m in sys.modules]
        print(",".join(heavy))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "", f"imported at import/registration time: {out.stdout}"


def test_the_learner_depends_on_interfaces_not_on_a_plugin():
    """The learning loop imports no plugin module, the built-in teachers' included."""
    code = ("import sys, iloci.concepts.learner, iloci.agent; "
            "print(','.join(m for m in ('iloci.teachers', 'iloci.commands') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == ""


def test_one_table_of_component_kinds():
    """Config sections, registry kinds, hooks and Config fields all come from COMPONENT_KINDS."""
    import dataclasses

    from test_hooks import hookspec_names

    from iloci.interfaces import ALL_KINDS, COMPONENT_KINDS, KINDS
    assert KINDS == ("perceptual_model", "clusterer", "teacher", "ik", "simulator")
    # every registration hook is a kind of the one registry; executors and robots
    # are kinds that are no component section of a config
    assert {k.hook for k in ALL_KINDS.values()} == {
        n for n in hookspec_names() if n.startswith("iloci_register_")}
    assert list(ALL_KINDS) == [*KINDS, "executor", "robot"]
    fields = [f.name for f in dataclasses.fields(Config)]
    assert fields[:len(KINDS)] == list(KINDS)
    assert list(Config().to_dict())[:len(KINDS)] == list(KINDS)
    assert [k for k, v in COMPONENT_KINDS.items() if v.optional] == ["simulator"]
    from iloci.registry import FIRST_PARTY
    assert {kind for kind, _ in FIRST_PARTY} == set(ALL_KINDS) - {"teacher"}
    reg = get_registry()
    with pytest.raises(InvalidInputError, match="kinds are perceptual_model, clusterer, "
                       "teacher, ik, simulator"):
        reg.get("ik_solver", "pinocchio")


def test_hookimpl_is_exported_and_pm_has_no_side_effects():
    assert iloci.hookimpl is hookimpl
    pm1, pm2 = get_plugin_manager(), get_plugin_manager()
    assert pm1 is not pm2
    assert "iloci.teachers" in dict(pm1.list_name_plugin())


def test_builtin_teachers_register_through_hooks():
    reg = get_registry(get_plugin_manager(autoload=False))
    assert reg.names("teacher") == ["console", "noisy", "oracle"]
    assert reg.get("teacher", "oracle").distribution == "iloci"


def test_block_named_plugin(monkeypatch):
    monkeypatch.setenv("ILOCI_BLOCK_PLUGINS", "iloci.teachers")
    reg = get_registry(get_plugin_manager(autoload=False))
    assert reg.names("teacher") == []
    reg = get_registry(get_plugin_manager(autoload=False, block=["iloci.teachers"]))
    assert reg.names("teacher") == []


def test_disable_autoload_env_keeps_only_iloci_own_plugins(monkeypatch):
    from iloci.plugins import DEFAULT_PLUGINS, FIRST_PARTY_DISTRIBUTIONS
    monkeypatch.setenv("ILOCI_DISABLE_PLUGIN_AUTOLOAD", "1")
    monkeypatch.delenv("ILOCI_BLOCK_PLUGINS", raising=False)
    pm = get_plugin_manager()
    loaded = set(dict(pm.list_name_plugin()))
    info = pm.iloci_plugin_info
    # the built-ins and every installed first-party back end, nothing else
    assert set(DEFAULT_PLUGINS) <= loaded
    for name in loaded - set(DEFAULT_PLUGINS):
        assert info[name].distribution in FIRST_PARTY_DISTRIBUTIONS
    for name, i in info.items():
        if i.distribution in FIRST_PARTY_DISTRIBUTIONS:
            assert i.status == "loaded", (name, i)
        elif i.distribution != "iloci":
            assert i.status == "not autoloaded", (name, i)
    assert set(dict(get_plugin_manager(autoload=False).list_name_plugin())) == \
        set(DEFAULT_PLUGINS) == {"iloci.teachers", "iloci.evaluation.executors",
                                 "iloci.sensorimotor.robots.presets"}


def test_disable_autoload_env_keeps_installed_back_ends(monkeypatch):
    pytest.importorskip("iloci_scipy")
    monkeypatch.setenv("ILOCI_DISABLE_PLUGIN_AUTOLOAD", "1")
    monkeypatch.delenv("ILOCI_BLOCK_PLUGINS", raising=False)
    assert "scipy" in get_registry(get_plugin_manager()).names("clusterer")


def test_misspelled_hook_is_an_error():
    class Typo:
        @hookimpl
        def iloci_register_teacher(self, registry):  # missing "s"
            pass

    with pytest.raises(PluginError, match="iloci_register_teacher"):
        get_plugin_manager(autoload=False, plugins=[Typo()])


def test_duplicate_name_is_an_error():
    class Dup:
        @hookimpl
        def iloci_register_teachers(self, registry):
            registry.add("oracle", OracleTeacher)

    pm = get_plugin_manager(autoload=False, plugins=[Dup()])
    with pytest.raises(PluginError, match="registered twice"):
        get_registry(pm)


def _registry_with_teacher_requiring(module: str):
    class NeedsLib:
        @hookimpl
        def iloci_register_teachers(self, registry):
            registry.add("fancy", "fancy_teacher_pkg.mod:Fancy", requires=(module,),
                         install="pip install fancy-teacher")

    return get_registry(get_plugin_manager(autoload=False, plugins=[NeedsLib()]))


def test_missing_backend_names_pip_command():
    reg = _registry_with_teacher_requiring("no_such_module_iloci_test")
    cfg = load_config({"teacher": {"name": "fancy"}, "perceptual_model": {}},
                      registry=_full(reg))
    with pytest.raises(MissingBackendError, match="pip install fancy-teacher") as exc:
        reg.build("teacher", cfg.teacher.name, cfg.teacher.params)
    assert "no_such_module_iloci_test" in str(exc.value)


def _full(reg):
    """Registry plus stand-in registrations for the non-teacher defaults.

    Only component *names* are needed to validate a config; nothing is built.
    """
    from iloci.config import DEFAULT_NAMES
    for kind in ("perceptual_model", "clusterer", "ik"):
        name = DEFAULT_NAMES[kind]
        if (kind, name) not in reg:
            reg.add(kind, name, "iloci_missing_for_test:X", plugin="test")
    return reg


def test_unknown_component_name_did_you_mean():
    reg = _full(get_registry(get_plugin_manager(autoload=False)))
    with pytest.raises(UnknownComponentError) as exc:
        load_config({"teacher": {"name": "orcale"}}, registry=reg)
    msg = str(exc.value)
    assert "teacher" in msg and "'oracle'" in msg and "Did you mean 'oracle'?" in msg
    assert "console" in msg and "noisy" in msg


def test_unknown_config_key_names_key_and_file(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("[learner]\nk_cutof = 0.4\n")
    reg = _full(get_registry(get_plugin_manager(autoload=False)))
    with pytest.raises(ConfigError) as exc:
        load_config(p, registry=reg)
    assert "learner.k_cutof" in str(exc.value) and str(p) in str(exc.value)
    assert "Did you mean 'k_cutoff'" in str(exc.value)


def test_unknown_component_param_is_rejected_by_its_schema():
    reg = _full(get_registry(get_plugin_manager(autoload=False)))
    with pytest.raises(ConfigError, match="teacher.q"):
        load_config({"teacher": {"name": "noisy", "q": 0.2}}, registry=reg)
    with pytest.raises(ConfigError, match=r"p must be in \[0, 1\]"):
        load_config({"teacher": {"name": "noisy", "p": 2.0}}, registry=reg)
    with pytest.raises(ConfigError, match="teacher.p must be a number"):
        load_config({"teacher": {"name": "noisy", "p": "high"}}, registry=reg)


def test_malformed_toml_reports_line(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[learner]\nk_cutoff = 0.5\nnum_threshold = = 3\n")
    with pytest.raises(ConfigError) as exc:
        load_config(p, registry=_full(get_registry(get_plugin_manager(autoload=False))))
    assert exc.value.line == 3
    assert f"{p}:3" in str(exc.value)


def test_defaults_are_the_papers():
    cfg = load_config(None, registry=_full(get_registry(get_plugin_manager(autoload=False))))
    assert (cfg.learner.k_cutoff, cfg.learner.num_threshold,
            cfg.learner.similarity_threshold) == (0.5, 3, 0.1)
    assert (cfg.evaluation.folds, cfg.evaluation.train_fraction) == (5, 0.2)
    from iloci.params import RNNPBParams
    p = RNNPBParams()
    assert (p.input_size, p.pb, p.context, p.hidden) == (6, 4, 25, 60)


def test_config_show_round_trips(tmp_path):
    reg = _full(get_registry(get_plugin_manager(autoload=False)))
    cfg = load_config({"teacher": {"name": "noisy", "p": 0.25},
                       "learner": {"k_cutoff": 0.75}}, registry=reg)
    p = tmp_path / "resolved.toml"
    p.write_text(to_toml(cfg))
    again = load_config(p, registry=reg)
    assert again.to_dict() == cfg.to_dict()
    assert again.teacher.params.p == 0.25
    assert isinstance(again, Config) and again.source == str(p)


def test_replace_validates():
    reg = _full(get_registry(get_plugin_manager(autoload=False)))
    cfg = load_config(None, registry=reg)
    with pytest.raises(ConfigError, match="num_threshold"):
        cfg.replace(learner={"num_threshold": 0})


def test_replace_resolves_through_the_config_own_registry():
    # a teacher registered only in this registry, not by any installed plugin
    reg = _full(get_registry(get_plugin_manager(autoload=False)))
    reg.add("teacher", "lab-teacher", "iloci.teachers:OracleTeacher", plugin="lab")
    cfg = load_config({"teacher": {"name": "lab-teacher"}}, registry=reg)
    again = cfg.replace(learner={"k_cutoff": 0.5})
    assert again.teacher.name == "lab-teacher" and again.learner.k_cutoff == 0.5
    assert again == load_config(again.to_dict(), registry=reg)
    with pytest.raises(UnknownComponentError, match="lab-teachr"):
        cfg.replace(teacher={"name": "lab-teachr"})


def test_replace_keeps_supplied_sections_unresolved():
    reg = _full(get_registry(get_plugin_manager(autoload=False)))
    cfg = load_config({"ik": {"name": "robot-stack-ik", "tol": 1e-4}}, registry=reg,
                      supplied=["ik"])
    again = cfg.replace(learner={"k_cutoff": 0.5})
    assert again.ik.name == "robot-stack-ik" and again.learner.k_cutoff == 0.5


def test_cli_unknown_component_exit_2(tmp_path, cli):
    p = tmp_path / "c.toml"
    p.write_text('[teacher]\nname = "orcale"\n')
    # Validate only the teacher: leave the other sections to whatever is installed.
    res = cli("config", "check", str(p))
    assert res.returncode == 2
    assert "Traceback" not in res.stderr
    assert "Did you mean 'oracle'?" in res.stderr and "unknown teacher" in res.stderr


def test_cli_malformed_toml_exit_2(tmp_path, cli):
    p = tmp_path / "c.toml"
    p.write_text("[learner\n")
    res = cli("config", "check", str(p))
    assert res.returncode == 2 and f"{p}:1" in res.stderr and "Traceback" not in res.stderr


def test_cli_missing_file_exit_2(tmp_path, cli):
    res = cli("config", "show", str(tmp_path / "nope.toml"))
    assert res.returncode == 2 and "not found" in res.stderr


def test_cli_plugins_table(cli):
    res = cli("plugins")
    assert res.returncode == 0, res.stderr
    header = res.stdout.splitlines()[0].split()
    assert header == ["KIND", "NAME", "DISTRIBUTION", "VERSION", "STATUS"]
    assert any(line.split()[:2] == ["teacher", "oracle"] for line in res.stdout.splitlines())


# -- build() with component objects -------------------------------------------------

def _real_components() -> dict:
    """Real first-party components, built through the default plugin manager."""
    full = get_registry()
    try:
        return {"perceptual_model": full.build("perceptual_model", "jax-rnnpb",
                                               {"epochs": 5}, seed=0),
                "clusterer": full.build("clusterer", "scipy"),
                "ik": full.build("ik", "pinocchio")}
    except MissingBackendError as exc:
        pytest.skip(str(exc))


def test_build_with_component_objects_never_looks_up_their_configured_names():
    objects = _real_components()
    # only iloci's built-in teachers: no configured back end is registered here
    bare = get_plugin_manager(autoload=False)
    config = {"perceptual_model": {"name": "jax-rnnpb", "epochs": 5},
              "ik": {"name": "pinocchio", "max_error": 1e-3},
              "simulator": {"name": "pybullet"}}
    agent = iloci.build(config, plugin_manager=bare, simulator=None, **objects)
    assert agent.perceptual_model is objects["perceptual_model"]
    assert agent.clusterer is objects["clusterer"]
    assert agent.ik_solver is objects["ik"]
    assert agent.simulator is None
    assert isinstance(agent.teacher, OracleTeacher)  # not given: built from the config
    # the sections of given components are kept as written (saved with the memory)
    assert agent.config.ik.to_dict() == {"name": "pinocchio", "max_error": 1e-3}
    assert agent.config.simulator.name == "pybullet"
    # the repr names what the agent holds, not the configured name of a given object
    text = repr(agent)
    assert f"ik={type(objects['ik']).__name__}(...)" in text and "simulator=None" in text
    assert "teacher='oracle'" in text and "'pinocchio'" not in text
    # not even a name that no plugin registers anywhere is looked up
    agent = iloci.build({"ik": {"name": "my-robot-ik", "gain": 2}, "clusterer": {"name": "x"}},
                        plugin_manager=bare, **objects)
    assert agent.ik_solver is objects["ik"] and agent.config.ik.name == "my-robot-ik"
    # a component that is not given is still looked up, and still must be installed
    with pytest.raises(MissingBackendError, match="pinocchio"):
        iloci.build(config, plugin_manager=bare, simulator=None,
                    perceptual_model=objects["perceptual_model"],
                    clusterer=objects["clusterer"])


def test_build_rejects_objects_that_are_not_components_in_one_error():
    class HalfIK:
        joint_names = ("a", "b")

        def solve(self, points, q0=None):
            return points

    bare = get_plugin_manager(autoload=False)
    # checked before any name is looked up: the missing default back ends are not the error
    with pytest.raises(InvalidInputError) as exc:
        iloci.build(None, plugin_manager=bare, ik=HalfIK(), teacher=OracleTeacher,
                    clusterer=None)
    msg = str(exc.value)
    assert "ik=" in msg and "HalfIK" in msg and "IKSolver" in msg
    assert "lacks forward, lower, upper (" in msg             # all it lacks, and only that
    assert "teacher=" in msg and "instance" in msg          # the class, not an instance
    assert "clusterer=None" in msg and "required" in msg    # only a simulator may be None


def test_errors_survive_a_pickle_round_trip():
    """Errors raised in evaluation worker processes reach the caller as themselves."""
    import pickle

    errors = [UnknownComponentError("teacher", "orcale", ["oracle"]),
              MissingBackendError("IK solver", "pinocchio", ["pinocchio"], "pip install x"),
              ConfigError("bad value", source="c.toml", key="learner.k_cutoff", line=3)]
    errors[0].args = ("c.toml: [teacher] name: " + errors[0].args[0],)  # as load_config does
    for exc in errors:
        again = pickle.loads(pickle.dumps(exc))
        assert type(again) is type(exc) and str(again) == str(exc)
        assert vars(again) == vars(exc)


def test_versions_list_every_plugin_distribution_and_what_it_requires():
    """metrics.json's versions: read from metadata, so a third-party plugin is listed too."""
    from iloci.evaluation.evaluate import versions
    from iloci.plugins import plugin_infos

    pm = get_plugin_manager()
    out = versions(pm)
    dists = {i.distribution for i in plugin_infos(pm).values() if i.distribution}
    assert dists <= set(out), dists - set(out)
    assert {"python", "iloci", "numpy", "scipy", "pluggy"} <= set(out)
    import importlib.metadata as md
    for dist in dists - {"iloci"}:
        for req in md.requires(dist) or ():
            name = req.split(";")[0].split(">")[0].split("=")[0].split("<")[0].strip()
            try:
                assert md.metadata(name)["Name"] in out, (dist, name)
            except md.PackageNotFoundError:
                pass


def test_preload_imports_the_configured_back_ends_and_nothing_is_built():
    """`import iloci` imports no back end; iloci.preload imports the configured ones."""
    pytest.importorskip("iloci_torch")
    pytest.importorskip("iloci_pinocchio")
    pytest.importorskip("iloci_scipy")
    code = textwrap.dedent("""
        import sys, iloci
        assert "torch" not in sys.modules and "pinocchio" not in sys.modules
        done = iloci.preload({"perceptual_model": {"name": "torch-rnnpb"}})
        print(",".join(done))
        assert "torch" in sys.modules and "pinocchio" in sys.modules
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["perceptual_model=torch-rnnpb,clusterer=scipy,"
                                  "teacher=oracle,ik=pinocchio"]
    with pytest.raises(ConfigError):
        iloci.preload({"learner": {"k_cutoff": "high"}})


@dataclasses.dataclass(frozen=True)
class WithPath:
    file: Path = Path("labels.csv")


@dataclasses.dataclass(frozen=True)
class BadDefault:
    ratio: float = "0.5"  # type: ignore[assignment]


@dataclasses.dataclass(frozen=True)
class WithMode:
    mode: Literal["strict", "lenient"] = "strict"


def test_a_plugins_settings_must_be_what_a_toml_config_can_give():
    """A plugin audit: a settings field typed pathlib.Path could never be set from TOML, and
    its default failed to be written to metrics.json after the whole run (a traceback from
    json) and to the memory after a teach (its learning lost); a Literal field took any
    string; a float field defaulting to "0.5" reached the teacher unchecked."""
    def plugin_with(params):
        class Plugin:
            @hookimpl
            def iloci_register_teachers(self, registry):
                registry.add("typed", OracleTeacher, params=params)
        return Plugin()

    for params, said in ((WithPath, r"file: Path is not a type a TOML config can give"),
                         (BadDefault, r"ratio: the default '0.5' is not a number")):
        pm = get_plugin_manager(autoload=False, plugins=[plugin_with(params)])
        with pytest.raises(PluginError, match=r"the settings of teacher 'typed' \("
                           + params.__qualname__ + r"\) cannot be a \[teacher\] section: "
                           + said):
            get_registry(pm)

    from iloci.registry import validate_params
    registry = get_registry(get_plugin_manager(autoload=False,
                                               plugins=[plugin_with(WithMode)]))
    spec = registry.get("teacher", "typed")
    with pytest.raises(ConfigError, match=r"teacher.mode must be one of 'strict', 'lenient', "
                                          r"got 'bogus'"):
        validate_params(spec, {"mode": "bogus"})
    assert validate_params(spec, {"mode": "lenient"}).mode == "lenient"
