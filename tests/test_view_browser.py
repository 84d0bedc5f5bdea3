"""The viewer in a real browser: Playwright driving Debian's chromium.

Pages are opened at deep links and every node element's ``data-status`` is compared with
``state_at`` from the read model; the keyboard steps and the timeline scrubs; questions
get ``btlog ask``'s answers; the exported file opens from ``file://`` with the network
off; recorded markup stays text. Screenshots go to ``tmp/artifacts`` (``BTLOG_ARTIFACTS``).
Skipped only when chromium is not installed (CI installs it with apt).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from btlog.replay.database import RunDatabase, open_runs
from tests.view_support import (
    ARTIFACTS,
    CHROMIUM,
    CHUCK,
    HOSTILE_NAME,
    RECORDINGS,
    Served,
    btlog,
    copy_recording,
    hostile_recording,
    launched_chromium,
)

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(), reason="chromium is not installed (apt-get install -y chromium)"
)
STATUSES = """pane => Array.from(document.querySelectorAll(
    `.pane[data-run="${pane}"] g.node:not(.absent)`)).map(g => [Number(g.dataset.uid),
    g.dataset.status])"""


@pytest.fixture(scope="module")
def browser() -> Iterator:
    yield from launched_chromium()


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("view-browser")


@pytest.fixture(scope="module")
def chuck(folder: Path) -> Path:
    return copy_recording(CHUCK, folder)


@pytest.fixture(scope="module")
def database(chuck: Path) -> Iterator[RunDatabase]:
    with open_runs(chuck) as opened:
        yield opened


@pytest.fixture(scope="module")
def served(chuck: Path, database: RunDatabase) -> Iterator[Served]:
    server = Served(chuck)
    yield server
    server.stop()


@pytest.fixture
def page(browser) -> Iterator:
    context = browser.new_context(viewport={"width": 1400, "height": 900})
    opened = context.new_page()
    opened.dialogs = []  # type: ignore[attr-defined]
    opened.on("dialog", lambda dialog: (opened.dialogs.append(dialog.message), dialog.dismiss()))
    opened.errors = []  # type: ignore[attr-defined]
    opened.on("pageerror", lambda error: opened.errors.append(str(error)))
    yield opened
    context.close()
    assert not opened.errors


def at_count(page, count: int, pane: int = 0) -> None:
    page.wait_for_selector(f'.pane[data-run="{pane}"][data-count="{count}"]', timeout=15000)


def expected_statuses(database: RunDatabase, count: int, run: int = 0) -> list[list]:
    tree, state = database.runs and database.run(database.runs[run].run_id).state_after(count)
    return sorted([n.uid, state.status_of(n.uid).name] for n in tree)


def shown_statuses(page, pane: int = 0) -> list[list]:
    """Every node's drawn status (subtrees expanded first: fit collapses some)."""
    page.evaluate("pane => window.btlogViewer.panes[pane].graph.expandAll()", pane)
    return sorted(page.evaluate(STATUSES, pane))


def screenshot(page, name: str) -> None:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / name))


def test_deep_links_show_the_read_models_statuses(page, served, database) -> None:
    run = database.run()
    page.goto(served.url + "#seq=40")
    for link, moment in [
        ("#seq=40", "seq:40"),
        ("#tick=300", "tick:300"),
        ("#t=10.4s", "10.4s"),
        ("#t=30s", "30s"),
        ("#seq=0", "seq:0"),
        ("#seq=255", "seq:255"),
    ]:
        page.evaluate("link => { location.hash = link; }", link)
        resolved = run.resolve(moment)
        at_count(page, resolved.count)
        assert shown_statuses(page) == expected_statuses(database, resolved.count), link
        assert page.evaluate("location.hash") == link
        pane = page.locator(".pane")
        assert int(pane.get_attribute("data-tick")) == resolved.tick, link
        assert int(pane.get_attribute("data-t-ns")) == resolved.t_ns, link
    page.evaluate("location.hash = '#t=10.4s'")
    at_count(page, run.resolve("10.4s").count)
    failed = page.locator('g.node[data-status="FAILURE"]').count()
    assert failed >= 1
    screenshot(page, "view-chuck-fails-at-10.4s.png")


