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
from iloci.progress import MemoryLockedError  # noqa: E402
from iloci.commands.serve import build_classroom  # noqa: E402
from iloci.data import load_lasa  # noqa: E402
from iloci.web.app import MAX_BODY, MAX_POINTS, STATIC, TOKEN_HEADER, create_app  # noqa: E402

from conftest import agent_state, assert_same_state, small_config  # noqa: E402



def judge(client, answer, value):
    """POST /api/feedback judging ``answer`` (its turn and its id) with ``value``."""
    return client.post("/api/feedback", json={"turn": answer["turn"], "answer": answer["id"],
                                              "value": value})

def page_client(classroom, **app_options) -> TestClient:
    """A client as the page is one: this computer's address, the server's token."""
    app = create_app(classroom, **app_options)
    client = TestClient(app, base_url="http://127.0.0.1:8000")
    client.headers[TOKEN_HEADER] = app.state.token
    return client


def stroke(demo, n: int = 120, seconds: float = 1.3) -> list[list[float]]:
    """A LASA demonstration as a mouse stroke: n points in a 400 px box, y up, slow then fast."""
    pos = demo.positions
    idx = np.linspace(0, len(pos) - 1, n).astype(int)
    p = pos[idx]
    p = (p - p.min(axis=0)) / np.ptp(p, axis=0).max() * 360 + 20
    u = np.linspace(0, 1, n)
    t = 10.0 + seconds * u ** 1.6            # accelerating: not LASA's pace
    return [[float(x), float(y), float(s)] for (x, y), s in zip(p, t)]


@pytest.fixture
def served(tmp_path):
    memory = tmp_path / "memory.npz"
    classroom = build_classroom(memory, small_config(), worker=False, protocol="paper")
    try:
        with page_client(classroom) as client:
            yield client, classroom, memory
    finally:
        classroom.close()


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
    # the only concept there is: no confidence is claimed for the last guess left
    assert (answer["concept"], answer["attempt"], answer["confidence"]) == ("c1", 1, None)
    assert answer["last_guess"] is True
    assert len(answer["drawing"]) == len(answer["joint_path"]) == 50
    assert answer["dt"] > 0 and len(answer["start_posture"]) == 4
    assert client.get("/api/state").json()["pending"]["turn"] == answer["turn"]
    assert client.get("/api/progress").json() == {"progress": None}
    done = judge(client, answer, -1).json()
    assert done["outcome"]["action"] == "new_concept" and done["outcome"]["concept"] == "c2"
    assert [c["name"] for c in done["memory"]["concepts"]] == ["c1", "c2"]

    # the same shape again: a correct guess, rewarded
    data = client.post("/api/observe", json={"points": stroke(lasa["GShape/1"], 90, 2.5)}).json()
    answer = data["answer"]
    assert answer["concept"] == "c1"
    # its drawing is shown where the stroke was drawn (pixels, y up)
    drawing = np.array(answer["drawing"])
    assert np.all(drawing.min(axis=0) > -200) and np.all(drawing.max(axis=0) < 600)
    done = judge(client, answer, 1).json()
    assert done["outcome"]["action"] in ("strengthen", "new_exemplar")
    assert done["outcome"]["feedbacks"] == [1]

    renamed = client.post("/api/rename", json={"concept": "c1", "name": "G"}).json()
    assert [c["name"] for c in renamed["memory"]["concepts"]] == ["G", "c2"]
    got = client.post("/api/recognize", json={"points": stroke(lasa["GShape/2"])}).json()
    assert got["concept"] == "G" and 0 <= got["confidence"] <= 1
    # kept in the file: every command sees the name
    assert iloci.Agent.load(memory).memory.concepts() == ["G", "c2"]
    assert classroom.agent.memory.demonstrations_seen == 3

    # a second server on the same file is refused, naming the first
    with pytest.raises(MemoryLockedError, match=r"iloci serve, pid \d+, since"):
        build_classroom(memory, worker=False)
    # a restarted server goes on from the file
    classroom.close()
    again = build_classroom(memory, worker=False)
    with page_client(again) as client2:
        state = client2.get("/api/state").json()["memory"]
        assert [c["name"] for c in state["concepts"]] == ["G", "c2"]
        assert state["demonstrations_seen"] == 3
    again.close()


