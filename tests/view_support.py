"""Shared pieces of the viewer's tests: recordings made for real, a served viewer."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDINGS = ROOT / "recordings"
CHUCK = RECORDINGS / "kitting-look-at-chuck-fails.mcap"
ARTIFACTS = Path(os.environ.get("BTLOG_ARTIFACTS", ROOT / "tmp" / "artifacts"))
#: Debian's chromium, which Playwright drives (``playwright install`` is never needed).
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def launched_chromium() -> Iterator:
    """A headless chromium driven by Playwright, closed when the generator ends (the
    body of the browser tests' ``browser`` fixture)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        launched = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield launched
        launched.close()


#: A tree whose names and values try to be markup.
HOSTILE_TREE = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence name="&lt;script&gt;alert(2)&lt;/script&gt;">
      <AlwaysSuccess name="&lt;img src=x onerror=alert(1)&gt;"/>
      <SetBlackboard output_key="&lt;b&gt;key"
                     value="&lt;/script&gt;&lt;img src=x onerror=alert(3)&gt;"/>
    </Sequence>
  </BehaviorTree>
</root>
"""
HOSTILE_NAME = "<img src=x onerror=alert(1)>"


def copy_recording(source: Path, folder: Path) -> Path:
    """A copy of a committed recording (its read-model cache is built beside the copy)."""
    target = folder / source.name
    shutil.copyfile(source, target)
    return target


def btlog(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """The real command line, in a subprocess."""
    return subprocess.run(
        [sys.executable, "-m", "btlog.cli.main", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )


def hostile_recording(folder: Path) -> Path:
    """A run of HOSTILE_TREE, recorded by ``btlog run``."""
    tree = folder / "hostile.xml"
    tree.write_text(HOSTILE_TREE, encoding="utf-8")
    output = folder / "hostile.mcap"
    done = btlog("run", str(tree), "-o", str(output), "--quiet")
    assert done.returncode == 0, done.stderr
    return output


class Served:
    """``btlog view ... --no-browser`` running in a subprocess; ``url`` is what it printed."""

    def __init__(self, *recordings: Path) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "btlog.cli.main", "view", *map(str, recordings), "--no-browser"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        line = self.process.stdout.readline() if self.process.stdout else ""
        if not line.startswith("btlog view: http://127.0.0.1:"):
            self.stop()
            raise RuntimeError(f"btlog view did not start: {line!r}")
        self.url = line.split()[2]

    def stop(self) -> None:
        """Stop the server this test started."""
        self.process.terminate()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
        for stream in (self.process.stdout, self.process.stderr):
            if stream:
                stream.close()


def wide_tree_xml(stages: int = 16, steps: int = 4) -> str:
    """A tree of about 300 nodes (at the defaults: 1 + 16 × (3 + 4 × 4) = 305): a
    Sequence of stages, each a Fallback of a Sequence of steps — every step a Sequence
    of three actions — and a recovery."""
    lines = ['<root BTCPP_format="4" main_tree_to_execute="Main">', '<BehaviorTree ID="Main">',
             '<Sequence name="run the line">']  # fmt: skip
    for stage in range(1, stages + 1):
        lines.append(f'<Fallback name="stage {stage}"><Sequence name="do stage {stage}">')
        for step in range(1, steps + 1):
            lines.append(f'<Sequence name="step {stage}.{step}">')
            for verb in ("move", "grip", "check"):
                lines.append(f'<Action ID="{verb}" name="{verb} {stage}.{step}"/>')
            lines.append("</Sequence>")
        lines.append(f'</Sequence><Action ID="recover" name="recover stage {stage}"/></Fallback>')
    lines += ["</Sequence>", "</BehaviorTree>", "</root>"]
    return "\n".join(lines) + "\n"


def wide_recording(folder: Path) -> Path:
    """A run of ``wide_tree_xml()`` in which one check fails once."""
    tree = folder / "wide.xml"
    tree.write_text(wide_tree_xml(), encoding="utf-8")
    output = folder / "wide.mcap"
    outcomes = folder / "wide.yaml"
    outcomes.write_text("default: {status: SUCCESS, duration: 0.2}\n", encoding="utf-8")
    done = btlog("run", str(tree), "--outcomes", str(outcomes), "--fail", "check 7.2",
                 "-o", str(output), "--quiet")  # fmt: skip
    assert done.returncode == 0, done.stderr
    return output
