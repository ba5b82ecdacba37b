"""Bad input of every kind gets one clear iloci error (exit 2), or is read right.

Each test is the right value of a case tried as a new user would (a config
saved with a byte-order mark, ``nan`` in a config, a pen-tablet CSV export,
a European-locale CSV, one folder per person, a plugin with a misnamed hook
argument, two distributions with one entry-point name), generalised to its
whole kind.
"""

from __future__ import annotations

import codecs
import dataclasses
import math
import sys
import textwrap
import typing
import warnings
from pathlib import Path

import numpy as np
import pytest

import iloci

from iloci.config import _PLAIN_SECTIONS, load_config
from iloci.data import load_trajectory
from iloci.data.files import shared_stems, trajectory_files
from iloci.errors import (
    ConfigError,
    InvalidDemonstrationError,
    MissingBackendError,
    PluginError,
    PluginNotLoadedError,
    UnknownComponentError,
)
from iloci.plugins import PluginInfo, PluginLoadWarning, get_plugin_manager, get_registry
from iloci.registry import Registry

# ------------------------------------------------------------------ config files


def test_toml_with_utf8_byte_order_mark_is_read(tmp_path):
    f = tmp_path / "bom.toml"
    f.write_bytes(codecs.BOM_UTF8 + b"[learner]\nk_cutoff = 0.7\n")
    from iloci.interfaces import COMPONENT_KINDS  # no back end looked up: runs in bare too
    assert load_config(f, supplied=COMPONENT_KINDS).learner.k_cutoff == 0.7


def test_toml_in_utf16_says_so(tmp_path):
    f = tmp_path / "u16.toml"
    f.write_bytes("[learner]\nk_cutoff = 0.7\n".encode("utf-16"))
    with pytest.raises(ConfigError, match="UTF-16.*save it as UTF-8"):
        load_config(f)


def _float_fields(cls: type) -> list[str]:
    hints = typing.get_type_hints(cls)
    return [f.name for f in dataclasses.fields(cls) if hints.get(f.name) is float]


def _every_float_setting() -> list[tuple[str, dict, str]]:
    """(section, other keys, key) of every float setting, plain and registered schemas."""
    out = [(sec, {}, key) for sec, cls in _PLAIN_SECTIONS.items() for key in _float_fields(cls)]
    from iloci.interfaces import COMPONENT_KINDS
    registry = get_registry()
    for sec in COMPONENT_KINDS:
        for spec in registry.specs(sec):
            if spec.params is not None:
                out += [(sec, {"name": spec.name}, key) for key in _float_fields(spec.params)]
    return out


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_no_float_setting_takes_nan_or_inf(bad):
    settings = _every_float_setting()
    assert len(settings) >= 4  # k_cutoff, similarity_threshold, train_fraction, noisy p
    for sec, base, key in settings:
        with pytest.raises(ConfigError, match=rf"{sec}\.{key} must be a finite number") as e:
            load_config({sec: {**base, key: bad}})
        assert e.value.key == f"{sec}.{key}"