def test_the_novelty_answer_and_unknown_in_the_browser_api(tmp_path):
    """[learner] novelty_below / unknown_below served: the novelty answer is
    marked ``novel`` with a null confidence (JSON has no NaN; it was a 500),
    and "yes" founds the concept it named; recognition says ``unknown``."""
    shapes = ["GShape", "Angle", "Sine", "Leaf_1", "Snake", "Worm"]
    lasa = {d.key: d for d in load_lasa(shapes)}
    cfg = small_config(learner={"novelty_below": 0.8, "unknown_below": 0.8,
                                "confirm_rewards": True})
    classroom = build_classroom(tmp_path / "memory.npz", cfg, worker=False, protocol="paper")
    novel = None
    with page_client(classroom) as client:
        for shape in shapes:
            r = client.post("/api/observe", json={"points": stroke(lasa[f"{shape}/0"])})
            assert r.status_code == 200, r.text
            while "answer" in r.json():
                answer = r.json()["answer"]
                assert isinstance(answer["novel"], bool)
                if answer["novel"]:
                    assert answer["confidence"] is None
                    novel = answer
                    r = judge(client, answer, 1)
                    outcome = r.json()["outcome"]
                    assert (outcome["action"], outcome["concept"]) == ("new_concept",
                                                                       answer["concept"])
                    break
                if answer["last_guess"]:                  # no margin claimed then
                    assert answer["confidence"] is None
                else:
                    assert 0 <= answer["confidence"] <= 1
                r = judge(client, answer, -1)
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
    cases = [({"turn": answer["turn"] + 1, "answer": answer["id"], "value": 1}, 409),
             ({"turn": answer["turn"], "answer": answer["id"] + "x", "value": 1}, 409),
             ({"turn": answer["turn"], "value": 1}, 400),
             ({"turn": answer["turn"], "answer": answer["id"], "value": 0}, 422),
             ({"turn": answer["turn"], "answer": answer["id"], "value": True}, 422),
             ({"turn": answer["turn"], "answer": answer["id"], "value": "yes"}, 422),
             ({"value": 1}, 400), ([1], 400)]
    for body, status in cases:
        r = client.post("/api/feedback", json=body)
        assert r.status_code == status, (body, r.text)
        assert r.json()["error"]
    assert memory.read_bytes() == before
    # the guess still waits: answered now, once
    assert judge(client, answer, -1).status_code == 200
    assert judge(client, answer, -1).status_code == 409


