"""Faults of the world around the method (issue 29), one test per kind, on inputs made here.

Robot descriptions (mimic joints, unexpanded xacro, missing limits, continuous joints,
massless links, relative paths), Ray sweeps (tests/plugins/test_ray.py), huge strokes,
files from a newer iloci, unwritable output folders, file names that are not UTF-8, and
plugin hooks that return the wrong type.
"""

from __future__ import annotations

from pathlib import Path
import re

import numpy as np
import pytest

from iloci.cli import main
from iloci.config import load_config
from iloci.errors import InvalidInputError
from iloci.sensorimotor.robots import check_robot, describe_robot


# -- robot descriptions ------------------------------------------------------------------

def _arm(path: Path, *, limit: str = 'lower="-2" upper="2"', j3_kind: str = "revolute",
         j3_extra: str = "", mass: str = "0.4", lim_j2: str | None = None) -> Path:
    """A 3-joint planar arm (base, a, b, c, pen) whose joints can be spoiled one by one."""
    def link(name: str) -> str:
        inertial = (f'<inertial><mass value="{mass}"/><inertia ixx="1e-3" ixy="0" ixz="0" '
                    'iyy="1e-3" iyz="0" izz="1e-3"/></inertial>') if mass else ""
        return f'<link name="{name}">{inertial}</link>'

    def joint(name: str, parent: str, child: str, x: float, kind: str = "revolute",
              lim: str = limit, extra: str = "") -> str:
        return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
                f'<child link="{child}"/><origin xyz="{x} 0 0.1"/><axis xyz="0 1 0"/>'
                f'<limit {lim} effort="1" velocity="1"/>{extra}</joint>')

    path.write_text(
        '<?xml version="1.0"?>\n<robot name="spoilt">'
        + "".join(link(n) for n in ("base", "a", "b", "c")) + '<link name="pen"/>'
        + joint("s1", "base", "a", 0.0) + joint("s2", "a", "b", 0.2, lim=lim_j2 or limit)
        + joint("s3", "b", "c", 0.2, kind=j3_kind, extra=j3_extra)
        + '<joint name="tip" type="fixed"><parent link="c"/><child link="pen"/>'
          '<origin xyz="0.1 0 0"/></joint></robot>\n')
    return path


def _toml(path: Path, urdf: str, simulator: str = "none") -> Path:
    path.write_text(f'[robot]\nname = "spoilt"\nurdf = "{urdf}"\ntip_frame = "pen"\n'
                    f'[simulator]\nname = "{simulator}"\n')
    return path


