"""The viewer without a browser: its JSON against the read model, the server's rules, the
exported file's escaping, and the CLI (``view --export``, ``check --html``)."""

from __future__ import annotations

import json
import re
import threading
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from btlog.explain.questions import answer, explain
from btlog.replay.database import open_runs
from btlog.view.export import ExportTooLarge, export_data
from btlog.view.model import RunView
from btlog.view.page import embed_json
from btlog.view.server import ViewerApp, serve
from tests.view_support import CHUCK, HOSTILE_NAME, btlog, copy_recording, hostile_recording


@pytest.fixture(scope="module")
def chuck(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return copy_recording(CHUCK, tmp_path_factory.mktemp("view"))


@pytest.fixture(scope="module")
def app(chuck: Path):
    database = open_runs(chuck)
    yield ViewerApp([RunView(database, database.run(), "chuck")])
    database.close()


@pytest.mark.parametrize("count", [0, 1, 40, 41, 150, 256])
def test_the_state_json_is_the_read_models_state(app: ViewerApp, count: int) -> None:
    run = app.views[0].run
    tree, state = run.state_after(count)
    shown = app.api("/api/run/0/state", {"count": str(count)})
    assert shown["count"] == count
    statuses = {int(uid): status for uid, status in shown["status"].items()}
    assert statuses == {u: s.name for u, s in state.status.items() if s.name != "IDLE"}
    assert shown["present"] == sorted(tree.nodes)
    answers = explain(tree, state, run.history())
    assert [a["answer"] for a in shown["answers"]] == [a.text for a in answers]
    values = {(e["scope"], e["key"]): e["value"] for e in shown["blackboard"]}
    assert values == {(s, k): v for s, e in state.blackboard.items() for k, v in e.items()}


def test_every_blackboard_entry_names_its_writer(app: ViewerApp) -> None:
    entries = app.api("/api/run/0/state", {"count": "256"})["blackboard"]
    assert entries, "the kitting run writes poses"
    nodes = app.views[0].tree.nodes
    for entry in entries:
        assert entry["writer"] in nodes and 0 <= entry["seq"] < 256


def test_questions_get_btlog_asks_answers_with_the_runs_history(app: ViewerApp) -> None:
    run = app.views[0].run
    moment = run.resolve("seq:40")
    tree, state = run.state_after(41)
    for question in (
        "What went wrong?",
        "Can you look at chuck?",
        "why?",
        "When did look at chuck last fail?",
        "Why did insert large gear fail?",
    ):
        shown = app.api("/api/run/0/ask", {"count": "41", "q": question})
        expected = answer(tree, state, question, run.history(), moment.t_ns).text
        assert shown["answer"] == expected
    assert (
        app.api("/api/run/0/ask", {"count": "41", "q": "When did look at chuck last fail?"})[
            "answer"
        ]
        == "look at chuck last failed at 10.400 s."
    )
    unknown = app.api("/api/run/0/ask", {"count": "41", "q": "Sing"})
    assert unknown["answer"].startswith('Sorry. I don\'t understand "Sing"')


def test_a_tick_step_goes_to_the_end_of_the_next_tick_with_or_without_events(
    app: ViewerApp,
) -> None:
    view = app.views[0]
    run = view.run
    for at in ("tick:0", "seq:40", "tick:290", "10.45s"):
        moment = run.resolve(at)
        forward = app.api("/api/run/0/step", {"at": at, "dir": "1"})
        assert forward == run.resolve(f"tick:{moment.tick + 1}").to_json()
        back = app.api("/api/run/0/step", {"at": at, "dir": "-1"})
        assert back["tick"] == max(0, moment.tick - 1)
    quiet = app.api("/api/run/0/step", {"at": "tick:290", "dir": "1"})
    assert quiet["tick"] == 291 and quiet["count"] == run.resolve("tick:290").count


def test_the_state_names_its_moment_as_every_command_does(app: ViewerApp) -> None:
    run = app.views[0].run
    for at in ("tick:300", "12s", "seq:40", "end", "-2s"):
        shown = app.api("/api/run/0/state", {"at": at})
        assert shown["moment"] == run.resolve(at).to_json()
    by_time = app.api("/api/run/0/state", {"t_ns": "12000000000"})["moment"]
    assert (by_time["seq"], by_time["tick"], by_time["t_ns"]) == (40, 121, 12_000_000_000)
    assert by_time["last_event_t_ns"] == 10_400_000_000


def test_the_story_is_btlog_explains(app: ViewerApp, chuck: Path) -> None:
    told = json.loads(btlog("explain", str(chuck), "--json").stdout)
    told.pop("notes")
    assert app.api("/api/runs", {})["runs"][0]["story"] == told


def test_deep_link_forms_resolve_like_moments(app: ViewerApp) -> None:
    run = app.views[0].run
    for at in ("seq:40", "tick:300", "30s", "10.4s", "end"):
        assert app.api("/api/run/0/resolve", {"at": at}) == run.resolve(at).to_json()
    assert app.api("/api/run/0/resolve", {"at": "seq:-1"})["count"] == 0


def test_the_gantt_has_the_failure_of_look_at_chuck(app: ViewerApp) -> None:
    gantt = app.api("/api/run/0/gantt", {})
    (uid,) = [n.uid for n in app.views[0].tree if n.name == "look at chuck"]
    statuses = [s for u, s in zip(gantt["uid"], gantt["status"], strict=True) if u == uid]
    assert "FAILURE" in statuses and "RUNNING" in statuses
    assert all(a <= b for a, b in zip(gantt["start"], gantt["end"], strict=True))


def _get(url: str, host: str | None = None) -> tuple[int, bytes]:
    request = urllib.request.Request(url, headers={"Host": host} if host else {})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as error:
        return error.code, error.read()


def test_the_server_is_loopback_only_and_read_only(app: ViewerApp) -> None:
    server = serve(app)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        host, port = server.server_address[:2]
        assert host == "127.0.0.1"
        base = f"http://127.0.0.1:{port}"
        status, body = _get(base + "/api/runs")
        assert status == 200 and json.loads(body)["runs"][0]["events"] == 256
        assert _get(base + "/api/runs", host=f"attacker.example:{port}")[0] == 403
        assert _get(base + "/static/../model.py")[0] == 404
        assert _get(base + "/static/app.js")[0] == 200
        post = urllib.request.Request(base + "/api/runs", data=b"x", method="POST")
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(post, timeout=10)
        assert refused.value.code == 501
    finally:
        server.shutdown()
        server.server_close()


def test_embedded_json_cannot_close_its_script_element() -> None:
    text = embed_json({"name": "</script><img src=x onerror=alert(1)>", "a&b": "<!--"})
    assert "<" not in text and ">" not in text and "&" not in text
    assert json.loads(text)["name"] == "</script><img src=x onerror=alert(1)>"


def test_an_exported_page_holds_recorded_markup_as_data_only(tmp_path: Path) -> None:
    recording = hostile_recording(tmp_path)
    page = tmp_path / "hostile.html"
    done = btlog("view", str(recording), "--export", str(page))
    assert done.returncode == 0, done.stderr
    html = page.read_text(encoding="utf-8")
    assert "<img" not in html and "alert(" not in html.split('id="btlog-data">')[0]
    data = re.search(r'id="btlog-data">(.*?)</script>', html, re.S).group(1)
    names = [n["name"] for n in json.loads(data)["runs"][0]["meta"]["nodes"]]
    assert HOSTILE_NAME in names
    assert not re.search(r"<link|<script src|src=[\"']?http|url\(", html)


def test_a_run_too_large_to_export_says_to_use_view(app: ViewerApp) -> None:
    with pytest.raises(ExportTooLarge, match=r"256 events.*btlog view"):
        export_data(app.views, None, None, limit=100)


def test_view_of_a_missing_file_is_one_line_and_exit_2(tmp_path: Path) -> None:
    done = btlog("view", str(tmp_path / "missing.mcap"), "--export", str(tmp_path / "x.html"))
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "missing.mcap" in done.stderr


def test_check_html_writes_the_viewer_of_a_failing_check_only(tmp_path: Path) -> None:
    root = Path(__file__).resolve().parents[1]
    taxi = copy_recording(root / "recordings" / "taxi-optimal.mcap", tmp_path)
    report = tmp_path / "report.html"
    human = str(root / "trees" / "taxi-human.xml")
    failed = btlog("check", str(taxi), "--rerun", "--tree", human, "--html", str(report))
    assert failed.returncode == 1
    html = report.read_text(encoding="utf-8")
    assert '"identical":false' in html and "move right" in html and "FAIL" in html
    assert sorted(p.name for p in tmp_path.glob("*.mcap")) == ["taxi-optimal.mcap"]
    report.unlink()
    same = str(root / "trees" / "taxi.xml")
    passed = btlog("check", str(taxi), "--rerun", "--tree", same, "--html", str(report))
    assert passed.returncode == 0 and not report.exists()