def test_every_bad_drawing_is_a_4xx_json_error_and_the_memory_is_untouched(served, lasa):
    client, classroom, memory = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    before = memory.read_bytes()
    seen = classroom.agent.memory.demonstrations_seen
    good = stroke(lasa["Angle/0"])
    flat = [[5.0, 5.0, 1.0 + i / 10] for i in range(20)]
    # a short move, then the pen rests: 3 samples once the rest is trimmed
    resting = [[5.0 + 10 * min(i, 2), 5.0, 1.0 + i / 10] for i in range(20)]
    backwards = [list(p) for p in good]
    backwards[7][2] = backwards[6][2]
    many = [[float(i % 300), float(i // 300), i / 1000] for i in range(MAX_POINTS + 1)]
    cases = [
        (b"{not json", 400, "not JSON"),
        (json.dumps({"pts": good}), 400, "points"),
        (json.dumps({"points": "abc"}), 400, "list"),
        (json.dumps({"points": [[1, 2]] * 5}), 400, "three numbers"),
        (json.dumps({"points": [[1, 2, "t"]] * 5}), 400, "three numbers"),
        (json.dumps({"points": good[:4]}), 422, "at least 5"),
        (json.dumps({"points": many}), 422, f"at most {MAX_POINTS}"),
        (json.dumps({"points": flat}), 422, "does not move"),
        (json.dumps({"points": resting}), 422, "too short"),
        (json.dumps({"points": backwards}), 422, "times must increase"),
        (json.dumps({"points": [[float("nan"), 1.0, 1.0]] + good[1:]}), 422, "not finite"),
        (json.dumps({"points": [[1e300, 1.0, 1.0]] + good[1:]}), 422, "exceeds"),
        (b"x" * (MAX_BODY + 1), 413, f"over {MAX_BODY:,} bytes: a drawing is sent with at "
                                     f"most {MAX_POINTS} points [x, y, t]; send fewer"),
    ]
    for path in ("/api/observe", "/api/recognize"):
        for body, status, words in cases:
            r = client.post(path, content=body, headers={"content-type": "application/json"})
            assert r.status_code == status, (path, body[:40], r.text)
            assert words in r.json()["error"], r.json()
            assert "[sensorimotor]" not in r.json()["error"]     # a person's words
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
    cfg = small_config(simulator={"name": "pybullet"})
    classroom = build_classroom(tmp_path / "sim.npz", cfg, worker=False, protocol="paper")
    with page_client(classroom) as sim:
        sim.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
        answer = sim.post("/api/observe", json={"points": stroke(lasa["GShape/1"])}
                          ).json()["answer"]
        assert answer["executed"] and answer["arm"]
        png = sim.get(answer["arm"])
        assert png.status_code == 200 and png.content[:8] == b"\x89PNG\r\n\x1a\n"
        assert sim.get("/api/arm.png?turn=99&attempt=1").status_code == 404


def test_the_server_learns_with_its_network_in_a_worker(tmp_path, lasa):
    classroom = build_classroom(tmp_path / "w.npz", small_config(), protocol="paper")   # a worker
    try:
        assert type(classroom.agent.perceptual_model).__name__ == "WorkerModel"
        with page_client(classroom) as client:
            client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
            answer = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}
                                 ).json()["answer"]
            out = judge(client, answer, -1).json()
            assert out["outcome"]["concept"] == "c2"
    finally:
        classroom.close()
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


# -- safe by default (issue 26) ------------------------------------------------------
def test_writes_need_the_token_json_and_no_foreign_origin(served, lasa):
    client, classroom, memory = served
    good = stroke(lasa["GShape/0"])
    body = json.dumps({"points": good})
    token = client.headers[TOKEN_HEADER]
    page = client.get("/").text
    assert token in page and len(token) >= 32            # the page has it, and only the page
    attacks = [
        ({TOKEN_HEADER: ""}, 403, "token"),
        ({TOKEN_HEADER: token[:-1] + "x"}, 403, "token"),
        ({"content-type": "text/plain"}, 415, "application/json"),
        ({"content-type": "application/x-www-form-urlencoded"}, 415, "application/json"),
        ({"origin": "http://127.0.0.1:9999"}, 403, "another page"),
        ({"origin": "null"}, 403, "another page"),
        ({"sec-fetch-site": "cross-site"}, 403, "another site"),
        ({"sec-fetch-site": "same-site"}, 403, "another site"),
        ({"host": "evil.example:8000"}, 403, "--allow-host"),
        ({"host": "127.0.0.1.evil.example"}, 403, "--allow-host"),
    ]
    for path in ("/api/observe", "/api/rename", "/api/undo", "/api/reset", "/api/forget"):
        for headers, status, words in attacks:
            h = {"content-type": "application/json", **headers}
            r = client.post(path, content=body, headers=h)
            assert r.status_code == status, (path, headers, r.text)
            assert words in r.json()["error"], r.json()
    assert not memory.exists()                           # nothing was learned or saved
    # reads: another site (or a rebinding Host) reads nothing
    for path in ("/api/state", "/api/export", "/api/progress"):
        assert client.get(path, headers={"sec-fetch-site": "cross-site"}).status_code == 403
        assert client.get(path, headers={"host": "evil.example"}).status_code == 403
    assert client.get("/", headers={"host": "evil.example"}).status_code == 403
    r = client.get("/")
    assert r.headers["x-frame-options"] == "DENY"
    assert "frame-ancestors 'none'" in r.headers["content-security-policy"]
    assert "access-control-allow-origin" not in r.headers
    assert client.get("/api/state").headers["cross-origin-resource-policy"] == "same-origin"
    # the page itself (same origin) teaches
    r = client.post("/api/observe", content=body, headers={
        "content-type": "application/json; charset=utf-8", "origin": "http://127.0.0.1:8000",
        "sec-fetch-site": "same-origin"})
    assert r.status_code == 200, r.text
    assert memory.exists()


def test_allow_host_names_another_host(tmp_path, lasa):
    classroom = build_classroom(tmp_path / "m.npz", small_config(), worker=False)
    try:
        with page_client(classroom, hosts=["robot.local"]) as client:
            assert client.get("/api/state", headers={"host": "robot.local:8000"}
                              ).status_code == 200
            assert client.get("/api/state", headers={"host": "other.local"}).status_code == 403
        with page_client(classroom, hosts=["*"]) as client:
            assert client.get("/api/state", headers={"host": "other.local"}).status_code == 200
    finally:
        classroom.close()


def test_malformed_requests_are_4xx_with_a_message_and_no_traceback(served, lasa, caplog):
    client, _, memory = served
    good = stroke(lasa["GShape/0"])
    deep = b'{"points": ' + b"[" * 100_000 + b"]" * 100_000 + b"}"
    huge = json.dumps({"points": [[int("9" * 400), 1, 1]] + good[1:]})
    cases = [(deep, (400, 413), "JSON"), (huge, (422,), "exceeds"),
             (b'{"points": [[1, 2, 3]]' + b" " * 10, (400,), "not JSON"),
             (b"\xff\xfe", (400,), "not JSON")]
    r = client.post("/api/observe", json={"points": good, "client": "../x"})
    assert r.status_code == 400 and "client" in r.json()["error"]
    for body, statuses, _words in cases:
        for path in ("/api/observe", "/api/recognize"):
            r = client.post(path, content=body, headers={"content-type": "application/json"})
            assert r.status_code in statuses, (path, body[:30], r.text)
            assert r.json()["error"]
    for body in [{"turn": int("9" * 400), "value": 1}, {"turn": "1", "value": 1},
                 {"turn": 1, "value": [1]}, {"turn": 1, "value": {"a": 1}}]:
        r = client.post("/api/feedback", json=body)
        assert 400 <= r.status_code < 500 and r.json()["error"], (body, r.text)
    for body in [{"entry": int("9" * 400)}, {"entry": -1}, {"entry": True}, {"concept": 3}, []]:
        r = client.post("/api/forget", json=body)
        assert 400 <= r.status_code < 500 and r.json()["error"], (body, r.text)
    assert client.get("/api/arm.png?turn=" + "9" * 400 + "&attempt=1").status_code == 404
    assert "Traceback" not in caplog.text
    assert not memory.exists()


# -- each tab its own turn -------------------------------------------------------------
def test_each_client_has_its_own_turn(served, lasa):
    client, classroom, _ = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"]), "client": "a"})
    a = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"]),
                                          "client": "a"}).json()["answer"]
    b = client.post("/api/observe", json={"points": stroke(lasa["GShape/1"]),
                                          "client": "b"}).json()["answer"]
    assert a["turn"] != b["turn"]
    # a reload of tab A finds its guess and its drawing; B's is B's
    sa = client.get("/api/state?client=a").json()["pending"]
    assert sa["turn"] == a["turn"] and len(sa["points"]) == 120
    assert client.get("/api/state?client=b").json()["pending"]["turn"] == b["turn"]
    # B's drawing did not drop A's guess; B ends its turn (the memory changes) ...
    out = judge(client, b, 1).json()
    assert out["outcome"]["concept"] == "c1"
    # ... and A's answer is not lost: its drawing is looked at again, A is told why
    again = judge(client, a, -1).json()
    assert "notice" in again and "looked at your drawing again" in again["notice"]
    done = judge(client, again["answer"], -1).json()
    assert done["outcome"]["action"] == "new_concept"
    # a tab's new drawing replaces only its own guess
    a2 = client.post("/api/observe", json={"points": stroke(lasa["Angle/1"]),
                                           "client": "a"}).json()["answer"]
    client.post("/api/observe", json={"points": stroke(lasa["Angle/2"]), "client": "a"})
    assert judge(client, a2, 1).status_code == 409
    # a tab that names itself cannot judge another tab's guess (an audit's tab B said
    # "no" to tab A's drawing; A was then told its guess was judged already)
    a3 = client.get("/api/state?client=a").json()["pending"]
    r = client.post("/api/feedback", json={"turn": a3["turn"], "answer": a3["id"],
                                           "value": -1, "client": "b"})
    assert r.status_code == 409 and "another tab's drawing" in r.json()["error"]
    r = client.post("/api/feedback", json={"turn": a3["turn"], "answer": a3["id"],
                                           "value": -1, "client": "a"})
    assert r.status_code == 200, r.text