def test_nan_config_is_refused_by_config_check(tmp_path, cli):
    f = tmp_path / "nan.toml"
    f.write_text("[learner]\nsimilarity_threshold = nan\n")
    out = cli("config", "check", str(f))
    assert out.returncode == 2
    assert "learner.similarity_threshold must be a finite number, got nan" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("section, values, match", [
    ("evaluation", {"seed": -1}, "seed must be >= 0"),
    ("evaluation", {"folds": 1}, "folds must be >= 2"),
    ("evaluation", {"train_fraction": 1.5}, r"train_fraction must be in \(0, 1\)"),
    ("evaluation", {"jobs": -1}, "jobs must be >= 1, or 0 for one per CPU core"),
    ("evaluation", {"seed": 2**70}, "64-bit integer"),
    ("evaluation", {"seed": "0"}, "evaluation.seed must be an integer"),
    ("evaluation", {"seed": 1.5}, "evaluation.seed must be an integer"),
    ("evaluation", {"seeds": 1}, "unknown key 'evaluation.seeds'.*Did you mean 'seed'"),
    ("learner", {"k_cutoff": -0.5}, "k_cutoff must be >= 0"),
    ("learner", {"num_threshold": True}, "learner.num_threshold must be an integer"),
    ("sensorimotor", {"steps": 2}, r"steps must be in 3..10000"),
    ("sensorimotor", {"steps": 10**9}, r"steps must be in 3..10000"),
    ("learner", {"rehearsal_epochs": 10**8}, r"rehearsal_epochs must be in 0..10000000"),
    ("evaluation", {"k_cutoff": 0.5}, r"unknown key 'evaluation.k_cutoff'.*'k_cutoff' is "
                                      r"a key of \[learner\]: move it there"),
    ("learner", {"evaluation": {"seed": 3}}, r"evaluation.seed under \[learner\] is read as "
                                             r"learner.evaluation.seed"),
    ("sensorimotor", {"robot": "nao"}, r"unknown key 'sensorimotor.robot'"),
    ("robot", {"plane": "manual"}, r"plane must be 'auto' or \[x, y, z, width, height\]"),
    ("sensorimotor", {"smoothing_window": 4}, "odd number"),
    ("data", {"shapes": ["GShape", "Gshape"]}, "unknown LASA shape 'Gshape'"),
    ("data", {"shapes": ["GShape", "GShape"]}, "names a shape twice"),
    ("data", {"shapes": "GShape"}, "data.shapes must be"),
])
def test_out_of_range_or_mistyped_values_name_their_key(section, values, match):
    with pytest.raises(ConfigError, match=match):
        load_config({section: values})


@pytest.mark.usefixtures("default_back_ends")  # the perceptual model's own settings
@pytest.mark.parametrize("values, match", [
    ({"hidden": 10**8}, r"hidden must be at most 4,096, got 100,000,000"),
    ({"epochs": 2**63 - 1}, r"epochs must be at most 10,000,000"),
    ({"recognition_starts": 10**6}, r"recognition_starts must be at most 1,000"),
    ({"k_cutoff": 0.4}, r"'k_cutoff' is a key of \[learner\]: move it there"),
])
def test_sizes_no_machine_holds_are_refused_before_anything_runs(values, match):
    """hidden = 10^8 failed with numpy's MemoryError (26 GiB), epochs = 2^63 - 1 with
    'array is too big', steps = 10^9 hung: each passed `iloci config check`."""
    with pytest.raises(ConfigError, match=match):
        load_config({"perceptual_model": values})


def test_a_json_or_yaml_config_and_utf16_without_a_mark_say_what_they_are(tmp_path):
    from iloci.interfaces import COMPONENT_KINDS  # no back end looked up: runs in bare too
    for name, text in (("c.json", '{"learner": {"k_cutoff": 0.7}}'),
                       ("c.yaml", "learner:\n  k_cutoff: 0.7\n")):
        (tmp_path / name).write_text(text)
        kind = "JSON" if name.endswith("json") else "YAML"
        with pytest.raises(ConfigError, match=rf"this is a {kind} file \({name}\), and iloci "
                                              r"reads TOML"):
            load_config(tmp_path / name, supplied=COMPONENT_KINDS)
    f = tmp_path / "u16.toml"
    f.write_bytes("[learner]\nk_cutoff = 0.7\n".encode("utf-16-le"))  # no byte-order mark
    with pytest.raises(ConfigError, match=r"looks like UTF-16 text \(every other byte is "
                                          r"zero\)"):
        load_config(f, supplied=COMPONENT_KINDS)


def test_input_size_must_match_the_encoding():
    registry = get_registry()
    models = registry.names("perceptual_model")
    if not models:
        pytest.skip("no perceptual model installed")
    with pytest.raises(ConfigError, match="input_size is 5.*6 features"):
        iloci.build({"perceptual_model": {"name": models[0], "input_size": 5}})


# ------------------------------------------------------------------ trajectory files

CIRCLE = [(300 + 100 * math.cos(a), 200 + 100 * math.sin(a))
          for a in np.linspace(0, 2 * math.pi, 40, endpoint=False)]


