"""Mistakes a new user makes with the commands (an audit of teach, show, sweep, recognize,
serve): each is now one error that says what to do, before any work, or a warning, never a
silent wrong result or an exit 0 for a command that stopped half-way."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("pinocchio")

FAST = """
[perceptual_model]
epochs = 60
[learner]
rehearsal_epochs = 60
"""


@pytest.fixture
def fast(tmp_path):
    path = tmp_path / "fast.toml"
    path.write_text(FAST)
    return path


def test_teach_whose_output_is_closed_says_it_stopped_and_does_not_exit_0(fast, tmp_path):
    """`iloci teach ... | head -1` stopped after the first demonstration and exited 0."""
    memory = tmp_path / "m.npz"
    proc = subprocess.Popen([sys.executable, "-m", "iloci", "teach", "--config", str(fast),
                             "--memory", str(memory), "GShape/0", "Sine/0", "GShape/1",
                             "Sine/1", "GShape/2"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline()
    proc.stdout.close()                      # as `| head -1` does
    stderr = proc.stderr.read()
    assert proc.wait(timeout=600) == 141
    assert "stopped: the output of `iloci teach` was closed" in stderr
    assert "Traceback" not in stderr
    assert memory.exists()


@pytest.mark.parametrize("argv", [
    ["teach", "--config", "a.toml", "--config", "b.toml", "GShape/0"],
    ["teach", "--memory", "a.npz", "GShape/0", "--memory", "b.npz"],
    ["show", "GShape/0", "--out", "a.png", "--out", "b.png"],
    ["recognize", "--memory", "a.npz", "--memory", "b.npz", "GShape/0"],
    ["evaluate", "--out", "a", "--out", "b"]])
def test_a_single_valued_option_given_twice_is_an_error(argv, cli):
    """The last one won silently: a teach ran with another config than the one meant."""
    done = cli(*argv)
    assert done.returncode == 2
    option = argv[[i for i, a in enumerate(argv) if a.startswith("--")][0]]
    assert f"error: {option} given twice" in done.stderr


def test_show_checks_the_image_name_before_any_work_and_recognize_json_is_json(fast, tmp_path,
                                                                                  cli):
    """show --out g.txt failed with matplotlib's "Format 'txt' is not supported" after all
    the work (exit 1); recognize --json printed a bare NaN, which strict JSON readers
    refuse (a memory of one concept has no familiarity)."""
    done = cli("show", "GShape/2", "--out", str(tmp_path / "g.txt"))
    assert done.returncode == 2 and "error: --out " in done.stderr
    assert "an image's name ends in" in done.stderr and "g.png" in done.stderr
    memory = tmp_path / "one.npz"
    assert cli("teach", "--config", str(fast), "--memory", str(memory),
               "GShape/0").returncode == 0
    done = cli("recognize", "--memory", str(memory), "Sine/0", "--json")
    assert done.returncode == 0, done.stderr
    row = json.loads(done.stdout, parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
    assert row["familiarity"] is None and row["concept"]


def test_a_memory_name_left_out_or_a_memory_given_as_config_is_said_so(fast, tmp_path, cli):
    """`iloci teach --memory GShape/0 Sine/0` (the memory's name left out) made a folder
    GShape/ and a memory file GShape/0, taught Sine/0 only, and from then on hid the LASA
    name; `--memory new.csv` saved a zip as .csv; a memory given to --config was said not
    to be UTF-8, with iconv advice."""
    done = cli("teach", "--config", str(fast), "--memory", "GShape/0", "Sine/0", cwd=tmp_path)
    assert done.returncode == 2
    assert "--memory 'GShape/0' would be a new memory file, and a memory file's name ends " \
        "in .npz" in done.stderr and "Did you leave out the memory's name?" in done.stderr
    assert not (tmp_path / "GShape").exists()
    done = cli("teach", "--config", str(fast), "--memory", "new.csv", "Sine/0", cwd=tmp_path)
    assert done.returncode == 2 and not (tmp_path / "new.csv").exists()
    memory = tmp_path / "m.npz"
    assert cli("teach", "--config", str(fast), "--memory", str(memory),
               "GShape/0").returncode == 0
    renamed = memory.rename(tmp_path / "robot.mem")          # an existing memory: any name
    done = cli("teach", "--config", str(fast), "--memory", str(renamed), "GShape/1")
    assert done.returncode == 0, done.stderr
    for argv in (("teach", "--config", str(renamed), "GShape/1"),
                 ("config", "check", str(renamed))):
        done = cli(*argv)
        assert done.returncode == 2
        assert "is a zip file (an iloci memory, .npz?), not TOML text" in done.stderr
        assert "iconv" not in done.stderr


def test_a_misspelt_file_or_a_folder_among_the_demonstrations_fails_before_learning(
        fast, tmp_path, cli):
    """`iloci teach circle.csv eigth.csv` warned, taught the rest and exited 0 (a misspelt
    LASA name is an error); a folder was said not to exist, or to be an unknown LASA
    shape."""
    folder = tmp_path / "drawings"
    folder.mkdir()
    memory = tmp_path / "m.npz"
    for tokens, said in (([str(folder)], f"{str(folder)!r} is a folder, not a "
                                         "demonstration: give the trajectory files in it"),
                         (["GShape/0", str(tmp_path / "eigth.csv")], "no such file: "),
                         ([str(folder / "circle")], "no such file: .*trajectory files end "
                                                    "in .csv")):
        done = cli("teach", "--config", str(fast), "--memory", str(memory), *tokens)
        assert done.returncode == 2, done.stderr
        assert re.search(said, done.stderr), done.stderr
        assert "Nothing was learned" in done.stderr and not memory.exists()


def test_teach_refuses_files_of_mixed_position_units_before_learning(fast, tmp_path, cli):
    """`iloci evaluate --data` refused a data set of x_mm and x_px files; `iloci teach` took
    the same files without a word."""
    circle = np.stack([np.cos(np.linspace(0, 6, 40)), np.sin(np.linspace(0, 6, 40))], axis=1)
    mm, px = tmp_path / "circle_mm.csv", tmp_path / "circle_px.csv"
    mm.write_text("x_mm,y_mm\n" + "".join(f"{x},{y}\n" for x, y in 30 * circle))
    px.write_text("x_px,y_px\n" + "".join(f"{x},{y}\n" for x, y in 100 * circle))
    memory = tmp_path / "m.npz"
    done = cli("teach", "--config", str(fast), "--memory", str(memory), str(mm), str(px))
    assert done.returncode == 2, done.stderr
    assert re.search(r"the files mix position units: mm: 1 file\(s\), e\.g\. .*circle_mm\.csv; "
                     r"px: 1 file", done.stderr), done.stderr
    assert "Nothing was learned" in done.stderr and not memory.exists()
    assert "Traceback" not in done.stderr


def test_serve_on_a_busy_port_or_an_unknown_host_says_so_before_announcing_a_page(tmp_path,
                                                                                    cli):
    """uvicorn's "[Errno 98] address already in use" came after "teach the robot at
    http://...", with exit code 3."""
    import socket

    pytest.importorskip("uvicorn")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        done = cli("serve", "--memory", str(tmp_path / "m.npz"), "--port", str(port))
    assert done.returncode == 2
    assert f"error: port {port} on 127.0.0.1 is in use" in done.stderr
    assert "teach the robot at" not in done.stdout and not (tmp_path / "m.npz").exists()
    done = cli("serve", "--memory", str(tmp_path / "m.npz"), "--host", "999.1.1.1")
    assert done.returncode == 2 and "--host 999.1.1.1: no such host" in done.stderr


def test_a_huge_file_is_refused_from_its_first_bytes_and_its_size(tmp_path, cli, monkeypatch):
    """`truncate -s 3G sparse.csv; iloci teach sparse.csv` read 3 GB (twice: for the
    resume digest, then to parse) and took 4.8 GB of memory before refusing its first
    byte."""
    from iloci.data import csvfile
    from iloci.errors import InvalidInputError

    sparse = tmp_path / "sparse.csv"
    with open(sparse, "wb") as fh:
        fh.truncate(3 << 30)                      # 3 GiB of zeros, no disk used
    done = cli("teach", "--memory", str(tmp_path / "m.npz"), str(sparse))
    assert "sparse.csv is not a text CSV file: it holds binary data" in done.stderr
    big = tmp_path / "big.csv"
    big.write_text("x,y\n" + "0.5,0.25\n" * 20000)
    monkeypatch.setattr(csvfile, "MAX_BYTES", 100_000)
    with pytest.raises(InvalidInputError, match="big.csv is 0 MiB: more than a drawing of "
                                                "at most 2,000,000 samples can be as text"):
        csvfile.read_csv(big)


def test_a_headerless_x_y_pressure_file_read_as_t_x_y_is_warned_of(tmp_path, cli):
    """An audit: a headerless x, y, pressure CSV whose x increased was read as t, x, y (the
    drawing taught was x against pressure) with exit 0 and no word."""
    import warnings

    import numpy as np

    from iloci.data.files import load_trajectory
    from iloci.errors import ColumnsWarning

    u = np.linspace(0.0, 1.0, 60)
    pressure = tmp_path / "wave.csv"
    np.savetxt(pressure, np.c_[10 * u, np.sin(6 * u), np.where(u < 0.5, 0.8, 0.9)],
               delimiter=",")
    with pytest.warns(ColumnsWarning, match="wave.csv: no header, so its 3 columns were read "
                                            "as t, x, y, but its y takes only 2 value"):
        load_trajectory(pressure)
    timed = tmp_path / "circle.csv"
    np.savetxt(timed, np.c_[u, np.cos(6 * u), np.sin(6 * u)], delimiter=",")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_trajectory(timed)                    # a real t, x, y file: no warning
    done = cli("show", str(pressure), "--out", str(tmp_path / "w.png"))
    assert "warning: wave.csv: no header" in done.stderr


def test_show_draws_a_screen_coordinate_pen_path_the_way_it_was_drawn(tmp_path, monkeypatch):
    """A fresh user's report: with [sensorimotor] y_axis = "down", `iloci show` drew the
    robot's fitted path upright and the pen path beside it upside down."""
    import matplotlib.pyplot as plt

    import iloci
    from iloci.commands.show import plot_motion
    shown = []
    monkeypatch.setattr(plt, "close", lambda fig=None: shown.append(fig))
    agent = iloci.build({"sensorimotor": {"y_axis": "down"}})
    t = np.linspace(0, 1, 40)
    demo = iloci.Demonstration(np.stack([t, t ** 2], axis=1))
    motion = agent.motion(demo)
    reached = np.asarray(agent.ik_solver.forward(motion.joint_path))
    for y_axis, inverted in (("down", True), ("up", False)):
        plot_motion(demo, motion, reached, agent.robot, tmp_path / f"{y_axis}.png",
                    y_axis=y_axis)
        pen = shown[-1].axes[0]
        assert bool(pen.yaxis_inverted()) is inverted
        assert pen.get_ylabel() == f"y (teacher, pointing {y_axis})"
