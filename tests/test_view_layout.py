"""The viewer's geometry at 1400×900 in a real browser (issue #26): after "fit" every
drawn node's box lies inside the tree's pane and every label is at least 11 px; search
jumps to a node and its Gantt row; a story episode is a link to its moment (the URL
follows); two panes share the moment (``#t=`` moves both) and use the width. The
kitting tree (79 nodes), Nav2's NavigateToPose and a ~300-node tree are drawn, and
their screenshots written (``BTLOG_ARTIFACTS=docs/screenshots`` refreshes docs/'s)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.test_view_browser import screenshot
from tests.view_support import (
    CHROMIUM,
    CHUCK,
    RECORDINGS,
    ROOT,
    Served,
    btlog,
    copy_recording,
    launched_chromium,
    wide_recording,
)

pytestmark = pytest.mark.skipif(not CHROMIUM.exists(), reason="chromium is not installed")
GEOMETRY = """pane => {
  const root = document.querySelector(`.pane[data-run="${pane}"] .graphbox`);
  const box = root.getBoundingClientRect();
  const nodes = [...root.querySelectorAll("g.node:not(.absent)")].map((g) => {
    const r = g.querySelector("rect.box").getBoundingClientRect();
    return [r.left - box.left, r.top - box.top, r.right - box.left, r.bottom - box.top];
  });
  const labels = [...root.querySelectorAll("g.node:not(.absent) text.name, " +
    "g.node:not(.absent) text.type")].map((t) =>   // the font size as drawn on the screen
    parseFloat(getComputedStyle(t).fontSize) * t.getScreenCTM().a);
  return { width: box.width, height: box.height, nodes, labels };
}"""


@pytest.fixture(scope="module")
def browser() -> Iterator:
    yield from launched_chromium()


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("layout")
    nav = folder / "nav.mcap"
    done = btlog(
        "run", str(ROOT / "trees/nav2/navigate_to_pose.xml"),
        "--outcomes", str(ROOT / "trees/nav2/follow-path-fails-once.yaml"),
        "--nodes-model", str(ROOT / "trees/nav2/nodes_model.xml"), "-o", str(nav), "--quiet",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return {"kitting": copy_recording(CHUCK, folder), "nav2": nav, "wide": wide_recording(folder)}


@pytest.fixture
def page(browser) -> Iterator:
    context = browser.new_context(viewport={"width": 1400, "height": 900})
    opened = context.new_page()
    errors: list[str] = []
    opened.on("pageerror", lambda error: errors.append(str(error)))
    yield opened
    context.close()
    assert not errors


def opened(page, url: str) -> None:
    page.goto(url)
    page.wait_for_selector(".pane[data-ready='1']", timeout=30000)
    page.wait_for_function("() => document.querySelector('#app').dataset.loaded === '1'")


@pytest.mark.parametrize(("name", "link"), [("kitting", "#t=10.4s"), ("nav2", "#t=2.2s")])
def test_fit_shows_the_tree_inside_the_pane_with_readable_labels(
    page, recordings: dict[str, Path], name: str, link: str
) -> None:
    server = Served(recordings[name])
    try:
        opened(page, server.url + link)
        shape = page.evaluate(GEOMETRY, 0)
        assert shape["width"] > 900  # the tree takes most of 1400 px
        assert len(shape["nodes"]) >= 3
        for left, top, right, bottom in shape["nodes"]:
            assert left >= 0 and top >= 0, (name, left, top)
            assert right <= shape["width"] and bottom <= shape["height"], (name, right, bottom)
        assert min(shape["labels"]) >= 11, name
        screenshot(page, f"viewer-{name}.png")
        page.click("text=fit")  # the button gives the same
        assert page.evaluate(GEOMETRY, 0)["nodes"] == shape["nodes"]
    finally:
        server.stop()


def test_a_fan_out_too_wide_to_read_keeps_the_current_node_in_view_with_an_overview(
    page, recordings: dict[str, Path]
) -> None:
    """16 stages side by side do not fit 11 px labels into 980 px: the fit then keeps
    the readable zoom, centred on the (collapsed node holding the) current node, and the
    minimap shows the whole tree and the view."""
    server = Served(recordings["wide"])
    try:
        opened(page, server.url + "#t=20s")
        shape = page.evaluate(GEOMETRY, 0)
        assert min(shape["labels"]) >= 11
        holder = page.locator("g.node.current, g.node.holds-current").first
        box = holder.locator("rect.box").bounding_box()
        pane = page.locator(".graphbox").bounding_box()
        assert pane["x"] <= box["x"] and box["x"] + box["width"] <= pane["x"] + pane["width"]
        assert pane["y"] <= box["y"] and box["y"] + box["height"] <= pane["y"] + pane["height"]
        assert page.locator("canvas.minimap").is_visible()
        screenshot(page, "viewer-wide.png")
    finally:
        server.stop()


def test_search_jumps_to_the_node_and_its_gantt_row(page, recordings: dict[str, Path]) -> None:
    server = Served(recordings["wide"])
    try:
        opened(page, server.url + "#t=1s")
        page.fill("input[aria-label='find a node']", "check 12.3")
        page.press("input[aria-label='find a node']", "Enter")
        selected = page.locator("g.node.selected")
        assert selected.count() == 1
        uid = int(selected.get_attribute("data-uid"))
        box = page.locator(".graphbox").bounding_box()
        found = page.locator("g.node.selected rect.box").bounding_box()
        assert box["x"] <= found["x"] and found["x"] + found["width"] <= box["x"] + box["width"]
        assert box["y"] <= found["y"] and found["y"] + found["height"] <= box["y"] + box["height"]
        assert "check 12.3" in page.locator(".selection").inner_text()
        timeline = "() => window.btlogViewer.panes[0].timeline"
        row = page.evaluate(f"uid => ({timeline})().rowOf.get(uid)", uid)
        top = page.evaluate("() => document.querySelector('.timelinebox').scrollTop")
        height = page.evaluate("() => document.querySelector('.timelinebox').clientHeight")
        assert top <= row * 16 <= top + height - 16  # the row is in view
        assert page.evaluate(f"() => ({timeline})().found") == uid
        page.hover("g.node.selected")
        assert page.locator(".tip").inner_text().startswith("check 12.3")
    finally:
        server.stop()


def test_a_story_episode_links_to_its_moment(page, recordings: dict[str, Path]) -> None:
    server = Served(recordings["kitting"])
    try:
        opened(page, server.url)
        episode = page.locator(".story ol.episodes a").first
        assert episode.inner_text().startswith("10.400 s")
        assert "look at chuck failed" in page.locator(".story").inner_text()
        episode.click()
        page.wait_for_function("() => location.hash === '#seq=33'")
        assert page.locator(".pane").get_attribute("data-seq") == "33"
        page.locator(".story table.subgoals a").nth(1).click()  # go pick screw's start
        page.wait_for_function("() => location.hash === '#t=34s'")
        page.locator(".events div[data-seq]").first.click()
        page.wait_for_function("() => location.hash.startsWith('#seq=')")
        rows = page.evaluate(
            "() => [...document.querySelectorAll('.events div')].map(d => [d.scrollWidth, "
            "d.clientWidth])"
        )
        assert rows and all(scroll <= width for scroll, width in rows)  # nothing cut
    finally:
        server.stop()


def test_the_story_panel_counts_as_the_story_does(page, recordings: dict[str, Path]) -> None:
    """The panel is ``btlog explain``'s story: the same count of failures, the failures by
    design on their own line."""
    server = Served(recordings["nav2"])
    try:
        opened(page, server.url)
        panel = page.locator(".story").inner_text()
        told = btlog("explain", str(recordings["nav2"])).stdout.splitlines()
        assert told[1] == "Failures: 1." and told[1] in panel
        assert told[4].strip() == "(6 failures by design chose another branch.)"
        assert told[4].strip() in panel
    finally:
        server.stop()


def test_two_panes_share_the_moment_and_the_width(page, tmp_path: Path) -> None:
    a = copy_recording(RECORDINGS / "taxi-optimal.mcap", tmp_path)
    b = copy_recording(RECORDINGS / "taxi-human.mcap", tmp_path)
    server = Served(a, b)
    try:
        opened(page, server.url + "#t=5s")
        for pane in (0, 1):
            page.wait_for_selector(f'.pane[data-run="{pane}"][data-t-ns="5000000000"]')
        widths = [page.evaluate(GEOMETRY, pane)["width"] for pane in (0, 1)]
        assert min(widths) > 600  # each tree gets its pane's width
        page.evaluate("location.hash = '#t=2.5s'")
        for pane in (0, 1):
            page.wait_for_selector(f'.pane[data-run="{pane}"][data-t-ns="2500000000"]')
        page.locator('.pane[data-run="1"] .graphbox').click(position={"x": 5, "y": 5})
        page.keyboard.press("ArrowRight")  # run B one event on: run A follows its time
        page.wait_for_function("() => location.hash.startsWith('#b.seq=')")
        b_time = page.locator('.pane[data-run="1"]').get_attribute("data-t-ns")
        page.wait_for_selector(f'.pane[data-run="0"][data-t-ns="{b_time}"]')
        screenshot(page, "viewer-two-runs.png")
    finally:
        server.stop()