def _write(tmp_path: Path, name: str, text: str, encoding: str = "utf-8") -> Path:
    f = tmp_path / name
    f.write_bytes(text.encode(encoding))
    return f


def test_header_columns_are_taken_by_name_pressure_ignored(tmp_path):
    rows = "\n".join(f"{x:.3f},{y:.3f},0.5" for x, y in CIRCLE)
    d = load_trajectory(_write(tmp_path, "p.csv", "x,y,pressure\n" + rows))
    assert np.allclose(d.positions, CIRCLE, atol=1e-3)
    assert np.array_equal(d.times, np.arange(len(CIRCLE)))  # no time column: indices


def test_time_column_in_milliseconds_anywhere(tmp_path):
    rows = "\n".join(f"{x:.3f},{y:.3f},{8 * i}" for i, (x, y) in enumerate(CIRCLE))
    d = load_trajectory(_write(tmp_path, "t.csv", "x,y,t_ms\n" + rows))
    assert np.allclose(d.positions, CIRCLE, atol=1e-3)
    assert np.allclose(d.times, 0.008 * np.arange(len(CIRCLE)))
    rows = "\n".join(f"0.1,{i * 10},{x:.3f},{y:.3f}" for i, (x, y) in enumerate(CIRCLE))
    d = load_trajectory(_write(tmp_path, "u.csv", "pressure,t [ms],X,Y\n" + rows))
    assert np.allclose(d.times, 0.01 * np.arange(len(CIRCLE)))


@pytest.mark.parametrize("header", ["a,b,c", "x,pressure,tilt", "t,u,v,w"])
def test_ambiguous_header_is_named_in_the_error(tmp_path, header):
    n = len(header.split(","))
    rows = "\n".join(",".join(str(i + k) for k in range(n)) for i in range(5))
    with pytest.raises(InvalidDemonstrationError, match=f"header '{header}'.*x and y"):
        load_trajectory(_write(tmp_path, "h.csv", header + "\n" + rows))


@pytest.mark.parametrize("name, text, encoding", [
    ("semicolon decimal comma", "t;x;y\n" + "\n".join(
        f"{0.02 * i:.3f};{x:.3f};{y:.3f}".replace(".", ",")
        for i, (x, y) in enumerate(CIRCLE)), "utf-8"),
    ("tabs", "t\tx\ty\n" + "\n".join(
        f"{0.02 * i}\t{x}\t{y}" for i, (x, y) in enumerate(CIRCLE)), "utf-8"),
    ("spaces", "\n".join(f"{0.02 * i}  {x} {y}" for i, (x, y) in enumerate(CIRCLE)),
     "utf-8"),
    ("utf-8 bom, crlf", "t,x,y\r\n" + "\r\n".join(
        f"{0.02 * i},{x},{y}" for i, (x, y) in enumerate(CIRCLE)), "utf-8-sig"),
    ("utf-16 with bom", "t,x,y\n" + "\n".join(
        f"{0.02 * i},{x},{y}" for i, (x, y) in enumerate(CIRCLE)), "utf-16"),
    ("utf-16-le without bom", "t;x;y\n" + "\n".join(
        f"{0.02 * i};{x};{y}" for i, (x, y) in enumerate(CIRCLE)), "utf-16-le"),
    ("quoted header, pipes", '"time"|"x"|"y"\n' + "\n".join(
        f"{0.02 * i}|{x}|{y}" for i, (x, y) in enumerate(CIRCLE)), "utf-8"),
])
def test_dialects_and_encodings(tmp_path, name, text, encoding):
    d = load_trajectory(_write(tmp_path, "d.csv", text, encoding))
    assert np.allclose(d.positions, CIRCLE, atol=1e-3), name
    assert np.allclose(d.times, 0.02 * np.arange(len(CIRCLE)), atol=1e-3), name