def test_the_keyboard_steps_by_event_and_by_tick(page, served, database) -> None:
    run = database.run()
    ticks = [entry.tick for entry in run.timeline()]
    page.goto(served.url + "#seq=40")
    at_count(page, 41)
    page.keyboard.press("ArrowRight")
    at_count(page, 42)
    page.keyboard.press("ArrowLeft")
    page.keyboard.press("ArrowLeft")
    at_count(page, 40)
    page.keyboard.press("Shift+ArrowRight")  # the end of the next tick, events or not
    tick = run.resolve("seq:39").tick + 1
    after = run.resolve(f"tick:{tick}")
    page.wait_for_selector(f'.pane[data-tick="{tick}"]')
    at_count(page, after.count)
    assert shown_statuses(page) == expected_statuses(database, after.count)
    page.keyboard.press("Shift+ArrowRight")
    page.wait_for_selector(f'.pane[data-tick="{tick + 1}"]')
    page.keyboard.press("Shift+ArrowLeft")
    page.wait_for_selector(f'.pane[data-tick="{tick}"]')
    assert page.evaluate("location.hash") == f"#tick={tick}"
    assert ticks[after.count - 1] <= tick


def test_collapse_zoom_and_play_at_10x(page, served, database) -> None:
    page.goto(served.url + "#seq=-1")
    at_count(page, 0)
    page.click("text=expand all")
    toggle = page.locator('g.node[data-uid="2"] > g.toggle')
    toggle.dispatch_event("click")
    hidden = page.locator("g.node.absent").count()
    below = len(list(database.run().tree.node(2).walk())) - 1
    assert hidden == below > 0
    toggle.dispatch_event("click")
    assert page.locator("g.node.absent").count() == 0
    scale = "() => document.querySelector('g.viewport').getAttribute('transform')"
    before = page.evaluate(scale)
    page.mouse.move(400, 300)
    page.mouse.wheel(0, -400)
    page.wait_for_function(f"before => ({scale})() !== before", arg=before)
    zoom = [float(x) for x in re.findall(r"scale\(([0-9.]+)\)", page.evaluate(scale) + before)]
    assert zoom[0] > zoom[1]
    page.select_option('select[aria-label="speed"]', "10")
    page.keyboard.press(" ")
    page.wait_for_timeout(1000)
    page.keyboard.press(" ")
    page.wait_for_function("() => !window.btlogViewer.playing && !window.btlogViewer.focused.busy")
    count = int(page.locator(".pane").get_attribute("data-count"))
    t_ns = database.run().state_after(count)[1].t_ns
    assert 4e9 < t_ns < 20e9  # about 1 s of the wall clock at 10x
    assert shown_statuses(page) == expected_statuses(database, count)


def test_the_timeline_zooms_and_its_labels_select(page, served, database) -> None:
    page.goto(served.url + "#t=10.4s")
    at_count(page, database.run().resolve("10.4s").count)
    box = page.locator(".timelinebox canvas").bounding_box()
    span = "() => { const t = window.btlogViewer.panes[0].timeline; return t.hi - t.lo; }"
    whole = page.evaluate(span)
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + 40)
    page.mouse.wheel(0, -600)
    page.wait_for_function(f"whole => ({span})() < whole / 2", arg=whole)
    page.wait_for_function("() => window.btlogViewer.panes[0].timeline.segments !== null")
    (uid,) = [n.uid for n in database.run().tree if n.name == "look at chuck"]
    row = page.evaluate(f"() => window.btlogViewer.panes[0].timeline.rowOf.get({uid})")
    page.evaluate(f"() => window.btlogViewer.panes[0].timeline.scrollToRow({row}, true)")
    scroll = page.evaluate("() => document.querySelector('.timelinebox').scrollTop")
    page.mouse.click(box["x"] + 20, box["y"] + 20 + 16 * row - scroll + 8)  # its label
    assert page.locator("g.node.selected").get_attribute("data-uid") == str(uid)
    assert "look at chuck" in page.locator(".selection").inner_text()
    screenshot(page, "view-timeline-zoomed.png")


