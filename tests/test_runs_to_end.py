"""Every bundled tree and both of the paper's trees run to the end under their domain,
for seeds 1-20, with and without random failures (issue #11, item 1).

The 40 runs per tree go through ``btlog.cli.main.main`` in this process (the code path of
the ``btlog`` command, minus the interpreter start-up); a few real subprocess runs check
the installed command itself.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from btlog.cli.main import main

ROOT = Path(__file__).resolve().parent.parent
SEEDS = range(1, 21)
OWN_TREES = [
    *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "trees").glob("*.xml")),
    "tests/data/v3-gear-pair.xml",
    "tests/data/v3-delivery.xml",
]
PAPER_TREES = ["paper/kitting-tree.xml", "paper/taxi-domain-tree.xml"]


def domain_of(tree: Path) -> str:
    """The simulated domain a tree file is written for."""
    text = tree.read_text(encoding="utf-8")
    if "move right" in text or "taxi" in tree.name:
        return "taxi"
    if "convert to grasp pose" in text or "kitting" in tree.name:
        return "kitting"
    return "scripted"


def run_all_seeds(tree: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> list[str]:
    """Run ``tree`` for every seed, with and without --failure-rate 0.2; the problems."""
    problems = []
    domain = domain_of(tree)
    for rate in ("0", "0.2"):
        for seed in SEEDS:
            argv = ["run", str(tree), "--domain", domain, "--seed", str(seed)]
            argv += ["--failure-rate", rate, "-o", str(out / f"{seed}-{rate}.mcap")]
            code = main(argv)
            captured = capsys.readouterr()
            final = [line for line in captured.out.splitlines() if "final status:" in line]
            if code != 0 or not final or "stopped" in final[0] or captured.err:
                problems.append(f"seed {seed} rate {rate}: exit {code} {captured.err.strip()}")
    return problems


@pytest.mark.parametrize("tree_file", OWN_TREES + PAPER_TREES, indirect=True)
def test_every_tree_runs_to_the_end(
    tree_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert run_all_seeds(tree_file, tmp_path, capsys) == []


@pytest.mark.parametrize("tree_file", ["paper/kitting-tree.xml"], indirect=True)
def test_paper_kitting_tree_as_a_command(tree_file: Path, tmp_path: Path) -> None:
    """The installed command runs the paper's kitting tree (whose "convert to grasp pose"
    has no shift_z) to the end: the simulated skill uses the port's default."""
    for seed in (1, 7):
        argv = ["run", str(tree_file), "--domain", "kitting", "--seed", str(seed)]
        argv += ["--failure-rate", "0.2", "-o", str(tmp_path / "k.mcap")]
        result = subprocess.run(
            [sys.executable, "-m", "btlog.cli.main", *argv],
            env={**os.environ, "NO_COLOR": "1"},
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert result.returncode == 0, result.stderr
        assert result.stderr == ""
        assert "final status: SUCCESS" in result.stdout or "final status: FAILURE" in result.stdout