@pytest.mark.parametrize("text, match", [
    ("t;x;y\n0,0;1,0;0,0\n0,1;1,5;abc\n0,2;2,0;1,0\n",
     r"line 3, column 'y': 'abc' is not a number \(.*separated by ';', decimal commas\)"),
    ("x,y\n0,0\n1,\n2,0\n", "line 3, column 'y': '' is not a number"),
    ("x,y\n0,0\n1,1\n2,0,5\n", "line 4 has 3 fields where the header has 2"),
    ("t,x,y\n0,0,0\n1,1,1\n0.5,2,0\n", "line 4: time 0.5 is before the previous row's 1"),
    ("x,y\n", "at least 3"),
    ("", "holds no rows"),
])
def test_bad_values_name_their_line(tmp_path, text, match):
    with pytest.raises(InvalidDemonstrationError, match=match):
        load_trajectory(_write(tmp_path, "bad.csv", text))


def test_bad_file_on_the_command_line_exits_2(tmp_path, cli):
    f = _write(tmp_path, "bad.csv", "a,b,c\n1,2,3\n2,3,4\n3,4,5\n")
    out = cli("show", str(f), "--out", str(tmp_path / "x.png"))
    assert out.returncode == 2 and "header 'a,b,c'" in out.stderr


def test_files_of_one_name_in_different_folders_get_distinct_keys(tmp_path):
    paths = []
    for person in ("s01", "s02"):
        (tmp_path / person).mkdir()
        for shape in ("circle", "zigzag"):
            p = tmp_path / person / f"{shape}.csv"
            p.write_text("x,y\n0,0\n1,1\n2,0\n")
            paths.append(p)
    files = trajectory_files(paths + [paths[0]])
    assert [f.key for f in files] == ["circle/0", "zigzag/0", "circle/1", "zigzag/1",
                                      "circle/0"]  # the same file again: same key
    assert [f.load().key for f in files] == [f.key for f in files]
    groups = shared_stems(files)
    assert [[f.path for f in g] for g in groups] == [[str(paths[0]), str(paths[2])],
                                                     [str(paths[1]), str(paths[3])]]


def test_teach_names_files_of_one_name(tmp_path, cli):
    pytest.importorskip("iloci_pinocchio")
    for person in ("s01", "s02"):
        (tmp_path / person).mkdir()
        (tmp_path / person / "circle.csv").write_text(
            "x,y\n" + "\n".join(f"{x},{y}" for x, y in CIRCLE))
    from iloci.data.streams import resolve_demos
    items = resolve_demos([str(tmp_path / "s01/circle.csv"), "GShape/1",
                           str(tmp_path / "s02/circle.csv")])
    assert [getattr(i, "key", None) for i in items] == ["circle/0", "GShape/1", "circle/1"]


# ------------------------------------------------------------------ plugins


def _fake_distribution(site: Path, dist: str, module: str, entry_name: str,
                       source: str, version: str = "0.1") -> None:
    """An installed-looking distribution: a module, dist-info and an ``iloci`` entry point."""
    site.mkdir(exist_ok=True)
    (site / f"{module}.py").write_text(textwrap.dedent(source))
    info = site / f"{dist.replace('-', '_')}-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: {version}\n")
    (info / "entry_points.txt").write_text(f"[iloci]\n{entry_name} = {module}\n")


BAD_ARGNAME = """
    from iloci import hookimpl

    class Strict:
        def feedback(self, demo, response):
            return 1

    @hookimpl
    def iloci_register_teachers(reg):          # the spec's argument is `registry`
        reg.add("strict", Strict, summary="rewards everything")
"""

GOOD_TEACHER = """
    from iloci import hookimpl

    class Kind:
        def feedback(self, demo, response):
            return 1

    @hookimpl
    def iloci_register_teachers(registry):
        registry.add("{name}", Kind, summary="rewards everything")
"""


@pytest.fixture
def site(tmp_path, monkeypatch):
    path = tmp_path / "site"
    path.mkdir()
    monkeypatch.syspath_prepend(str(path))
    monkeypatch.delenv("ILOCI_BLOCK_PLUGINS", raising=False)
    monkeypatch.delenv("ILOCI_DISABLE_PLUGIN_AUTOLOAD", raising=False)
    return path