def _assert_check_and_robots_name(cfg, urdf, names, capsys):
    """`config check` and `iloci robots` each refuse (exit 2), naming the file and ``names``."""
    for argv in (["config", "check", str(cfg)], ["robots", "--show", "--config", str(cfg)]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert str(urdf) in err and "Traceback" not in err
        for name in names:
            assert name in err, (argv, name, err)


@pytest.mark.parametrize("spoil, simulator, names", [
    ({"j3_extra": '<mimic joint="s2" multiplier="-0.5" offset="0.1"/>'}, "none",
     ["'s3' mimics joint 's2'", "fixed joint"]),
    ({"lim_j2": 'lower="${-pi/2}" upper="${pi/2}"'}, "none",
     ["<joint name='s2'>", "${-pi/2}", "run xacro"]),
    ({"limit": ""}, "none", ["'s1' (revolute), 's2' (revolute), 's3' (revolute)",
                              "<limit lower="]),
    ({"lim_j2": 'lower="0.5" upper="0.5"'}, "none", ["'s2' [0.5, 0.5]", "lower < upper"]),
    ({"j3_kind": "continuous"}, "none", ["'s3' are continuous", 'type="revolute"']),
    ({"mass": ""}, "mujoco", ["'a', 'b', 'c'", "<inertial>", "pybullet"]),
], ids=["mimic", "xacro", "no-limits", "zero-range", "continuous", "no-inertials"])
@pytest.mark.usefixtures("default_back_ends")
def test_urdf_faults_are_named_by_config_check_and_robots(tmp_path, capsys, spoil, simulator,
                                                         names):
    urdf = _arm(tmp_path / "arm.urdf", **spoil)
    cfg = _toml(tmp_path / "arm.toml", "arm.urdf", simulator)
    _assert_check_and_robots_name(cfg, urdf, names, capsys)


def test_xacro_tags_and_substitution_args_are_caught(tmp_path):
    ns = _arm(tmp_path / "ns.urdf.xacro").read_text().replace(
        '<robot name="spoilt">',
        '<robot name="spoilt" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="L" value="0.2"/>')
    (tmp_path / "ns.urdf.xacro").write_text(ns)
    with pytest.raises(InvalidInputError, match=r"<xacro:property>.*xacro ns.urdf.xacro > ns.urdf"):
        describe_robot(tmp_path / "ns.urdf.xacro", tip_frame="pen")
    undeclared = ns.replace(' xmlns:xacro="http://www.ros.org/wiki/xacro"', "")
    (tmp_path / "bare.urdf").write_text(undeclared)
    with pytest.raises(InvalidInputError, match="xacro: tags.*run xacro"):
        describe_robot(tmp_path / "bare.urdf", tip_frame="pen")
    arg = _arm(tmp_path / "arg.urdf").read_text().replace('xyz="0.2 0 0.1"',
                                                          'xyz="$(arg reach) 0 0.1"', 1)
    (tmp_path / "arg.urdf").write_text(arg)
    with pytest.raises(InvalidInputError, match=r"\$\(arg reach\).*run xacro"):
        describe_robot(tmp_path / "arg.urdf", tip_frame="pen")


def test_mimic_joint_off_the_pen_chain_is_accepted(tmp_path):
    # a gripper finger mimicking another, hanging off the arm: no effect on the pen tip
    text = _arm(tmp_path / "g.urdf").read_text().replace("</robot>", (
        '<link name="f1"/><link name="f2"/>'
        '<joint name="g1" type="prismatic"><parent link="c"/><child link="f1"/>'
        '<axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>'
        '<joint name="g2" type="prismatic"><parent link="c"/><child link="f2"/>'
        '<axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/>'
        '<mimic joint="g1"/></joint></robot>'))
    (tmp_path / "g.urdf").write_text(text)
    robot = describe_robot(tmp_path / "g.urdf", tip_frame="pen")
    assert robot.joint_names == ("s1", "s2", "s3")



def _spoilt(tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    f = tmp_path / "arm.urdf"
    text = _arm(f).read_text()
    assert old in text
    f.write_text(text.replace(old, new, count))
    return f


@pytest.mark.parametrize("old, new, names", [
    ('name="s2" type="revolute"', 'name="s2" type="planar"',
     ["'s2' (planar)", "fixed joint", "base_frame below it"]),
    ('name="s1" type="revolute"', 'name="s1" type="floating"', ["'s1' (floating)"]),
    ('name="s2" type="revolute"', 'name="s2" type="revolut"',
     ["type 'revolut'", "Did you mean 'revolute'?"]),
    ('<link name="pen"/>', '<link name="pen"/><link name="b"/>', ["link 'b' is defined twice"]),
    ('name="s3"', 'name="s2"', ["joint 's2' is defined twice"]),
    ('<link name="pen"/>', '<link name="pen"/><link name="x"/><joint name="x" type="fixed">'
     '<parent link="a"/><child link="c"/></joint>', ["link 'c' is the child of joints"]),
    ('<limit lower="-2" upper="2"', '<limit lower="2" upper="-2"', ["[2, -2] (lower above "
                                                                   "upper: swapped?)"]),
    ('<limit lower="-2" upper="2"', '<limit lower="-inf" upper="2"', ["not a finite number"]),
    ('<robot name="spoilt">', '<robot name="spoilt"><!-- caf\xe9 -->',
     ["not valid XML", "not UTF-8 (byte 0xe9", 'encoding="ISO-8859-1"']),
], ids=["planar", "floating", "bad-type", "dup-link", "dup-joint", "two-parents", "inverted",
        "infinite", "latin1-undeclared"])
@pytest.mark.usefixtures("default_back_ends")
def test_more_urdf_faults_are_named(tmp_path, capsys, old, new, names):
    urdf = _spoilt(tmp_path, old, new)
    if "caf" in new:
        urdf.write_bytes(urdf.read_text().encode("latin-1"))
    cfg = _toml(tmp_path / "arm.toml", "arm.urdf")
    _assert_check_and_robots_name(cfg, urdf, names, capsys)


def test_a_chain_without_a_movable_joint_says_where_one_is(tmp_path):
    _arm(tmp_path / "arm.urdf")
    with pytest.raises(InvalidInputError, match=r"between the base frame 'b' and the pen-tip "
                       r"frame 'b'.*tip_frame below a movable joint \('c'\)"):
        describe_robot(tmp_path / "arm.urdf", base_frame="b", tip_frame="b")
    with pytest.raises(InvalidInputError, match=r"'a' does not hang below the base frame 'c'"):
        describe_robot(tmp_path / "arm.urdf", base_frame="c", tip_frame="a")


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16", "iso-8859-1"])
def test_a_urdf_in_any_declared_encoding_reaches_the_ik(tmp_path, encoding):
    """Pinocchio's own parser reads UTF-8 only: it is given the text as iloci decoded it."""
    pytest.importorskip("pinocchio")
    from iloci.plugins import get_registry

    text = _arm(tmp_path / "plain.urdf").read_text().replace(
        '<?xml version="1.0"?>', f'<?xml version="1.0" encoding="{encoding.upper()}"?>'
        if encoding != "utf-8-sig" else '<?xml version="1.0"?>').replace(
        '<robot name="spoilt">', '<robot name="spoilt"><!-- caf\xe9 -->')
    (tmp_path / "arm.urdf").write_bytes(text.encode(encoding))
    robot = describe_robot(tmp_path / "arm.urdf", tip_frame="pen")
    ik = get_registry().build("ik", "pinocchio", robot=robot)
    q = np.array([0.3, -0.4, 0.5])
    plain = get_registry().build("ik", "pinocchio",
                                 robot=describe_robot(tmp_path / "plain.urdf", tip_frame="pen"))
    assert np.allclose(ik.forward(q), plain.forward(q))

@pytest.mark.usefixtures("default_back_ends")
def test_relative_urdf_is_read_beside_the_config_from_any_folder(tmp_path, monkeypatch):
    (tmp_path / "robots").mkdir()
    _arm(tmp_path / "robots" / "arm.urdf")
    cfg_file = _toml(tmp_path / "robots" / "arm.toml", "arm.urdf")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    cfg = load_config(cfg_file)
    assert cfg.robot.urdf == str((tmp_path / "robots" / "arm.urdf").resolve())
    assert check_robot(cfg.robot).joint_names == ("s1", "s2", "s3")
    # what a memory stores: the absolute path, so the saved config loads from anywhere
    saved = cfg.to_dict()
    monkeypatch.chdir(tmp_path)
    assert load_config(saved).robot.urdf == cfg.robot.urdf
    assert np.isfinite(check_robot(load_config(saved).robot).lower).all()


# -- size: a huge stroke ------------------------------------------------------------------

def _stroke(n: int, seed: int = 0) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    rng = np.random.default_rng(seed)
    return np.column_stack([np.cos(6 * t) * (1 + t), np.sin(4 * t)]) + \
        rng.normal(0.0, 0.002, (n, 2))


def test_a_huge_stroke_is_read_in_linear_time_close_to_the_exact_fit(monkeypatch):
    import iloci.sensorimotor.path as path
    from scipy.ndimage import gaussian_filter1d

    xy = _stroke(path.POOL_ABOVE + 10_000)
    # the path's Gaussian by FFT above FFT_ABOVE: scipy's direct convolution's result
    sigma = path.PRESMOOTH * len(xy)
    assert np.allclose(path._gaussian(xy, sigma), gaussian_filter1d(xy, sigma, axis=0,
                                                                  mode="nearest"),
                       rtol=0, atol=1e-12)
    pooled = path.resample_path(xy)
    monkeypatch.setattr(path, "POOL_ABOVE", 10**12)
    exact = path.resample_path(xy)
    assert np.abs(pooled - exact).max() < 1e-4 * np.ptp(exact, axis=0).max()


def test_beyond_the_maximum_a_stroke_is_refused_before_any_work(tmp_path, monkeypatch):
    import iloci.sensorimotor.preprocess as pp
    from iloci import Demonstration
    from iloci.data import load_trajectory
    from iloci.errors import InvalidDemonstrationError
    from iloci.sensorimotor.robots import NAO_PLANE

    line = np.linspace(0.0, 1.0, pp.MAX_POINTS + 1)
    demo = Demonstration(positions=np.column_stack([line, line]), shape="huge")
    with pytest.raises(InvalidDemonstrationError, match="2,000,001 samples; iloci reads at "
                       "most 2,000,000.*Downsample"):
        pp.preprocess(demo, plane=NAO_PLANE)
    import iloci.validation as validation       # the one place the maximum lives
    monkeypatch.setattr(validation, "MAX_POINTS", 500)
    f = tmp_path / "long.csv"
    np.savetxt(f, _stroke(600), delimiter=",", header="x,y", comments="")
    with pytest.raises(InvalidDemonstrationError, match="long.csv .about 601 lines. has 600"):
        load_trajectory(f)



def test_a_big_or_pickled_npy_and_deep_json_or_toml_are_refused_before_reading(
        tmp_path, monkeypatch):
    import iloci.validation as validation
    from iloci.config import ConfigError, read_config_file
    from iloci.data import load_trajectory
    from iloci.data.datasets import load_dataset
    from iloci.errors import InvalidDemonstrationError

    monkeypatch.setattr(validation, "MAX_POINTS", 500)
    np.save(tmp_path / "long.npy", _stroke(600))
    with pytest.raises(InvalidDemonstrationError, match=r"long.npy \(a \(600, 2\) array\) has "
                       "600 samples; iloci reads at most 500"):
        load_trajectory(tmp_path / "long.npy")
    monkeypatch.undo()
    np.save(tmp_path / "obj.npy", np.array([{"x": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(InvalidInputError, match="obj.npy' is refused: it holds pickled"):
        load_trajectory(tmp_path / "obj.npy")
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(InvalidInputError, match="deep.json: its JSON is nested too deeply"):
        load_dataset(tmp_path / "deep.json")
    (tmp_path / "deep.toml").write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(ConfigError, match="nested too deeply"):
        read_config_file(tmp_path / "deep.toml")

def test_a_big_csv_is_read_as_the_row_by_row_reader_reads_it(tmp_path, monkeypatch):
    import iloci.data.csvfile as csvfile
    from iloci.data import load_trajectory
    from iloci.errors import InvalidDemonstrationError

    rows = np.column_stack([np.arange(5000) * 0.01, _stroke(5000)])
    f = tmp_path / "big.csv"
    np.savetxt(f, rows, delimiter=";", header="time_ms;pos_x;pos_y", comments="", fmt="%.7g")
    fast = load_trajectory(f)
    monkeypatch.setattr(csvfile, "_SAMPLE", 10**12)  # dialect from the whole file: no fast path
    slow = load_trajectory(f)
    assert np.array_equal(fast.positions, slow.positions)
    assert np.array_equal(fast.times, slow.times) and fast.times[1] == pytest.approx(1e-5)
    monkeypatch.undo()
    lines = f.read_text().splitlines()
    lines[4001] = "40.0;0.5;abc"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(InvalidDemonstrationError, match=r"line 4002, column 'pos_y': 'abc'"):
        load_trajectory(f)
    lines[4001] = "0.5;0.5;0.5"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(InvalidDemonstrationError, match=r"line 4002: time 0.0005 is before"):
        load_trajectory(f)


def test_a_step_over_a_second_shows_its_progress(monkeypatch, capsys):
    import iloci.progress as progress
    import iloci.sensorimotor.path as path
    import iloci.sensorimotor.preprocess as pp
    from iloci import Demonstration
    from iloci.sensorimotor.robots import NAO_PLANE

    monkeypatch.setattr(progress, "SHOW_AFTER", 0.0)
    monkeypatch.setattr(progress, "_EVERY", 0.0)
    seen = []
    demo = Demonstration(positions=_stroke(path.POOL_ABOVE + 1), shape="long")
    with progress.progress_sink(lambda what, f, s: seen.append((what, f))):
        pp.preprocess(demo, plane=NAO_PLANE)
    assert seen[0][0] == f"reading the drawing long/0 ({path.POOL_ABOVE + 1:,} samples)"
    fractions = [f for _, f in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0 and len(fractions) >= 3
    pp.preprocess(demo, plane=NAO_PLANE)  # nobody listening: nothing shown, nothing kept
    assert len(seen) == len(fractions)


# -- files from elsewhere -----------------------------------------------------------------

@pytest.mark.usefixtures("default_back_ends")
def test_a_memory_from_a_newer_iloci_names_both_versions(tmp_path, monkeypatch):
    import iloci._version
    from iloci import Agent
    from iloci.concepts.memory import Memory, save_memory
    from iloci.errors import MemoryFileError

    saved = load_config(None).to_dict()
    saved["learner"]["forgetting_rate"] = 0.1  # a setting of a later version
    import iloci.concepts.storage as storage     # writes the version into the header
    monkeypatch.setattr(iloci._version, "__version__", "99.1.0")
    monkeypatch.setattr(storage, "__version__", "99.1.0")
    save_memory(tmp_path / "m.npz", Memory(), {}, extra={"config": saved})
    monkeypatch.undo()
    with pytest.raises(MemoryFileError, match=r"written by iloci 99.1.0, this is iloci "
                       rf"{iloci._version.__version__}: upgrade iloci.*forgetting_rate"), \
            pytest.warns(UserWarning, match="written by iloci 99.1.0"):
        Agent.load(tmp_path / "m.npz")


@pytest.mark.usefixtures("default_back_ends")
def test_a_config_from_a_newer_iloci_names_both_versions(tmp_path, capsys):
    from iloci._version import __version__
    from iloci.config import to_toml

    text = to_toml(load_config(None))
    assert f"written by iloci {__version__}" in text.splitlines()[0]
    f = tmp_path / "new.toml"
    f.write_text(text.replace(f"iloci {__version__}", "iloci 99.0")
                 + "\n[recognition]\nnovelty = 2.0\n")
    assert main(["config", "check", str(f)]) == 2
    err = capsys.readouterr().err
    assert f"written by iloci 99.0, this is iloci {__version__}: upgrade iloci" in err
    assert "recognition" in err
    # the same unknown key in a config that says no version: the usual message only
    f.write_text(text.replace(f"written by iloci {__version__}", "") + "\n[recognition]\n")
    assert main(["config", "check", str(f)]) == 2
    assert "upgrade" not in capsys.readouterr().err



def _memory_members(path: Path) -> dict[str, bytes]:
    import zipfile
    with zipfile.ZipFile(path) as z:
        return {n: z.read(n) for n in z.namelist()}


def test_a_memory_file_from_elsewhere_is_refused_before_it_is_unpacked(tmp_path, monkeypatch):
    """Pickles (whole file, or an object array inside), a zip bomb, a lying array header and
    a file that is no archive: each its own sentence, nothing unpickled or unpacked."""
    import io
    import pickle
    import zipfile

    import iloci.concepts.storage as storage
    from iloci.concepts.memory import Memory, load_memory, save_memory
    from iloci.errors import MemoryFileError

    good = save_memory(tmp_path / "good.npz", Memory(), {"w": np.zeros(3)})
    members = _memory_members(good)

    def npz(name: str, extra: dict[str, bytes], **kw) -> Path:
        f = tmp_path / name
        with zipfile.ZipFile(f, "w", **kw) as z:
            for n, b in {**members, **extra}.items():
                z.writestr(n, b)
        return f

    def npy(a: np.ndarray) -> bytes:
        buf = io.BytesIO()
        np.save(buf, a, allow_pickle=True)
        return buf.getvalue()

    (tmp_path / "p.npz").write_bytes(pickle.dumps({"a": 1}))
    with pytest.raises(MemoryFileError, match="p.npz is refused: the file is a Python pickle"):
        load_memory(tmp_path / "p.npz")
    f = npz("o.npz", {"mem/evil.npy": npy(np.array([{"a": 1}], dtype=object))})
    with pytest.raises(MemoryFileError, match="'mem/evil' holds Python objects.*run any code"):
        load_memory(f)
    monkeypatch.setattr(storage, "MAX_UNPACKED", 10**6)
    f = npz("bomb.npz", {"mem/z.npy": npy(np.zeros(2 * 10**5))},
            compression=zipfile.ZIP_DEFLATED)
    assert f.stat().st_size < 10**5
    with pytest.raises(MemoryFileError, match="would unpack to 0.0 GiB.*up to 0 GiB.*nothing "
                       "was unpacked"):
        load_memory(f)
    monkeypatch.undo()
    header = npy(np.zeros(4)).replace(b"(4,), ", b"(999999,),")
    f = npz("lie.npz", {"mem/lie.npy": header})
    with pytest.raises(MemoryFileError, match=r"'mem/lie' claims shape \(999999,\).*corrupted"):
        load_memory(f)
    (tmp_path / "t.npz").write_text("hello")
    with pytest.raises(MemoryFileError, match="not a complete .npz archive"):
        load_memory(tmp_path / "t.npz")
    assert load_memory(good)[1]["w"].shape == (3,)


def test_a_memory_from_an_older_or_newer_iloci_names_the_versions(tmp_path, monkeypatch):
    import iloci._version
    from iloci.concepts.memory import Memory, load_memory, save_memory
    from iloci.concepts.storage import read_memory_file, write_memory_file
    from iloci.errors import MemoryFileError

    save_memory(tmp_path / "m.npz", Memory(), {})
    arrays, header = read_memory_file(tmp_path / "m.npz")
    header = {k: v for k, v in header.items() if k not in ("checksum", "iloci")}
    arrays.pop("mem/prototype")  # an array an older iloci did not write
    write_memory_file(tmp_path / "old.npz", arrays, header)
    with pytest.raises(MemoryFileError, match=r"old.npz: .*it lacks 'mem/prototype'.*written "
                       rf"by iloci {iloci._version.__version__}; this is iloci"):
        load_memory(tmp_path / "old.npz")
    monkeypatch.setattr(iloci._version, "__version__", "42.0")
    import iloci.concepts.storage as storage  # the writer names its version in the header
    monkeypatch.setattr(storage, "__version__", "42.0", raising=False)
    save_memory(tmp_path / "new.npz", Memory(), {})
    monkeypatch.undo()
    with pytest.warns(UserWarning, match="new.npz was written by iloci 42.0, this is iloci "
                      ".*saving the memory from here drops"):
        load_memory(tmp_path / "new.npz")


def test_a_data_set_with_names_that_are_not_utf8_is_read_and_reported(tmp_path):
    import os

    from iloci.data.datasets import load_dataset
    from iloci.data.files import write_text_atomic

    if os.sys.getfilesystemencoding() != "utf-8":
        pytest.skip("a UTF-8 file system encoding")
    root = tmp_path / os.fsdecode(b"data\xe9")
    t = np.linspace(0.0, 1.0, 40)
    for concept, k in ((os.fsdecode(b"Sin\xe9"), 6), ("GShape", 3)):
        for i in range(2):
            (root / concept).mkdir(parents=True, exist_ok=True)
            np.savetxt(root / concept / os.fsdecode(b"s%d\xff.csv" % i),
                       np.column_stack([np.cos(k * t) + i, np.sin(k * t)]), delimiter=",")
    ds = load_dataset(root)
    assert sorted({d.true_concept for d in ds.demos}) == ["GShape", "Sin\\xe9"]
    report = write_text_atomic(tmp_path / "r.md", f"data set {root}, {ds.demos[-1].key}\n")
    assert report.read_bytes().endswith(b"data\\xe9, Sin\\xe9/1\n")

@pytest.mark.usefixtures("default_back_ends")
def test_output_folders_are_checked_before_any_work(tmp_path, capsys, monkeypatch):
    from iloci.data.files import writable_dir
    from iloci.evaluation.evaluate import evaluate

    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    # a folder that cannot be made (its parent is a file): refused before any fold is learned
    learned = []
    monkeypatch.setattr("iloci.evaluation.evaluate.run_fold",
                        lambda *a, **k: learned.append(1), raising=False)
    with pytest.raises(InvalidInputError, match=r"memory_dir .*a-file/m.*nothing can be "
                       "written there.*Nothing was done"):
        evaluate(load_config(None).replace(data={"shapes": ["GShape", "Sine"]}),
                 baseline=False, memory_dir=str(blocker / "m"))
    assert learned == []
    with pytest.raises(InvalidInputError, match="is a file, not a directory"):
        writable_dir(blocker, "--out")
    from iloci.commands.serve import build_classroom
    with pytest.raises(InvalidInputError, match="--memory .*a-file.*is a file, not a directory"):
        build_classroom(blocker / "m.npz", worker=False)  # before its lock is taken
    assert not (blocker.parent / "m.npz.lock").exists()
    argv = [["evaluate", "--out", str(tmp_path / "o"), "--memories", str(blocker / "m"),
             "--no-baseline"],
            ["teach", "--memory", str(blocker / "m.npz"), "GShape/0"],
            ["show", "GShape/0", "--out", str(blocker / "x.png")]]
    for args in argv:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert "Nothing was done" in err and "Traceback" not in err, (args, err)
    assert not (blocker.parent / "m.npz").exists()


@pytest.mark.skipif(not hasattr(__import__("os"), "fsencode") or
                    __import__("sys").getfilesystemencoding() != "utf-8",
                    reason="a UTF-8 file system encoding")
@pytest.mark.usefixtures("default_back_ends")
def test_a_file_name_that_is_not_utf8_is_accepted_by_teach_and_show(tmp_path, capsys):
    import os

    from iloci.data.files import shape_name

    name = os.fsdecode(b"caf\xe9.csv")  # a Latin-1 name on a UTF-8 system
    f = tmp_path / name
    t = np.linspace(0.0, 1.0, 80)
    np.savetxt(f, np.column_stack([t, np.cos(3 * t), np.sin(3 * t)]), delimiter=",",
               header="t,x,y", comments="")
    assert shape_name(f) == "caf\\xe9"
    assert main(["show", str(f), "--out", str(tmp_path / "s.png")]) == 0
    assert "caf\\xe9/0: 80 pen points" in capsys.readouterr().out
    cfg = tmp_path / "c.toml"
    cfg.write_text('[perceptual_model]\nepochs = 20\n[learner]\nrehearsal_epochs = 20\n'
                   '[teacher]\nconcepts = ["caf\\\\xe9=cup"]\n')
    memory = tmp_path / os.fsdecode(b"m\xff.npz")
    assert main(["teach", "--config", str(cfg), "--memory", str(memory), str(f)]) == 0
    out = capsys.readouterr().out
    assert "caf\\xe9/0" in out and "memory saved to" in out
    assert main(["show", str(memory)]) == 0
    assert "m\\xff.npz" in capsys.readouterr().out  # the name printed, its byte as \xff


# -- plugins: a hook result of the wrong type ----------------------------------------------

class _SloppyPlugin:
    """Hooks that return what iloci cannot use."""

    from iloci import hookimpl

    @hookimpl
    def iloci_register_teachers(self, registry):
        registry.add("sloppy", lambda **kw: {"feedback": 1}, summary="returns a dict")

    @hookimpl
    def iloci_make_executor(self, name, jobs, address):
        return "an executor" if name == "sloppy" else None

    @hookimpl
    def iloci_register_robots(self, registry):
        registry.add("sloppy-arm", lambda: "panda", summary="returns a name", joints=4,
                     plane="given")


class _SloppyOldRobots:
    """The deprecated dict form of ``iloci_register_robots``, adding no preset."""

    from iloci import hookimpl

    @hookimpl
    def iloci_register_robots(self, robots):
        robots["sloppy-arm"] = "panda"


class _ReturningPlugin:
    from iloci import hookimpl

    @hookimpl
    def iloci_register_clusterers(self, registry):
        return {"mine": object}  # instead of registry.add(...)


def test_a_hook_result_of_the_wrong_type_names_plugin_distribution_and_hook():
    from iloci.errors import PluginError
    from iloci.evaluation.executors import make_executor
    from iloci.plugins import get_plugin_manager, get_registry
    from iloci.sensorimotor.robots import available_robots, get_robot

    pm = get_plugin_manager(autoload=False, plugins=[_SloppyPlugin()])
    registry = get_registry(pm)
    with pytest.raises(PluginError, match=r"teacher 'sloppy' of plugin '.*' \(distribution "
                       r"none\), registered through iloci_register_teachers: its factory .* "
                       r"returned dict .* lacks feedback"):
        registry.build("teacher", "sloppy")
    with pytest.warns(DeprecationWarning, match="implements iloci_make_executor: deprecated"), \
            pytest.raises(PluginError, match=r"iloci_make_executor returned str 'an executor' "
                       "for executor 'sloppy', which is not a fold executor: it lacks name, run"):
        make_executor("sloppy", 1, plugin_manager=pm)
    with pytest.raises(PluginError, match=r"robot 'sloppy-arm' of plugin '.*' \(distribution "
                       r"none\), registered through iloci_register_robots: its factory .* "
                       r"returned str 'panda', which is not a robot: it lacks .*joint_names"):
        get_robot("sloppy-arm", pm)
    old = get_plugin_manager(autoload=False, plugins=[_SloppyOldRobots()])
    with pytest.warns(DeprecationWarning, match="iloci_register_robots\\(robots\\), a dict"), \
            pytest.raises(PluginError, match=r"iloci_register_robots added 'sloppy-arm': str"):
        available_robots(old)
    with pytest.raises(PluginError, match=r"iloci_register_clusterers returned dict .* "
                       r"returns nothing: it registers each component with registry.add"):
        get_registry(get_plugin_manager(autoload=False, plugins=[_ReturningPlugin()]))


@pytest.mark.usefixtures("default_back_ends")
def test_an_installed_plugin_with_a_wrong_factory_result_is_named_with_its_distribution(
        tmp_path, cli):
    site = tmp_path / "site"
    site.mkdir()
    (site / "sloppy_teacher.py").write_text(
        "from iloci import hookimpl\n\n"
        "@hookimpl\n"
        "def iloci_register_teachers(registry):\n"
        "    registry.add('sloppy', lambda **kw: 'yes', summary='says yes')\n")
    info = site / "iloci_sloppy-0.3.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: iloci-sloppy\nVersion: 0.3\n")
    (info / "entry_points.txt").write_text("[iloci]\nsloppy = sloppy_teacher\n")
    out = cli("teach", "--teacher", "sloppy", "--memory", str(tmp_path / "m.npz"), "GShape/0",
              env={"PYTHONPATH": str(site)})
    assert out.returncode == 2, out.stderr
    assert "teacher 'sloppy' of plugin 'sloppy' (distribution iloci-sloppy)" in out.stderr
    assert "iloci_register_teachers" in out.stderr and "returned str 'yes'" in out.stderr
    assert "Traceback" not in out.stderr and not (tmp_path / "m.npz").exists()


def _installed(site: Path, name: str, code: str) -> None:
    """A plugin distribution ``iloci-NAME`` (module NAME_plugin) found on PYTHONPATH=site."""
    site.mkdir(exist_ok=True)
    (site / f"{name}_plugin.py").write_text("from iloci import hookimpl\n\n" + code)
    info = site / f"iloci_{name}-0.3.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: iloci-{name}\nVersion: 0.3\n")
    (info / "entry_points.txt").write_text(f"[iloci]\n{name} = {name}_plugin\n")


@pytest.mark.usefixtures("default_back_ends")
def test_an_installed_plugin_that_raises_is_named_with_what_to_do(tmp_path, cli):
    """A factory that raises, a factory naming a module the plugin lacks, and a command
    hook that raises: each error names the plugin, its distribution, and how to block it."""
    site = tmp_path / "site"
    _installed(site, "shaky", (
        "def _broken(**kw):\n    raise RuntimeError('no teacher today')\n\n"
        "@hookimpl\n"
        "def iloci_register_teachers(registry):\n"
        "    registry.add('shaky', _broken, summary='raises')\n"
        "    registry.add('ghost', 'shaky_gone:Teacher', summary='lazy, module missing')\n"))
    env = {"PYTHONPATH": str(site)}
    for teacher, says in (("shaky", "its factory _broken raised RuntimeError: no teacher "
                                    "today"),
                          ("ghost", "its factory 'shaky_gone:Teacher' names module "
                                    "shaky_gone, which cannot be imported")):
        out = cli("teach", "--teacher", teacher, "--memory", str(tmp_path / "m.npz"),
                  "GShape/0", env=env)
        assert out.returncode == 2, out.stderr
        assert (f"teacher {teacher!r} of plugin 'shaky' (distribution iloci-shaky)"
                in out.stderr), out.stderr
        assert says in out.stderr and "ILOCI_BLOCK_PLUGINS=shaky" in out.stderr
        assert "Traceback" not in out.stderr and not (tmp_path / "m.npz").exists()
    _installed(site, "loud", "@hookimpl\ndef iloci_add_commands(subparsers):\n"
                             "    raise ValueError('no room')\n")
    # a plugin's failing iloci_add_commands leaves its commands out, not every command
    # (a plugin audit: it made `iloci plugins` and `iloci config check` fail too)
    out = cli("plugins", env=env)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    assert ("iloci plugin 'loud' (distribution 'iloci-loud') could not add its commands, "
            "which are left out: plugin 'loud' (distribution iloci-loud) failed in "
            "iloci_add_commands: ValueError: no room" in out.stderr
            and "ILOCI_BLOCK_PLUGINS=loud" in out.stderr)
    out = cli("plugins", env={**env, "ILOCI_BLOCK_PLUGINS": "loud"})
    assert out.returncode == 0 and "loud" not in out.stderr, out.stderr


def test_links_without_inertials_are_said_once_by_pybullet(tmp_path):
    """PyBullet accepts them (1 kg each): one warning naming the links."""
    pytest.importorskip("iloci_pybullet")
    from iloci.plugins import get_registry

    robot = describe_robot(_arm(tmp_path / "arm.urdf", mass=""), tip_frame="pen")
    with pytest.warns(UserWarning, match=r"'a', 'b', 'c' move with a joint but have no "
                      r"<inertial>; PyBullet gives each 1 kg"):
        sim = get_registry().build("simulator", "pybullet", robot=robot)
    sim.close()


def test_an_installed_plugins_unmarked_hook_and_exit_at_import_are_said(tmp_path, cli):
    """A plugin audit: an installed plugin's hook function without @iloci.hookimpl was
    passed over without a word (the observer never ran); a plugin module calling
    sys.exit() on import ended every iloci command, naming no plugin."""
    site = tmp_path / "site"
    _installed(site, "quiet", "def iloci_on_interaction(event):\n    print('never')\n\n"
                              "def helper():\n    pass\n")
    _installed(site, "quits", "import sys\nsys.exit('no licence server')\n")
    out = cli("plugins", env={"PYTHONPATH": str(site)})
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    assert ("iloci plugin 'quiet' (distribution 'iloci-quiet') defines iloci_on_interaction "
            "without @iloci.hookimpl: iloci never calls it") in out.stderr
    assert "helper" not in out.stderr
    assert ("iloci plugin 'quits' (distribution 'iloci-quits') failed to import and was "
            "skipped: SystemExit: no licence server") in out.stderr


@pytest.mark.usefixtures("default_back_ends")
def test_a_plugin_component_that_raises_at_work_is_named(tmp_path, cli):
    """A plugin audit: a teacher that raised inside feedback() gave "failed: RuntimeError:
    serial port closed" and no word of which plugin's code it was."""
    site = tmp_path / "site"
    _installed(site, "flaky", (
        "class Flaky:\n"
        "    def feedback(self, demo, response):\n"
        "        raise RuntimeError('serial port closed')\n\n"
        "@hookimpl\n"
        "def iloci_register_teachers(registry):\n"
        "    registry.add('flaky', Flaky, summary='raises')\n"))
    fast = tmp_path / "fast.toml"
    fast.write_text("[perceptual_model]\nepochs = 30\n[learner]\nrehearsal_epochs = 30\n")
    out = cli("teach", "--config", str(fast), "--teacher", "flaky", "--memory",
              str(tmp_path / "m.npz"), "GShape/0", "Sine/0", env={"PYTHONPATH": str(site)})
    assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
    assert "failed: RuntimeError: serial port closed" in out.stderr
    assert re.search(r"raised in plugin 'flaky' \(iloci-flaky\), flaky_plugin\.feedback line 5, "
                     r"not in iloci: .*ILOCI_BLOCK_PLUGINS=flaky", out.stderr), out.stderr
    # in an evaluation's worker processes too, whose traceback comes back as text
    fast.write_text(fast.read_text() + "[teacher]\nname = 'flaky'\n"
                    "[data]\nshapes = ['GShape', 'Sine']\n")
    out = cli("evaluate", "--config", str(fast), "--jobs", "2",
              "--folds", "0", "1", "--no-baseline", "--quiet", "--out", str(tmp_path / "ev"),
              env={"PYTHONPATH": str(site)})
    assert out.returncode == 1 and "Traceback" not in out.stderr, out.stderr
    assert re.search(r"raised in plugin 'flaky' \(iloci-flaky\), flaky_plugin\.feedback line 5",
                     out.stderr), out.stderr