def test_another_tabs_undo_start_over_or_import_keeps_this_tabs_guess(served, lasa, tmp_path):
    """Tab A's guess waits while tab B undoes, starts over or imports: A's answer is
    not refused with a wrong reason; A's drawing is looked at again and A is told why."""
    client, classroom, memory = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"]), "client": "b"})
    a = client.post("/api/observe", json={"points": stroke(lasa["GShape/1"]),
                                          "client": "a"}).json()["answer"]
    exported = memory.read_bytes()
    for path, body in [("/api/undo", {}), ("/api/reset", {}), ("/api/import", exported)]:
        if path == "/api/import":
            r = client.post(path, content=body,
                            headers={"Content-Type": "application/octet-stream"})
        else:
            r = client.post(path, json=body)
        assert r.status_code == 200, (path, r.text)
        out = judge(client, a, 1)
        assert out.status_code == 200, (path, out.text)
        out = out.json()
        assert "looked at your drawing again" in out["notice"], path
        if "answer" not in out:               # an empty memory: the drawing founds c1
            assert out["outcome"]["action"] == "new_concept"
            fresh = lasa[f"GShape/{3 + len(path) % 3}"]        # not the drawing just learned
            r = client.post("/api/observe", json={"points": stroke(fresh),
                                                  "client": "a"}).json()
            assert "answer" in r, (path, r.get("outcome"), r.get("error"))
            a = r["answer"]
        else:
            a = out["answer"]
    # a guess that no longer waits says why
    client.post("/api/observe", json={"points": stroke(lasa["GShape/2"]), "client": "a"})
    r = judge(client, a, 1)
    assert r.status_code == 409 and "this tab drew something newer" in r.json()["error"]
    b = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"]),
                                          "client": "b"}).json()["answer"]
    assert judge(client, b, "new").status_code == 200
    r = judge(client, b, "new")
    assert r.status_code == 409 and "answered already" in r.json()["error"]