def test_plugin_with_a_misnamed_hook_argument_is_skipped_and_listed(site, cli):
    _fake_distribution(site, "iloci-badarg", "iloci_badarg", "badarg", BAD_ARGNAME)
    _fake_distribution(site, "iloci-kind", "iloci_kind", "kind",
                       GOOD_TEACHER.format(name="kind"))
    with pytest.warns(PluginLoadWarning, match=r"'badarg'.*iloci-badarg.*\{'reg'\}"):
        pm = get_plugin_manager()
    info = pm.iloci_plugin_info["badarg"]
    assert info.status == "failed" and "reg" in info.error
    assert pm.get_plugin("badarg") is None
    registry = get_registry(pm)
    assert "strict" not in registry.names("teacher")
    assert {"kind", "oracle"} <= set(registry.names("teacher"))  # the rest works
    env = {"PYTHONPATH": str(site)}
    out = cli("plugins", env=env)
    assert out.returncode == 0, out.stderr
    assert "failed: plugin 'badarg' (iloci-badarg)" in out.stdout
    assert "warning: iloci plugin 'badarg'" in out.stderr and "Traceback" not in out.stderr
    # once, although the parser and the command each build a plugin manager
    assert out.stderr.count("iloci plugin 'badarg'") == 1, out.stderr
    if _defaults_installed():
        ok = site / "ok.toml"
        ok.write_text("[teacher]\nname = 'kind'\n")
        out = cli("config", "check", str(ok), env=env)
        assert out.returncode == 0, out.stderr


def test_plugin_failing_in_its_registration_hook_is_isolated(site):
    _fake_distribution(site, "iloci-boom", "iloci_boom", "boom", """
        from iloci import hookimpl

        @hookimpl
        def iloci_register_teachers(registry):
            registry.add("early", "x:y")
            raise RuntimeError("boom")
    """)
    _fake_distribution(site, "iloci-dup", "iloci_dup", "dup",
                       GOOD_TEACHER.format(name="oracle"))
    pm = get_plugin_manager()
    with pytest.warns(PluginLoadWarning) as caught:
        registry = get_registry(pm)
    text = " ".join(str(w.message) for w in caught)
    assert "'boom'" in text and "RuntimeError: boom" in text
    # a component name registered twice names both plugins and distributions
    assert "'oracle' is registered twice: by plugin 'iloci.teachers' (distribution iloci) " \
           "and by plugin 'dup' (distribution iloci-dup)" in text
    assert "early" not in registry.names("teacher")  # what it registered is withdrawn
    assert registry.get("teacher", "oracle").plugin == "iloci.teachers"
    assert pm.iloci_plugin_info["boom"].status == "failed"


def test_a_name_two_installed_plugins_register_is_used_by_neither(site):
    """A plugin audit: two installed plugins both registering teacher 'labelfile' -- the
    one whose entry point sorted first won, the other was skipped whole (its other
    components too), and a config naming 'labelfile' ran the impostor with exit 0."""
    two = GOOD_TEACHER + """
    @hookimpl
    def iloci_register_clusterers(registry):
        registry.add("mine", "x:y", summary="the real plugin's other component")
"""
    _fake_distribution(site, "iloci-impostor", "iloci_impostor", "aaa", GOOD_TEACHER.format(
        name="labelfile"))
    _fake_distribution(site, "iloci-real", "iloci_real", "real", two.format(name="labelfile"))
    with pytest.warns(PluginLoadWarning, match=r"teacher 'labelfile' is registered by 2 "
                      r"installed plugins: plugin 'aaa' \(distribution iloci-impostor\) and "
                      r"plugin 'real' \(distribution iloci-real\)"):
        registry = get_registry(get_plugin_manager())
    assert "labelfile" not in registry.names("teacher")
    assert "mine" in registry.names("clusterer")          # the rest of each plugin works
    with pytest.raises(PluginError, match="does not guess which one is meant.*"
                                          "ILOCI_BLOCK_PLUGINS=real"):
        load_config({"teacher": {"name": "labelfile"}}, registry=registry)
    # blocking one gives the name to the other
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PluginLoadWarning)
        registry = get_registry(get_plugin_manager(block=["aaa"]))
    assert registry.get("teacher", "labelfile").plugin == "real"


