"""Property tests: any input gives a result or an iloci error, never another exception.

Over the four things a user hands iloci: trajectory files (``.csv``,
``.npy``), :class:`~iloci.Demonstration` arrays, config files, and memory
files. On the command line the same inputs exit 0 or 2, never 1 (a
traceback).

Example counts: the ``ci`` profile (default, registered in conftest.py)
keeps the suite fast; ``HYPOTHESIS_PROFILE=thorough`` runs many more by
hand. ``pytest --hypothesis-show-statistics tests/test_properties.py``
prints how many ran.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from iloci.cli import main as cli_main
from iloci.concepts.memory import Entry, Memory, load_memory, save_memory
from iloci.config import load_config
from iloci.data import load_trajectory
from iloci.errors import IlociError
from iloci.interfaces import Demonstration
from iloci.sensorimotor.encoding import SensorimotorEncoder

FS = settings(suppress_health_check=[HealthCheck.function_scoped_fixture,
                                     HealthCheck.too_slow], deadline=None)


def result_or_iloci_error(fn, *args, **kwargs):
    """Call ``fn``; an IlociError is a fine answer, any other exception fails the test."""
    try:
        return fn(*args, **kwargs)
    except IlociError as exc:
        assert str(exc), "an iloci error must say what is wrong"
        return exc


# ------------------------------------------------------------------ trajectory files

NUMBER = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
    st.integers(-10**6, 10**6).map(str),
    st.sampled_from(["", " ", "1,5", "1.5e3", "-0", "nan", "inf", "abc", "1e400", "--1",
                     '"2"', "0x10", "1_000", "\u00a0", "½"]),
)
HEADER_CELL = st.sampled_from(["t", "time", "t_ms", "timestamp", "x", "y", "X", "Y",
                               "pressure", "t [ms]", "x (mm)", "pos_x", "pen_y", "", "a",
                               '"x"', "tilt", "t_s"])
DELIMITER = st.sampled_from([",", ";", "\t", "|", " ", "  "])
ENCODING = st.sampled_from(["utf-8", "utf-8-sig", "utf-16", "utf-16-le", "utf-16-be",
                            "latin-1", "utf-32"])


@st.composite
def csv_texts(draw) -> bytes:
    width = draw(st.integers(1, 5))
    delim = draw(DELIMITER)
    rows = []
    if draw(st.booleans()):
        rows.append(delim.join(draw(st.lists(HEADER_CELL, min_size=width, max_size=width))))
    n = draw(st.integers(0, 12))
    for _ in range(n):
        w = width if draw(st.integers(0, 9)) else draw(st.integers(0, 6))
        rows.append(delim.join(draw(st.lists(NUMBER, min_size=w, max_size=w))))
    newline = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    text = newline.join(rows) + draw(st.sampled_from(["", newline, newline * 3]))
    try:
        return text.encode(draw(ENCODING))
    except UnicodeEncodeError:
        return text.encode("utf-8")


@FS
@given(data=st.one_of(csv_texts(), st.binary(max_size=400)))
def test_any_csv_file_gives_a_demonstration_or_an_iloci_error(tmp_path_factory, data):
    f = tmp_path_factory.mktemp("csv") / "t.csv"
    f.write_bytes(data)
    out = result_or_iloci_error(load_trajectory, f)
    if isinstance(out, Demonstration):
        assert out.positions.shape[1] == 2 and np.all(np.isfinite(out.positions))
        assert np.all(np.diff(out.times) > 0)


@st.composite
def npy_bytes(draw) -> bytes:
    kind = draw(st.sampled_from(["array", "bytes", "truncated"]))
    if kind == "bytes":
        return draw(st.binary(max_size=300))
    arr = draw(hnp.arrays(
        dtype=st.sampled_from([np.float64, np.float32, np.int64, np.bool_, np.complex128,
                               np.dtype("U3")]),
        shape=hnp.array_shapes(min_dims=0, max_dims=3, max_side=6)))
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    raw = buf.getvalue()
    return raw[:draw(st.integers(0, len(raw)))] if kind == "truncated" else raw


@FS
@given(data=npy_bytes())
def test_any_npy_file_gives_a_demonstration_or_an_iloci_error(tmp_path_factory, data):
    f = tmp_path_factory.mktemp("npy") / "t.npy"
    f.write_bytes(data)
    result_or_iloci_error(load_trajectory, f)


# ------------------------------------------------------------------ Demonstration

FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(deadline=None)
@given(positions=st.one_of(
           hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=3, max_side=8),
                      elements=FLOATS),
           st.lists(st.lists(FLOATS, max_size=3), max_size=6),
           st.sampled_from([None, "abc", [[1, "x"], [2, 3], [4, 5]], {"a": 1}])),
       times=st.one_of(st.none(), hnp.arrays(np.float64, hnp.array_shapes(max_dims=2,
                                                                           max_side=8),
                                             elements=FLOATS),
                       st.sampled_from(["t", [1, 2, "x"]])),
       shape=st.text(max_size=8), index=st.integers(-5, 10**6))
def test_any_demonstration_arguments_give_one_or_an_iloci_error(positions, times, shape,
                                                                index):
    out = result_or_iloci_error(Demonstration, positions, times, shape=shape, index=index)
    if isinstance(out, Demonstration):
        assert out.positions.ndim == 2 and len(out.positions) >= 3
        assert np.all(np.isfinite(out.positions)) and np.all(np.diff(out.times) > 0)


# ------------------------------------------------------------------ config files

SECTIONS = ["perceptual_model", "clusterer", "teacher", "ik", "simulator", "learner",
            "sensorimotor", "data", "evaluation", "nonsense"]
KEYS = ["name", "k_cutoff", "num_threshold", "similarity_threshold", "rehearsal_epochs",
        "steps", "resample", "smoothing_window", "robot", "dataset", "shapes", "folds",
        "train_fraction", "seed", "jobs", "hidden", "pb", "epochs", "learning_rate",
        "input_size", "pb_bound", "p", "concepts", "gravity", "tolerance", "max_error",
        "picture_dir", "dtype", "bogus"]
NAMES = ["native-rnnpb", "torch-rnnpb", "jax-rnnpb", "scipy", "sklearn", "oracle", "noisy",
         "pinocchio", "pybullet", "mujoco", "none", "nope"]
VALUES = st.deferred(lambda: st.one_of(
    st.integers(-2**70, 2**70), FLOATS, st.booleans(), st.text(max_size=6),
    st.sampled_from(NAMES + ["GShape", "Sine", "time", "arc_length", "float64"]),
    st.lists(st.one_of(st.sampled_from(["GShape", "Sine", "Gshape", "a=b", "x"]),
                       st.integers(0, 3)), max_size=3),
    st.dictionaries(st.sampled_from(KEYS), st.integers(0, 3), max_size=2)))


@st.composite
def config_dicts(draw) -> dict:
    out = {}
    for sec in draw(st.lists(st.sampled_from(SECTIONS), max_size=4, unique=True)):
        if draw(st.integers(0, 15)) == 0:
            out[sec] = draw(VALUES)  # a key where a table belongs
            continue
        keys = draw(st.lists(st.sampled_from(KEYS), max_size=3, unique=True))
        out[sec] = {k: draw(VALUES) for k in keys}
    return out


@FS
@given(data=config_dicts())
def test_any_config_mapping_gives_a_config_or_an_iloci_error(data):
    result_or_iloci_error(load_config, data)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v) if -2**63 <= v < 2**63 else json.dumps(str(v))
    if isinstance(v, float):
        return {"nan": "nan", "inf": "inf", "-inf": "-inf"}.get(repr(v), repr(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def _toml_text(data: dict) -> str:
    """TOML text of a config mapping (a non-table section value is written as a key)."""
    lines = []
    for sec, values in data.items():
        if isinstance(values, dict):
            lines.append(f"[{sec}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in values.items()]
        else:
            lines.insert(0, f"{sec} = {_toml_value(values)}")
    return "\n".join(lines) + "\n"


@FS
@given(text=st.one_of(config_dicts().map(_toml_text), st.text(max_size=200)),
       encoding=ENCODING)
def test_any_config_file_exits_0_or_2(tmp_path_factory, capsys, text, encoding):
    f = tmp_path_factory.mktemp("cfg") / "c.toml"
    try:
        f.write_bytes(text.encode(encoding))
    except UnicodeEncodeError:
        f.write_bytes(text.encode("utf-8"))
    code = cli_main(["config", "check", str(f)])
    err = capsys.readouterr().err
    assert code in (0, 2), err
    assert "Traceback" not in err


# ------------------------------------------------------------------ memory files

def _memory_file(path: Path) -> Path:
    rng = np.random.default_rng(0)
    entries = [Entry(pb=rng.normal(size=4), pb_rec=rng.normal(size=4), num_samples=1 + i,
                     num_steps=49, initial_input=rng.normal(size=6), start=rng.normal(size=6),
                     dt=0.1, concept=f"c{i % 2 + 1}", generation_error=0.01, source=f"S/{i}",
                     sources=(f"S/{i}",)) for i in range(3)]
    memory = Memory(entries, SensorimotorEncoder.from_state(
        {"scale": np.full(6, 0.1), "limit": np.array(0.9)}), 2, 3)
    return save_memory(path, memory, {"w": rng.normal(size=(3, 3))},
                       extra={"config": {"learner": {"k_cutoff": 0.5}}})


@st.composite
def damaged(draw, raw: bytes) -> bytes:
    how = draw(st.sampled_from(["truncate", "flip", "splice", "garbage"]))
    if how == "truncate":
        return raw[:draw(st.integers(0, len(raw) - 1))]
    if how == "flip":
        i = draw(st.integers(0, len(raw) - 1))
        return raw[:i] + bytes([raw[i] ^ draw(st.integers(1, 255))]) + raw[i + 1:]
    if how == "splice":
        i = draw(st.integers(0, len(raw)))
        return raw[:i] + draw(st.binary(min_size=1, max_size=40)) + raw[i:]
    return draw(st.binary(max_size=500))


@pytest.fixture(scope="module")
def memory_bytes(tmp_path_factory) -> bytes:
    return _memory_file(tmp_path_factory.mktemp("mem") / "m.npz").read_bytes()


@pytest.mark.parametrize("offset_from_end, value", [
    # found by the thorough profile: a central-directory entry's flag or compression
    # method byte changed made zipfile raise NotImplementedError / RuntimeError
    ("method", 1), ("flags", 1)])
def test_zip_directory_damage_is_a_memory_file_error(tmp_path, memory_bytes, offset_from_end,
                                                     value):
    from iloci.errors import MemoryFileError
    raw = bytearray(memory_bytes)
    entry = raw.rfind(b"PK\x01\x02")  # the last central-directory entry (the header's)
    raw[entry + (10 if offset_from_end == "method" else 8)] = value
    f = tmp_path / "m.npz"
    f.write_bytes(bytes(raw))
    with pytest.raises(MemoryFileError, match="truncated, corrupted"):
        load_memory(f)


@FS
@given(data=st.data())
def test_any_damaged_memory_file_loads_or_gives_an_iloci_error(tmp_path_factory,
                                                               memory_bytes, data):
    raw = data.draw(damaged(memory_bytes))
    f = tmp_path_factory.mktemp("mem") / "m.npz"
    f.write_bytes(raw)
    out = result_or_iloci_error(load_memory, f)
    if not isinstance(out, IlociError):
        assert isinstance(out[0], Memory)


JSON = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-10, 10**12),
                              st.floats(allow_nan=False), st.text(max_size=5)),
                    lambda kids: st.one_of(st.lists(kids, max_size=3),
                                           st.dictionaries(st.text(max_size=5), kids,
                                                           max_size=3)), max_leaves=8)


@FS
@given(data=st.data())
def test_a_memory_header_edited_consistently_still_loads_or_gives_an_iloci_error(
        tmp_path_factory, memory_bytes, data):
    """A header rewritten with a valid checksum (the file was edited on purpose)."""
    from iloci.concepts.storage import _checksum
    with np.load(io.BytesIO(memory_bytes), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays.pop("__header__").tobytes())
    part = data.draw(st.sampled_from(["memory", "version", "array"]))
    if part == "memory":
        key = data.draw(st.sampled_from(sorted(header["memory"])))
        header["memory"][key] = data.draw(JSON)
    elif part == "version":
        header["version"] = data.draw(JSON)
    else:
        name = data.draw(st.sampled_from(sorted(arrays)))
        arrays[name] = data.draw(hnp.arrays(
            st.sampled_from([np.float64, np.int64, np.bool_]),
            hnp.array_shapes(min_dims=0, max_dims=2, max_side=4)))
    header["checksum"] = _checksum(header, arrays)
    arrays["__header__"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    f = tmp_path_factory.mktemp("mem") / "m.npz"
    with zipfile.ZipFile(f, "w") as zf:  # what np.savez writes
        for name, a in arrays.items():
            buf = io.BytesIO()
            np.save(buf, a, allow_pickle=False)
            zf.writestr(name + ".npy", buf.getvalue())
    result_or_iloci_error(load_memory, f)


def test_the_profiles_are_registered():
    assert settings.get_profile("ci").max_examples <= 100
    assert settings.get_profile("thorough").max_examples >= 1000