def test_names_ports_origins_and_routes_are_checked_strictly(served, lasa):
    client, classroom, memory = served
    for host in ("[::1]:8000", "LOCALHOST:8000", "127.0.0.1:9000", "localhost"):
        assert client.get("/api/state", headers={"host": host}).status_code == 200, host
    for host in ("[::1]evil.test:8000", "127.0.0.1:8000 evil", "127.0.0.1:evil",
                 "localhost.:8000", "evil.test:8000", "127.0.0.1:8000:1", ""):
        r = client.get("/api/state", headers={"host": host})
        assert r.status_code == 403 and "--allow-host" in r.json()["error"], host
    # the origin's scheme counts: the server speaks http
    r = client.post("/api/rename", json={"concept": "c1", "name": "x"},
                    headers={"origin": "https://127.0.0.1:8000"})
    assert r.status_code == 403 and "another page" in r.json()["error"]
    # routes and methods that do not exist answer JSON with a message
    r = client.put("/api/rename", json={})
    assert r.status_code == 405 and "takes POST" in r.json()["error"]
    r = client.get("/api/nothing")
    assert r.status_code == 404 and "nothing at /api/nothing" in r.json()["error"]


def test_a_guess_for_a_drawing_like_nothing_taught_says_unsure_not_a_confidence(tmp_path,
                                                                                 lasa):
    """Below [learner] unknown_below (Recognize's "unknown"), a guess shows no margin
    confidence: between two poor matches it can be 1.00. With the default config and 5
    shapes taught, LASA's heee got "c3, confidence 0.999" at familiarity 0.66."""
    for below, unsure in ((1.0, True), (0.0, False)):
        config = small_config(learner={"unknown_below": below})
        classroom = build_classroom(tmp_path / f"m{below}.npz", config, worker=False,
                                    protocol="paper")
        try:
            with page_client(classroom) as client:
                client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
                a = client.post("/api/observe",
                                json={"points": stroke(lasa["Angle/0"])}).json()["answer"]
                judge(client, a, "new")                  # two concepts: a familiarity scale
                a = client.post("/api/observe",
                                json={"points": stroke(lasa["GShape/1"])}).json()["answer"]
                assert a["unsure"] is unsure and 0 < a["familiarity"] <= 1
                assert (a["confidence"] is None) is unsure
                pending = client.get("/api/state").json()["pending"]   # a reload says the same
                assert pending["unsure"] is unsure
        finally:
            classroom.close()


def test_errors_are_in_a_persons_words(served, lasa):
    client, classroom, memory = served
    r = client.post("/api/recognize", json={"points": stroke(lasa["GShape/0"])})
    assert r.status_code == 409
    assert "teach it a first drawing (Teach mode)" in r.json()["error"]
    assert "Agent.learn" not in r.json()["error"]
    r = client.post("/api/import", content=b"PK\x03\x04" + bytes(100),
                    headers={"Content-Type": "application/octet-stream"})
    assert r.status_code == 422 and "not imported" in r.json()["error"]
    assert "upload.npz" not in r.json()["error"] and "/tmp" not in r.json()["error"]
    r = client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])},
                    headers={TOKEN_HEADER: "a token of an earlier start"})
    assert r.status_code == 403 and "Reload the page" in r.json()["error"]
    assert client.get("/api/state").json()["memory"]["saved"] is False
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    assert client.get("/api/state").json()["memory"]["saved"] is True


def test_a_guess_answered_already_in_a_duplicated_tab_is_said_in_a_persons_words(served,
                                                                                 lasa):
    """A browser audit: a duplicated tab (one client id) answering a guess the other had
    answered got "answer '6110a15f-1' is not waiting for a feedback ... Send feedback with
    the id of the answer shown (Answer.id)": library words, for a person."""
    client, classroom, _ = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"]), "client": "tab"})
    a = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"]),
                                          "client": "tab"}).json()["answer"]
    judge(client, a, "new")                                      # a second concept
    first = client.post("/api/observe", json={"points": stroke(lasa["Angle/1"]),
                                              "client": "tab"}).json()["answer"]
    assert judge(client, first, -1).json()["answer"]["id"] != first["id"]   # the next guess
    r = judge(client, first, -1)                                 # the other tab, late
    assert r.status_code == 409, r.text
    said = r.json()["error"]
    assert said.startswith("This guess was answered already (in another window or tab")
    assert "Answer.id" not in said and "nothing changed" in said


def test_something_new_founds_a_concept_in_one_click(served, lasa):
    client, _, _ = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])})
    a = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}).json()["answer"]
    out = judge(client, a, "new").json()
    assert out["outcome"]["action"] == "new_concept"
    assert all(f == -1 for f in out["outcome"]["feedbacks"])