def test_entry_point_name_collision_loads_both_and_names_both(site):
    _fake_distribution(site, "iloci-aaa", "iloci_aaa", "same", GOOD_TEACHER.format(name="a1"))
    _fake_distribution(site, "iloci-bbb", "iloci_bbb", "same", GOOD_TEACHER.format(name="b1"),
                       version="0.2")
    with pytest.warns(PluginLoadWarning, match=r"named 'same': iloci-aaa 0.1 and iloci-bbb 0.2"):
        pm = get_plugin_manager()
    registry = get_registry(pm)
    assert {"a1", "b1"} <= set(registry.names("teacher"))
    assert registry.get("teacher", "b1").plugin == "same@iloci-bbb"
    # blocking the entry-point name blocks both
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PluginLoadWarning)
        registry = get_registry(get_plugin_manager(block=["same"]))
    assert not {"a1", "b1"} & set(registry.names("teacher"))


def test_blocked_or_not_autoloaded_plugin_is_reported_as_such(site):
    _fake_distribution(site, "iloci-kind", "iloci_kind", "kind",
                       GOOD_TEACHER.format(name="kind"))
    registry = get_registry(get_plugin_manager(block=["kind"]))
    with pytest.raises(UnknownComponentError, match="'kind'.*blocked by ILOCI_BLOCK_PLUGINS"):
        load_config({"teacher": {"name": "kind"}}, registry=registry)
    registry = get_registry(get_plugin_manager(autoload=False))
    with pytest.raises(UnknownComponentError, match="plugin 'kind'.*autoloading is off"):
        load_config({"teacher": {"name": "kind"}}, registry=registry)


@pytest.mark.parametrize("status, match", [
    ("blocked", "blocked by ILOCI_BLOCK_PLUGINS"),
    ("not autoloaded", "autoloading is off"),
    ("failed", "failed to load: ImportError: x"),
])
def test_first_party_back_end_not_loaded_is_not_called_not_installed(status, match):
    registry = Registry()
    registry.unloaded = [PluginInfo("scipy", "iloci-scipy", "0.1.0", "ImportError: x", status)]
    with pytest.raises(PluginNotLoadedError, match=match) as e:
        registry.get("clusterer", "scipy")
    assert "not installed" not in str(e.value)
    assert isinstance(e.value, MissingBackendError)
    with pytest.raises(MissingBackendError, match="not installed"):
        Registry().get("clusterer", "scipy")


def _defaults_installed() -> bool:
    """Whether the default config's back ends are installed (not in `tox -e bare`)."""
    try:
        with warnings.catch_warnings():  # a test's faulty plugins may be on sys.path
            warnings.simplefilter("ignore", PluginLoadWarning)
            load_config(None)
    except MissingBackendError:
        return False
    return True


def test_config_check_reports_a_back_end_library_that_is_missing(site, cli):
    if not _defaults_installed():
        pytest.skip("the default config's back ends are not installed")
    _fake_distribution(site, "iloci-needs", "iloci_needs", "needs", """
        from iloci import hookimpl

        @hookimpl
        def iloci_register_teachers(registry):
            registry.add("needy", "iloci_needs_impl:T", requires=("no_such_module_xyz",),
                         install="pip install no-such-module-xyz")
    """)
    f = site / "c.toml"
    f.write_text("[teacher]\nname = 'needy'\n")
    out = cli("config", "check", str(f), env={"PYTHONPATH": str(site)})
    assert out.returncode == 2
    assert "teacher 'needy' needs no_such_module_xyz, which is not installed" in out.stderr
    assert "pip install no-such-module-xyz" in out.stderr


def test_plugins_given_by_the_caller_still_raise(site):
    from iloci import hookimpl

    class Typo:
        @hookimpl
        def iloci_register_teachers(self, reg):
            pass

    with pytest.raises(PluginError, match="reg"):
        get_plugin_manager(autoload=False, plugins=[Typo()])


