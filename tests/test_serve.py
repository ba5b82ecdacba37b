"""``iloci serve``: every HTTP endpoint and every bad input, through Starlette's TestClient.

Real agent (native-rnnpb, few epochs; pinocchio IK), real LASA shapes sent as
a person's strokes would be: pixel coordinates, y up, at a pace unlike
LASA's. The memory file must be untouched by every refused request.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("httpx")
pytest.importorskip("iloci_native")
pytest.importorskip("pinocchio")

from starlette.testclient import TestClient  # noqa: E402

import iloci  # noqa: E402
from iloci.commands.serve import build_classroom  # noqa: E402
from iloci.data import load_lasa  # noqa: E402
from iloci.web.app import MAX_BODY, MAX_POINTS, STATIC, create_app  # noqa: E402

EPOCHS = 30
CONFIG = {"perceptual_model": {"name": "native-rnnpb", "epochs": EPOCHS,
                               "recognition_steps": EPOCHS},
          "learner": {"rehearsal_epochs": EPOCHS}, "evaluation": {"seed": 0}}


def stroke(demo, n: int = 120, seconds: float = 1.3) -> list[list[float]]:
    """A LASA demonstration as a mouse stroke: n points in a 400 px box, y up, slow then fast."""
    pos = demo.positions
    idx = np.linspace(0, len(pos) - 1, n).astype(int)
    p = pos[idx]
    p = (p - p.min(axis=0)) / np.ptp(p, axis=0).max() * 360 + 20
    u = np.linspace(0, 1, n)
    t = 10.0 + seconds * u ** 1.6            # accelerating: not LASA's pace
    return [[float(x), float(y), float(s)] for (x, y), s in zip(p, t)]


@pytest.fixture(scope="module")
def lasa():
    return {d.key: d for d in load_lasa(["GShape", "Angle"])}


@pytest.fixture
def served(tmp_path):
    memory = tmp_path / "memory.npz"
    classroom = build_classroom(memory, CONFIG, worker=False)
    with TestClient(create_app(classroom)) as client:
        yield client, classroom, memory


def test_the_page_and_its_files_are_served_and_fetch_nothing_from_elsewhere(served):
    client, _, _ = served
    page = client.get("/")
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]
    for name in ("app.js", "style.css"):
        assert client.get(f"/static/{name}").status_code == 200
    for f in STATIC.iterdir():
        text = f.read_text(encoding="utf-8")
        assert "http://" not in text and "https://" not in text and "//cdn" not in text, f
    assert client.get("/static/../app.py").status_code == 404


def test_teach_a_concept_answer_it_rename_it_recognize_it(served, lasa, tmp_path):
    client, classroom, memory = served
    state = client.get("/api/state").json()
    assert state["memory"]["concepts"] == [] and state["pending"] is None
    assert client.post("/api/recognize", json={"points": stroke(lasa["GShape/0"])}
                       ).status_code == 409                    # nothing learned yet
    first = client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])}).json()
    assert first["outcome"]["action"] == "new_concept" and first["outcome"]["concept"] == "c1"
    assert memory.is_file()
    (concept,) = first["memory"]["concepts"]
    assert concept["name"] == "c1" and len(concept["entries"][0]["drawing"]) == 50

    # a new shape: the robot guesses c1, the person says no: a new concept
    data = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}).json()
    answer = data["answer"]
    assert (answer["concept"], answer["attempt"], answer["confidence"]) == ("c1", 1, 1.0)
    assert len(answer["drawing"]) == len(answer["joint_path"]) == 50
    assert answer["dt"] > 0 and len(answer["start_posture"]) == 4
    assert client.get("/api/state").json()["pending"]["turn"] == answer["turn"]
    assert client.get("/api/progress").json() == {"progress": None}
    done = client.post("/api/feedback", json={"turn": answer["turn"], "value": -1}).json()
    assert done["outcome"]["action"] == "new_concept" and done["outcome"]["concept"] == "c2"
    assert [c["name"] for c in done["memory"]["concepts"]] == ["c1", "c2"]

    # the same shape again: a correct guess, rewarded
    data = client.post("/api/observe", json={"points": stroke(lasa["GShape/1"], 90, 2.5)}).json()
    answer = data["answer"]
    assert answer["concept"] == "c1"
    # its drawing is shown where the stroke was drawn (pixels, y up)
    drawing = np.array(answer["drawing"])
    assert np.all(drawing.min(axis=0) > -200) and np.all(drawing.max(axis=0) < 600)
    done = client.post("/api/feedback", json={"turn": answer["turn"], "value": 1}).json()
    assert done["outcome"]["action"] in ("strengthen", "new_exemplar")
    assert done["outcome"]["feedbacks"] == [1]

    renamed = client.post("/api/rename", json={"concept": "c1", "name": "G"}).json()
    assert [c["name"] for c in renamed["memory"]["concepts"]] == ["G", "c2"]
    got = client.post("/api/recognize", json={"points": stroke(lasa["GShape/2"])}).json()
    assert got["concept"] == "G" and 0 <= got["confidence"] <= 1
    # kept in the file: every command sees the name
    assert iloci.Agent.load(memory).memory.concepts() == ["G", "c2"]
    assert classroom.agent.memory.demonstrations_seen == 3

    # a restarted server goes on from the file
    again = build_classroom(memory, worker=False)
    with TestClient(create_app(again)) as client2:
        state = client2.get("/api/state").json()["memory"]
        assert [c["name"] for c in state["concepts"]] == ["G", "c2"]
        assert state["demonstrations_seen"] == 3


def test_the_novelty_answer_and_unknown_in_the_browser_api(tmp_path):
    """[learner] novelty_below / unknown_below served: the novelty answer is
    marked ``novel`` with a null confidence (JSON has no NaN; it was a 500),
    and "yes" founds the concept it named; recognition says ``unknown``."""
    shapes = ["GShape", "Angle", "Sine", "Leaf_1", "Snake", "Worm"]
    lasa = {d.key: d for d in load_lasa(shapes)}
    cfg = {**CONFIG, "learner": {**CONFIG["learner"], "novelty_below": 0.8,
                                 "unknown_below": 0.8, "confirm_rewards": True}}
    classroom = build_classroom(tmp_path / "memory.npz", cfg, worker=False)
    novel = None
    with TestClient(create_app(classroom)) as client:
        for shape in shapes:
            r = client.post("/api/observe", json={"points": stroke(lasa[f"{shape}/0"])})
            assert r.status_code == 200, r.text
            while "answer" in r.json():
                answer = r.json()["answer"]
                assert isinstance(answer["novel"], bool)
                if answer["novel"]:
                    assert answer["confidence"] is None
                    novel = answer
                    r = client.post("/api/feedback", json={"turn": answer["turn"], "value": 1})
                    outcome = r.json()["outcome"]
                    assert (outcome["action"], outcome["concept"]) == ("new_concept",
                                                                       answer["concept"])
                    break
                assert 0 <= answer["confidence"] <= 1
                r = client.post("/api/feedback", json={"turn": answer["turn"], "value": -1})
                assert r.status_code == 200, r.text
            assert client.get("/api/state").status_code == 200
        assert novel is not None, "no novelty answer in six new shapes"
        got = client.post("/api/recognize", json={"points": stroke(lasa["GShape/1"])})
        assert got.status_code == 200, got.text
        rec = got.json()
        assert isinstance(rec["unknown"], bool) and 0 <= rec["familiarity"] <= 1


def test_feedback_refused_without_a_matching_guess(served, lasa):
    client, _, memory = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    answer = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}).json()["answer"]
    before = memory.read_bytes()
    cases = [({"turn": answer["turn"] + 1, "value": 1}, 409),
             ({"turn": answer["turn"], "value": 0}, 422),
             ({"turn": answer["turn"], "value": True}, 422),
             ({"turn": answer["turn"], "value": "yes"}, 422),
             ({"value": 1}, 400), ([1], 400)]
    for body, status in cases:
        r = client.post("/api/feedback", json=body)
        assert r.status_code == status, (body, r.text)
        assert r.json()["error"]
    assert memory.read_bytes() == before
    # the guess still waits: answered now, once
    assert client.post("/api/feedback", json={"turn": answer["turn"], "value": -1}
                       ).status_code == 200
    assert client.post("/api/feedback", json={"turn": answer["turn"], "value": -1}
                       ).status_code == 409


def test_every_bad_drawing_is_a_4xx_json_error_and_the_memory_is_untouched(served, lasa):
    client, classroom, memory = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    before = memory.read_bytes()
    seen = classroom.agent.memory.demonstrations_seen
    good = stroke(lasa["Angle/0"])
    flat = [[5.0, 5.0, 1.0 + i / 10] for i in range(20)]
    backwards = [list(p) for p in good]
    backwards[7][2] = backwards[6][2]
    many = [[float(i % 300), float(i // 300), i / 1000] for i in range(MAX_POINTS + 1)]
    cases = [
        (b"{not json", 400, "not JSON"),
        (json.dumps({"pts": good}), 400, "points"),
        (json.dumps({"points": "abc"}), 400, "list"),
        (json.dumps({"points": [[1, 2]] * 5}), 400, "three numbers"),
        (json.dumps({"points": [[1, 2, "t"]] * 5}), 400, "three numbers"),
        (json.dumps({"points": good[:2]}), 422, "at least 3"),
        (json.dumps({"points": many}), 422, f"at most {MAX_POINTS}"),
        (json.dumps({"points": flat}), 422, "zero extent"),
        (json.dumps({"points": backwards}), 422, "times must increase"),
        (json.dumps({"points": [[float("nan"), 1.0, 1.0]] + good[1:]}), 422, "not finite"),
        (json.dumps({"points": [[1e300, 1.0, 1.0]] + good[1:]}), 422, "exceeds"),
        (b"x" * (MAX_BODY + 1), 413, "over"),
    ]
    for path in ("/api/observe", "/api/recognize"):
        for body, status, words in cases:
            r = client.post(path, content=body, headers={"content-type": "application/json"})
            assert r.status_code == status, (path, body[:40], r.text)
            assert words in r.json()["error"], r.json()
    assert memory.read_bytes() == before
    assert classroom.agent.memory.demonstrations_seen == seen


def test_rename_errors(served, lasa):
    client, _, memory = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    before = memory.read_bytes()
    for body, status in [({"concept": "c9", "name": "x"}, 404),
                         ({"concept": "c1", "name": ""}, 422),
                         ({"concept": "c1", "name": "a/b"}, 422),
                         ({"concept": "c1", "name": "x" * 41}, 422),
                         ({"concept": "c1"}, 400), ({"concept": 1, "name": "x"}, 400)]:
        r = client.post("/api/rename", json=body)
        assert r.status_code == status and r.json()["error"], (body, r.text)
    assert memory.read_bytes() == before


def test_the_arm_picture_needs_a_simulator_and_a_pending_guess(served, lasa, tmp_path):
    client, _, _ = served
    r = client.get("/api/arm.png?turn=1&attempt=1")
    assert r.status_code == 404 and "simulator" in r.json()["error"]
    pytest.importorskip("pybullet")
    cfg = {**CONFIG, "simulator": {"name": "pybullet"}}
    classroom = build_classroom(tmp_path / "sim.npz", cfg, worker=False)
    with TestClient(create_app(classroom)) as sim:
        sim.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
        answer = sim.post("/api/observe", json={"points": stroke(lasa["GShape/1"])}
                          ).json()["answer"]
        assert answer["executed"] and answer["arm"]
        png = sim.get(answer["arm"])
        assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
        assert sim.get("/api/arm.png?turn=99&attempt=1").status_code == 404


def test_the_server_learns_with_its_network_in_a_worker(tmp_path, lasa):
    classroom = build_classroom(tmp_path / "w.npz", CONFIG)        # worker=True
    try:
        assert type(classroom.agent.perceptual_model).__name__ == "WorkerModel"
        with TestClient(create_app(classroom)) as client:
            client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
            answer = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}
                                 ).json()["answer"]
            out = client.post("/api/feedback", json={"turn": answer["turn"], "value": -1}).json()
            assert out["outcome"]["concept"] == "c2"
    finally:
        classroom.agent.close()
    assert iloci.Agent.load(tmp_path / "w.npz").memory.concepts() == ["c1", "c2"]


def test_the_command_refuses_a_bad_port_and_a_corrupt_memory(tmp_path, capsys):
    from iloci.cli import main

    assert main(["serve", "--port", "70000"]) == 2
    assert "--port must be 1..65535" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a memory")
    assert main(["serve", "--memory", str(bad), "--port", "8765"]) == 2
    assert "cannot read memory file" in capsys.readouterr().err
    assert bad.read_bytes() == b"not a memory"