# -- a person's controls -----------------------------------------------------------------
def test_undo_puts_memory_and_network_back_exactly(served, lasa):
    client, classroom, memory = served
    assert client.post("/api/undo", json={}).status_code == 409       # nothing yet
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    before, file_before = agent_state(classroom.agent), memory.read_bytes()
    a = client.post("/api/observe", json={"points": stroke(lasa["GShape/1"])}).json()["answer"]
    out = judge(client, a, 1).json()
    assert out["memory"]["undo"].startswith("drawing")
    with pytest.raises(AssertionError):
        assert_same_state(before, agent_state(classroom.agent))       # the step changed it
    r = client.post("/api/undo", json={})
    assert r.status_code == 200, r.text
    assert_same_state(before, agent_state(classroom.agent))
    saved = iloci.Agent.load(memory)
    assert_same_state(before, agent_state(saved))
    assert memory.read_bytes() != b"" and len(memory.read_bytes()) == len(file_before)
    # forget, rename, start over: each undone the same way
    for path, body in [("/api/rename", {"concept": "c1", "name": "G"}),
                       ("/api/forget", {"concept": "c1"}), ("/api/reset", {})]:
        r = client.post(path, json=body)
        assert r.status_code == 200, (path, r.text)
        client.post("/api/undo", json={})
        assert_same_state(before, agent_state(classroom.agent))


def test_forget_an_entry_and_a_concept(served, lasa):
    client, classroom, memory = served
    for key in ("GShape/0", "Angle/0"):
        r = client.post("/api/observe", json={"points": stroke(lasa[key])}).json()
        if "answer" in r:
            judge(client, r["answer"], -1)
    assert classroom.agent.memory.concepts() == ["c1", "c2"]
    r = client.post("/api/forget", json={"concept": "c9"})
    assert r.status_code == 404
    r = client.post("/api/forget", json={"entry": 0}).json()
    assert [c["name"] for c in r["memory"]["concepts"]] == ["c2"]
    r = client.post("/api/forget", json={"concept": "c2"}).json()
    assert r["memory"]["concepts"] == [] and iloci.Agent.load(memory).memory.entries == []


def test_a_control_from_a_page_another_tab_has_changed_is_refused(served, lasa):
    """An audit's two tabs: tab B taught, then tab A's Undo took back B's step (A's page
    still said "undo: drawing/9"); A's forget of "entry 2" removed another concept's entry
    after B forgot entry 0. A page names the memory version it shows; a control from an
    older view is refused with the memory as it is, and nothing is done."""
    client, classroom, memory = served
    for key in ("GShape/0", "Angle/0"):
        r = client.post("/api/observe", json={"points": stroke(lasa[key])}).json()
        if "answer" in r:
            judge(client, r["answer"], -1)
    seen = client.get("/api/state").json()["memory"]             # tab A's view
    assert seen["version"] == classroom.history.version == 2
    r = client.post("/api/forget", json={"entry": 0, "version": seen["version"]})  # tab B
    assert r.status_code == 200, r.text
    now = r.json()["memory"]
    before = [e.sources for e in classroom.agent.memory.entries]
    for path, body in (("/api/undo", {}), ("/api/forget", {"entry": 1}),
                       ("/api/rename", {"concept": "c2", "name": "angle"}), ("/api/reset", {})):
        r = client.post(path, json={**body, "version": seen["version"]})  # tab A, stale
        assert r.status_code == 409, (path, r.text)
        assert r.json()["error"].startswith("nothing was done: the memory changed since "
                                            "this page showed it")
        assert r.json()["memory"] == now                          # the page is brought up to date
        assert [e.sources for e in classroom.agent.memory.entries] == before
    r = client.post("/api/undo", json={"version": now["version"]})  # from the fresh view: done
    assert r.status_code == 200 and r.json()["undone"] == "forget entry 0"
    assert client.post("/api/undo", json={}).status_code == 200   # a script names no version


def test_a_misspelt_field_is_refused_naming_it_not_read_as_missing(served, lasa):
    """An audit's script sent {"vesion": 3} with an undo: the field was ignored, so the
    stale-page check it asked for never ran, and the undo took back another tab's step.
    Every JSON action refuses a field it does not take, names it (with the field meant,
    when close) and changes nothing."""
    client, classroom, memory = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    answer = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}).json()["answer"]
    before, version = memory.read_bytes(), classroom.history.version
    cases = [("/api/undo", {"vesion": version}, "vesion", "version"),
             ("/api/reset", {"version": version, "force": True}, "force", None),
             ("/api/forget", {"concpt": "c1"}, "concpt", "concept"),
             ("/api/rename", {"concept": "c1", "nmae": "g"}, "nmae", "name"),
             ("/api/feedback", {"turn": answer["turn"], "answer": answer["id"], "vaule": 1},
              "vaule", "value"),
             ("/api/observe", {"points": stroke(lasa["GShape/1"]), "pts": []}, "pts", "points"),
             ("/api/recognize", {"points": stroke(lasa["GShape/1"]), "k": 3}, '"k"', None)]
    for path, body, named, meant in cases:
        r = client.post(path, json=body)
        assert r.status_code == 400, (path, r.text)
        error = r.json()["error"]
        assert named in error and "Nothing was changed" in error, error
        assert (f"did you mean '{meant}'" in error) if meant else "did you mean" not in error
    assert memory.read_bytes() == before and classroom.history.version == version
    assert judge(client, answer, -1).status_code == 200         # the guess still waits