def test_evaluate_checks_its_report_libraries_before_fold_0(monkeypatch):
    import importlib.util

    from iloci.evaluation.report import check_report_extras
    # every other report module counts as installed, so the message is the
    # same whether or not this environment has scikit-learn (tox -e bare has not)
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name in ("dtaidistance", "matplotlib")
                        else object())
    with pytest.raises(MissingBackendError, match="matplotlib, dtaidistance.*--no-baseline"):
        check_report_extras(baseline=True)
    with pytest.raises(MissingBackendError, match="matplotlib") as e:
        check_report_extras(baseline=False)
    assert "dtaidistance" not in str(e.value)


def test_evaluate_refuses_an_unwritable_out_dir_before_fold_0(tmp_path, cli):
    for plugin in ("iloci_native", "iloci_scipy", "iloci_pinocchio"):  # the default config's
        pytest.importorskip(plugin)
    blocker = tmp_path / "file"
    blocker.write_text("")
    out = cli("evaluate", "--out", str(blocker / "sub"), "--quiet")
    assert out.returncode == 2 and "--out" in out.stderr and "fold" not in out.stderr


if sys.platform == "win32":  # pragma: no cover
    pytest.skip("POSIX paths", allow_module_level=True)


def test_agent_teach_numbers_files_of_one_name_too(tmp_path):
    from iloci.agent.stepwise import _as_demonstration
    from iloci.data.files import TrajectoryFile
    seen: dict = {}
    paths = []
    for person in ("s01", "s02"):
        (tmp_path / person).mkdir()
        p = tmp_path / person / "circle.csv"
        p.write_text("x,y\n0,0\n1,1\n2,0\n")
        paths.append(p)
    files = [trajectory_files([p], seen)[0] for p in paths + paths[:1]]
    assert [f.key for f in files] == ["circle/0", "circle/1", "circle/0"]
    assert all(isinstance(f, TrajectoryFile) for f in files)
    assert _as_demonstration(files[1], 0).key == "circle/1"


def test_evaluate_checks_every_back_end_before_fold_0(monkeypatch):
    """A configured component whose library is missing stops evaluate() before any data."""
    from iloci import hookimpl
    from iloci.evaluation import evaluate as ev

    class NeedsLib:
        @hookimpl
        def iloci_register_teachers(self, registry):
            registry.add("needy", "x_mod:T", requires=("no_such_module_xyz",),
                         install="pip install no-such-module-xyz")

    pm = get_plugin_manager(plugins=[NeedsLib()])
    if not _defaults_installed():
        pytest.skip("the default config's back ends are not installed")
    config = load_config({"teacher": {"name": "needy"}}, registry=get_registry(pm))

    def no_data(*a, **k):
        raise AssertionError("LASA was loaded before the back ends were checked")

    monkeypatch.setattr("iloci.data.load_lasa", no_data)
    monkeypatch.setattr("iloci.evaluation.evaluate.load_lasa", no_data)
    with pytest.raises(MissingBackendError, match="teacher 'needy' needs no_such_module_xyz"):
        ev.evaluate(config, plugin_manager=pm, jobs=1)


PARAMS_TEACHERS = """
    from dataclasses import dataclass
    from iloci import hookimpl

    class Kind:
        def __init__(self, **kw):
            pass

        def feedback(self, demo, response):
            return 1

    @dataclass(frozen=True)
    class NeedsPath:
        path: str                    # no default: hooks.md asks for one

    @dataclass(frozen=True)
    class Buggy:
        rate: int = 1

        def validate(self):
            return self.rate + "x"   # a fault of the plugin's code, not of the config

    @hookimpl
    def iloci_register_teachers(registry):
        registry.add("needs-path", Kind, params=NeedsPath, summary="needs a path")
        registry.add("buggy", Kind, params=Buggy, summary="a faulty validate")
"""