def test_dragging_the_timeline_scrubs(page, served, database) -> None:
    page.goto(served.url + "#seq=-1")
    at_count(page, 0)
    box = page.locator(".timelinebox canvas").bounding_box()
    y = box["y"] + 30
    page.mouse.move(box["x"] + 170 + (box["width"] - 180) * 0.2, y)
    page.mouse.down()
    page.mouse.move(box["x"] + 170 + (box["width"] - 180) * 0.6, y, steps=8)
    page.mouse.up()
    page.wait_for_function(
        "() => document.querySelector('.pane').dataset.count > 100 && "
        "location.hash.startsWith('#t=')"
    )
    page.wait_for_timeout(300)  # the last request of the drag
    count = int(page.locator(".pane").get_attribute("data-count"))
    duration = database.run().info.duration_ns
    t_ns = int(page.locator(".pane").get_attribute("data-t-ns"))
    assert 0.55 * duration < t_ns <= 0.62 * duration
    assert count == database.run().resolve(f"{t_ns}ns").count
    assert shown_statuses(page) == expected_statuses(database, count)
    screenshot(page, "view-scrubbed.png")


def test_the_ask_box_gives_btlog_asks_answers(page, served, chuck) -> None:
    page.goto(served.url + "#t=10.4s")
    page.wait_for_selector(".pane[data-ready='1']")
    for question in ("What went wrong?", "Can you look at chuck?"):
        page.fill(".ask input", question)
        page.press(".ask input", "Enter")
        cli = btlog("ask", str(chuck), "--at", "10.4s", question)
        expected = cli.stdout.splitlines()[0]
        page.wait_for_function(
            "text => document.querySelector('.askanswer').textContent === text", arg=expected
        )
    answers = page.locator(".answers dd").all_inner_texts()
    assert "I could not insert large gear because look at chuck failed." in " ".join(answers)


def test_the_export_opens_offline_from_a_file(browser, chuck, database, folder) -> None:
    exported = folder / "chuck.html"
    done = btlog("view", str(chuck), "--export", str(exported))
    assert done.returncode == 0, done.stderr
    context = browser.new_context(offline=True, viewport={"width": 1500, "height": 900})
    requests: list[str] = []
    context.on("request", lambda request: requests.append(request.url))
    page = context.new_page()
    try:
        run = database.run()
        for moment, link in [("30s", "#t=30s"), ("tick:300", "#tick=300"), ("seq:40", "#seq=40")]:
            page.goto(exported.as_uri() + link)
            count = run.resolve(moment).count
            at_count(page, count)
            assert shown_statuses(page) == expected_statuses(database, count), link
        page.keyboard.press("Shift+ArrowLeft")
        page.fill(".ask input", "What went wrong?")
        page.press(".ask input", "Enter")
        page.wait_for_function("() => document.querySelector('.askanswer').textContent")
        seq = int(page.locator(".pane").get_attribute("data-seq"))
        cli = btlog("ask", str(chuck), "--at", f"seq:{seq}", "What went wrong?")
        assert page.locator(".askanswer").inner_text() == cli.stdout.splitlines()[0]
        page.fill(".ask input", "Why did look at chuck fail?")
        page.press(".ask input", "Enter")
        page.wait_for_function(
            "() => document.querySelector('.askanswer').textContent.includes('offline')"
        )
        offline = page.locator(".askanswer").inner_text()
        assert "cannot answer that offline" in offline
        assert f"btlog ask {chuck} --at seq:{seq}" in offline
        screenshot(page, "export-offline.png")
    finally:
        context.close()
    assert requests and all(url.startswith("file://") for url in requests), requests