def test_export_then_import_into_a_fresh_server(served, lasa, tmp_path):
    client, classroom, _ = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
    exported = client.get("/api/export")
    assert exported.status_code == 200
    assert "attachment" in exported.headers["content-disposition"]
    fresh = build_classroom(tmp_path / "fresh.npz", small_config(), worker=False, protocol="paper")
    try:
        with page_client(fresh) as other:
            for bad in (b"", b"PK\x03\x04 not a zip", b"\x80\x04\x95 pickle"):
                r = other.post("/api/import", content=bad,
                               headers={"content-type": "application/octet-stream"})
                assert r.status_code in (400, 422) and r.json()["error"], r.text
            r = other.post("/api/import", content=exported.content,
                           headers={"content-type": "application/json"})
            assert r.status_code == 415
            r = other.post("/api/import", content=exported.content,
                           headers={"content-type": "application/octet-stream"})
            assert r.status_code == 200, r.text
            assert [c["name"] for c in r.json()["memory"]["concepts"]] == ["c1"]
            assert_same_state(agent_state(classroom.agent), agent_state(fresh.agent))
            assert iloci.Agent.load(tmp_path / "fresh.npz").memory.concepts() == ["c1"]
            assert other.post("/api/undo", json={}).json()["memory"]["concepts"] == []
    finally:
        fresh.close()


# -- one writer per memory file ---------------------------------------------------------
def test_a_hard_link_made_after_a_save_is_refused_too(served, lasa, tmp_path):
    """The file lock was on the file as the server started; its first save wrote a new
    file, and a hard link made to that one let a second server teach the same memory."""
    import os

    client, classroom, memory = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})  # a first save
    first = memory.stat().st_ino
    r = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}).json()
    if "answer" in r:
        judge(client, r["answer"], -1)                                   # a second save
    assert memory.stat().st_ino != first                                 # a new file
    other = tmp_path / "other-name.npz"
    os.link(memory, other)
    with pytest.raises(MemoryLockedError, match=r"under another name \(a hard link to the "
                                                r"same file\)"):
        build_classroom(other, small_config(), worker=False)