def test_a_plugins_setting_without_default_or_faulty_validate_is_said_as_such(site):
    """A plugin's params without a default blamed the user's config with Python's
    "__init__() missing 1 required positional argument"; a TypeError in its validate()
    was printed as a fault of the user's config file."""
    from iloci.errors import PluginError
    from iloci.interfaces import COMPONENT_KINDS

    _fake_distribution(site, "iloci-params", "iloci_params", "params", PARAMS_TEACHERS)
    registry = get_registry(get_plugin_manager())
    others = tuple(k for k in COMPONENT_KINDS if k != "teacher")
    with pytest.raises(ConfigError, match=r"\[teacher\] needs path: this teacher has no "
                                          r"default for it; set path = \.\.\. under "):
        load_config({"teacher": {"name": "needs-path"}}, registry=registry, supplied=others)
    assert load_config({"teacher": {"name": "needs-path", "path": "a.csv"}},
                       registry=registry, supplied=others).teacher.params.path == "a.csv"
    with pytest.raises(PluginError, match=r"iloci_params.Buggy.validate\(\) failed with "
                                          r"TypeError: .*not of the config"):
        load_config({"teacher": {"name": "buggy"}}, registry=registry, supplied=others)


def test_a_plugin_commands_failure_names_the_plugin(site, cli):
    _fake_distribution(site, "iloci-cmd", "iloci_cmd", "cmd", """
        from iloci import hookimpl

        def run(args):
            return {}["missing thing"]

        @hookimpl
        def iloci_add_commands(subparsers):
            subparsers.add_parser("mycmd").set_defaults(func=run)
    """)
    out = cli("mycmd", env={"PYTHONPATH": str(site)})
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert "failed: KeyError: 'missing thing'\nin `iloci mycmd`, a command of plugin 'cmd' " \
           "(iloci-cmd, module iloci_cmd), not of iloci: report it to its authors, or leave " \
           "the plugin out with ILOCI_BLOCK_PLUGINS=cmd" in out.stderr


@pytest.mark.usefixtures("default_back_ends")
def test_a_fold_named_twice_and_a_memory_path_that_is_a_folder_are_refused(tmp_path, cli):
    from iloci.errors import InvalidInputError
    from iloci.evaluation.evaluate import evaluate

    with pytest.raises(InvalidInputError, match=r"fold\(s\) 0 named more than once"):
        evaluate(None, folds=[0, 0])
    (tmp_path / "m.npz").mkdir()
    out = cli("show", str(tmp_path / "m.npz"))
    assert out.returncode == 2 and "is a directory, not a memory file" in out.stderr


@pytest.mark.usefixtures("default_back_ends")
def test_config_check_says_what_evaluate_would_refuse_of_the_data(tmp_path, cli):
    """`iloci config check` said ok to a [data] path that does not exist, 8 folds on LASA
    and untaught leaving fewer than 2 shapes; `iloci evaluate` then refused each."""
    for name, text, said in (
            ("path", '[data]\npath = "no/such/dir"\n', "[data] path 'no/such/dir' does not "
                                                       "exist"),
            ("folds", "[evaluation]\nfolds = 8\n", "LASA has 7 demonstrations of each "
                                                   "shape, so at most 7 folds"),
            ("untaught", '[data]\nshapes = ["GShape", "Sine", "Leaf_1"]\n[evaluation]\n'
                         "untaught = 2\n", "untaught = 2 leaves fewer than 2 of the 3 LASA "
                                           "shapes to learn; use at most 1")):
        f = tmp_path / f"{name}.toml"
        f.write_text(text)
        out = cli("config", "check", str(f))
        assert out.returncode == 2 and said in out.stderr, out.stderr


@pytest.mark.usefixtures("default_back_ends")
def test_a_teacher_flag_typo_is_said_as_the_flags(tmp_path, cli):
    """It was said as an error of the config file, which does not name a teacher."""
    cfg = tmp_path / "ok.toml"
    cfg.write_text("[learner]\nk_cutoff = 0.5\n")
    out = cli("teach", "--config", str(cfg), "--teacher", "oracel", "--memory",
              str(tmp_path / "m.npz"), "GShape/0")
    assert out.returncode == 2
    assert out.stderr.startswith("error: --teacher oracel: unknown teacher 'oracel'"), out.stderr
    assert "Did you mean 'oracle'?" in out.stderr and not (tmp_path / "m.npz").exists()
