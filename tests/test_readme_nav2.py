"""The README's Nav2 section, its commands copied verbatim from README.md and run as a
new user runs them (``bash`` in a fresh folder holding the project's ``trees/``): the
output block must be what ``explain`` prints, and nothing may warn. The placeholders of
the import commands (``my_bag/``, ``my_nav2_tree.xml``) are a bag exported from the
first commands' run and Nav2's default tree.

A one-goal import writes the file ``-o`` names (several goals: ``OUT-goalN.mcap``),
as the README says."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli_support import ROOT, btlog_environment

README = (ROOT / "README.md").read_text(encoding="utf-8")


def section_blocks(heading: str) -> list[tuple[str, str]]:
    """The fenced blocks (language, text) of the README section ``heading``, in order."""
    start = README.index(f"\n## {heading}\n")
    end = README.find("\n## ", start + 1)
    text = README[start : end if end > 0 else None]
    return re.findall(r"```(\w*)\n(.*?)```", text, re.S)


def run_block(block: str, folder: Path) -> subprocess.CompletedProcess:
    """The block's commands as a user's shell runs them (``btlog`` on the PATH)."""
    env = btlog_environment()
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    return subprocess.run(["bash", "-e", "-c", block], cwd=folder, env=env, capture_output=True,
                          text=True, check=False, timeout=600)  # fmt: skip


@pytest.fixture(scope="module")
def nav2(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess]:
    folder = tmp_path_factory.mktemp("readme-nav2")
    shutil.copytree(ROOT / "trees", folder / "trees")
    (language, commands), *_ = section_blocks("Nav2 trees")
    assert language == "sh" and "btlog run trees/nav2/navigate_to_pose.xml" in commands
    return folder, run_block(commands, folder)


def test_the_nav2_example_prints_what_the_readme_shows(nav2) -> None:
    _folder, done = nav2
    assert done.returncode == 0, done.stderr
    _commands, (language, shown), *_ = section_blocks("Nav2 trees")
    assert language == ""
    lines = done.stdout.splitlines()
    at = 0
    for line in shown.splitlines():  # the README's lines, in order, in explain's output
        at = lines.index(line, at) + 1
    assert any("ClearLocalCostmap-Context" in line and "2.000s" in line for line in lines)


def test_the_nav2_example_warns_about_nothing(nav2) -> None:
    _folder, done = nav2
    assert done.returncode == 0 and done.stderr == ""


def test_the_nav2_import_commands_run_as_written(nav2) -> None:
    folder, done = nav2
    assert done.returncode == 0, done.stderr
    (folder / "my_bag").mkdir()
    exported = run_block("btlog export nav.mcap --to nav2 my_bag/my_bag_0.mcap", folder)
    assert exported.returncode == 0, exported.stderr
    shutil.copy(ROOT / "trees" / "nav2" / "navigate_to_pose.xml", folder / "my_nav2_tree.xml")
    blocks = [text for _language, text in section_blocks("Nav2 trees")]
    (importing,) = [b for b in blocks if "btlog import my_bag/" in b]
    done = run_block(importing, folder)
    assert done.returncode == 0, done.stderr
    # at the end the recovery is over: what went wrong is told with its time
    said = "What went wrong?\n  At 2.000 s: I could not follow path because follow path failed."
    assert said in done.stdout
    assert done.stderr == ""
    assert (folder / "robot.mcap").exists() and (folder / "robot-ros.mcap").exists()