def test_one_writer_a_symlink_and_a_failed_save(tmp_path, lasa):
    import resource

    target = tmp_path / "real" / "robot.npz"
    target.parent.mkdir()
    link = tmp_path / "link.npz"
    link.symlink_to(target)
    classroom = build_classroom(link, small_config(), worker=False, protocol="paper")
    try:
        # another writer of the same file, by any path, is refused
        with pytest.raises(MemoryLockedError, match="iloci serve, pid"):
            build_classroom(target, small_config(), worker=False)
        with page_client(classroom) as client:
            client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
            assert link.is_symlink() and target.is_file()       # written through the link
            size = target.stat().st_size
            before = target.read_bytes()
            a = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}
                            ).json()["answer"]
            soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
            resource.setrlimit(resource.RLIMIT_FSIZE, (size // 2, hard))   # the disk is full
            try:
                r = judge(client, a, -1)
            finally:
                resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
            assert r.status_code == 507, r.text
            err = r.json()
            assert "could not save" in err["error"] and str(target) in err["error"]
            assert "still holds" in err["error"] and err["saved"] is False
            # the page shows what the file holds: one concept, not the refused c2
            assert [c["name"] for c in err["memory"]["concepts"]] == ["c1"]
            state = client.get("/api/state").json()["memory"]
            assert [c["name"] for c in state["concepts"]] == ["c1"] and state["save_error"]
            assert target.read_bytes() == before and link.is_symlink()
            # space again: the same drawing is learned and saved
            a = client.post("/api/observe", json={"points": stroke(lasa["Angle/0"])}
                            ).json()["answer"]
            out = judge(client, a, -1).json()
            assert out["outcome"]["concept"] == "c2" and out["memory"]["save_error"] is None
    finally:
        classroom.close()
    assert iloci.Agent.load(target).memory.concepts() == ["c1", "c2"]


def test_teach_and_a_library_save_are_refused_while_served(tmp_path, lasa, cli):
    import subprocess
    import sys

    memory = tmp_path / "m.npz"
    classroom = build_classroom(memory, small_config(), worker=False, protocol="paper")
    try:
        with page_client(classroom) as client:
            client.post("/api/observe", json={"points": stroke(lasa["GShape/0"])})
        before = memory.read_bytes()
        out = cli("teach", "--memory", str(memory), "Angle/0")
        assert out.returncode == 2, out.stderr
        assert "iloci serve, pid" in out.stderr and "Traceback" not in out.stderr
        code = ("import sys, iloci\nfrom iloci.progress import MemoryLockedError\n"
                "a = iloci.Agent.load(sys.argv[1])\n"
                "try:\n    a.save(sys.argv[1])\n"
                "except MemoryLockedError as e:\n    print('REFUSED', e)\n")
        r = subprocess.run([sys.executable, "-c", code, str(memory)], capture_output=True,
                           text=True, timeout=300)
        assert "REFUSED" in r.stdout and "iloci serve, pid" in r.stdout, r.stdout + r.stderr
        assert memory.read_bytes() == before
    finally:
        classroom.close()
    # released: teach goes on from the served memory
    assert cli("teach", "--memory", str(memory), "Angle/0").returncode == 0


def test_the_interactive_protocol_is_the_default_where_the_config_is_silent(tmp_path):
    from iloci.commands.teach import PAGE

    classroom = build_classroom(tmp_path / "a.npz", small_config(), worker=False)
    try:
        learner = classroom.agent.config.learner
        assert PAGE == {"unknown_below": 0.8} and learner.unknown_below == 0.8
        assert learner.novelty_below == 0.0 and learner.confirm_rewards is False
    finally:
        classroom.close()
    own = small_config(learner={"unknown_below": 0.5, "novelty_below": 0.8})
    classroom = build_classroom(tmp_path / "b.npz", own, worker=False)
    try:
        assert classroom.agent.config.learner.unknown_below == 0.5     # the config's word
        assert classroom.agent.config.learner.novelty_below == 0.8
    finally:
        classroom.close()
    classroom = build_classroom(tmp_path / "c.npz", small_config(), worker=False, protocol="paper")
    try:
        assert classroom.agent.config.learner.unknown_below == 0.0
    finally:
        classroom.close()


def test_teach_uses_the_interactive_protocol_unless_told_otherwise(tmp_path):
    from iloci.commands.teach import INTERACTIVE, command_config

    cfg = command_config(None, None)
    assert all(getattr(cfg.learner, k) == v for k, v in INTERACTIVE.items())
    toml = tmp_path / "c.toml"
    toml.write_text("[learner]\nconfirm_rewards = false\n")
    cfg = command_config(str(toml), None)
    assert cfg.learner.confirm_rewards is False and cfg.learner.novelty_below == 0.8
    assert command_config(None, None, "paper").learner.novelty_below == 0.0


def test_ctrl_c_says_what_it_waits_for_and_a_second_one_stops_without_tracebacks(tmp_path):
    """With a client holding a request open, Ctrl-C waited 16 s without a word, and a
    second Ctrl-C printed uvicorn's CancelledError tracebacks (a web-page audit)."""
    import re
    import signal
    import socket
    import subprocess
    import sys
    import time
    import urllib.request

    import tomli_w

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    cfg = tmp_path / "small.toml"
    cfg.write_text(tomli_w.dumps(small_config()))
    proc = subprocess.Popen([sys.executable, "-m", "iloci", "serve", "--memory",
                             str(tmp_path / "m.npz"), "--port", str(port), "--config", str(cfg)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        page = ""
        for _ in range(240):
            try:
                page = urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=1).read()
                break
            except OSError:
                time.sleep(0.25)
        token = re.search(rb'name="iloci-token" content="([^"]+)"', page).group(1).decode()
        held = socket.create_connection(("127.0.0.1", port))
        held.sendall(f"POST /api/recognize HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                     f"Content-Type: application/json\r\n{TOKEN_HEADER}: {token}\r\n"
                     "Content-Length: 1000\r\n\r\n{".encode())
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)                      # stop at once
        _, err = proc.communicate(timeout=30)
        held.close()
    finally:
        proc.kill()
    assert "stopping: finishing the 1 request(s) under way" in err, err
    assert "Traceback" not in err and "CancelledError" not in err, err


def test_two_tabs_drawings_waiting_at_once_get_two_names(served, lasa):
    """Both were named drawing/9 (numbered by the drawings learned so far), so the entries'
    sources could not tell them apart."""
    client, classroom, _ = served
    client.post("/api/observe", json={"points": stroke(lasa["GShape/0"]), "client": "a"})
    client.post("/api/observe", json={"points": stroke(lasa["Angle/0"]), "client": "a"})
    client.post("/api/observe", json={"points": stroke(lasa["Angle/1"]), "client": "b"})
    keys = [t.demo.key for t in classroom.turns.values()]
    assert len(keys) == 2 and len(set(keys)) == 2, keys


def test_a_body_too_large_says_what_to_do():
    """A 413 said only "request body over 524288 bytes" (a web-page audit)."""
    from iloci.web.schemas import MAX_MEMORY_BYTES, _too_big

    assert str(_too_big(MAX_MEMORY_BYTES)) == (
        "the request body is over 67,108,864 bytes: a memory file is imported up to 64 MiB; "
        "one this large was not written by iloci.")
