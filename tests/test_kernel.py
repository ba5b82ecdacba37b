"""The kernel: plugin manager, registry, config, errors, CLI basics."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

import iloci
from iloci import hookimpl
from iloci.config import Config, load_config, to_toml
from iloci.errors import (ConfigError, MissingBackendError, PluginError,
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


def test_disable_autoload_env(monkeypatch):
    monkeypatch.setenv("ILOCI_DISABLE_PLUGIN_AUTOLOAD", "1")
    pm = get_plugin_manager()
    assert set(dict(pm.list_name_plugin())) == {"iloci.teachers"}


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
    for kind, name in [("perceptual_model", "jax-rnnpb"), ("clusterer", "scipy"),
                       ("ik_solver", "pinocchio")]:
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
    with pytest.raises(ConfigError, match="teacher.p must be float"):
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
    with pytest.raises((ConfigError, UnknownComponentError, MissingBackendError)):
        cfg.replace(learner={"num_threshold": 0})


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