def test_recorded_markup_is_shown_as_text(page, folder) -> None:
    recording = hostile_recording(folder)
    exported = folder / "hostile.html"
    assert btlog("view", str(recording), "--export", str(exported)).returncode == 0
    server = Served(recording)
    try:
        for url in (exported.as_uri(), server.url):
            page.goto(url)
            page.wait_for_selector(".pane[data-ready='1']")
            page.click("g.node[data-uid='2']")
            assert page.locator("img").count() == 0
            assert page.locator("script:not([type]):not([src])").count() in (0, 5)
            page.hover("g.node[data-uid='2']")
            assert HOSTILE_NAME in page.locator(".tip").inner_text()
            assert HOSTILE_NAME in page.locator(".selection").inner_text()
            board = page.locator(".blackboard").inner_text()
            assert "</script><img src=x onerror=alert(3)>" in board
        assert page.dialogs == []
        screenshot(page, "view-hostile-names.png")
    finally:
        server.stop()


def test_two_runs_side_by_side_aligned_as_diff(page, folder) -> None:
    a = copy_recording(RECORDINGS / "taxi-optimal.mcap", folder)
    b = copy_recording(RECORDINGS / "taxi-human.mcap", folder)
    diff = btlog("diff", str(a), str(b), "--json")
    subgoals = json.loads(diff.stdout)["subgoals"]
    server = Served(a, b)
    try:
        page.goto(server.url + "#seq=10&b.seq=5")  # a moment each: not linked
        at_count(page, 11, 0)
        at_count(page, 6, 1)
        rows = page.locator(".diff tr.row")
        assert rows.count() == sum(len(s["rows"]) for s in subgoals)
        divergent = [r for s in subgoals for r in s["rows"] if r["op"] != "equal"]
        assert page.locator(".diff tr.row.divergent").count() == len(divergent)
        assert page.locator("g.node.divergent").count() >= 1
        first = next(i for s in subgoals for i, r in enumerate(s["rows"]) if r["a"] and r["b"])
        row = next(r for s in subgoals for r in s["rows"] if r["a"] and r["b"])
        rows.nth(first).click()
        at_count(page, row["a"]["seq"] + 1, 0)
        at_count(page, row["b"]["seq"] + 1, 1)
        assert page.evaluate("location.hash") == f"#seq={row['a']['seq']}&b.seq={row['b']['seq']}"
        screenshot(page, "view-two-runs.png")
    finally:
        server.stop()


def test_the_export_resolves_moments_as_btlog_does(browser, chuck, database, folder) -> None:
    """The exported page resolves moments in the browser (api.js): the same seq, tick
    and time as ``btlog.replay.moments`` for every form a deep link takes."""
    exported = folder / "moments.html"
    assert btlog("view", str(chuck), "--export", str(exported)).returncode == 0
    context = browser.new_context(offline=True, viewport={"width": 1400, "height": 900})
    page = context.new_page()
    run = database.run()
    try:
        links = [("seq", "40"), ("tick", "300"), ("t", "12s"), ("t", "10.4s"), ("t", "-2s"),
                 ("t", "1500ms"), ("tick", "0"), ("t", "29.95")]  # fmt: skip
        for kind, value in links:
            moment = run.resolve(f"{kind}:{value}" if kind != "t" else value)
            page.goto(f"{exported.as_uri()}#{kind}={value}")
            at_count(page, moment.count)
            pane = page.locator(".pane")
            shown = [pane.get_attribute(k) for k in ("data-seq", "data-tick", "data-t-ns")]
            seq = -1 if moment.seq is None else moment.seq
            assert shown == [str(seq), str(moment.tick), str(moment.t_ns)], (kind, value)
    finally:
        context.close()
