"""Hostile trees: each is generated here (small), refused with exit 2 and one line naming
the file within seconds, under a memory limit so that a regression fails instead of
taking the machine down."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest

from btlog import limits
from btlog.tree.loader import load_tree_text

ROOT = Path(__file__).resolve().parent.parent
MEMORY = 1536 * 1024 * 1024
SECONDS = 20


def _bounded_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))


def btlog(*args: str, cwd: Path, bounded: bool = True) -> tuple[subprocess.CompletedProcess, float]:
    """``btlog ARGS`` (under a memory limit unless it reads DuckDB, which reserves more
    address space); the result and its wall time."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "NO_COLOR": "1"}
    env.pop("BTLOG_DEBUG", None)
    started = time.monotonic()
    result = subprocess.run(
        [sys.executable, "-m", "btlog.cli.main", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=SECONDS * 3,
        check=False,
        preexec_fn=_bounded_memory if bounded else None,
    )
    return result, time.monotonic() - started


def refused(result: subprocess.CompletedProcess, seconds: float, *words: str) -> str:
    """Exit 2, one line on stderr holding ``words``, quickly; returns the line."""
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr[-2000:]
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert seconds < SECONDS, seconds
    return lines[0]


def tree(body: str, *extra: str) -> str:
    """A v4 document whose main tree is ``body``."""
    return (
        '<root BTCPP_format="4" main_tree_to_execute="Main">'
        f'<BehaviorTree ID="Main">{body}</BehaviorTree>{"".join(extra)}</root>'
    )


def subtree_bomb(levels: int) -> str:
    """Each tree calls the next twice: 2**levels nodes from a few KB."""
    trees = [
        f'<BehaviorTree ID="T{i}"><Sequence><SubTree ID="T{i + 1}"/>'
        f'<SubTree ID="T{i + 1}"/></Sequence></BehaviorTree>'
        for i in range(levels)
    ]
    trees.append(f'<BehaviorTree ID="T{levels}"><AlwaysSuccess/></BehaviorTree>')
    return tree('<SubTree ID="T0"/>', *trees)


def test_subtree_bomb_is_refused_before_expanding(tmp_path: Path) -> None:
    bomb = tmp_path / "bomb.xml"
    bomb.write_text(subtree_bomb(30))
    assert bomb.stat().st_size < 4000
    result, seconds = btlog("validate", str(bomb), cwd=tmp_path)
    refused(result, seconds, "bomb.xml:", f"more than {limits.MAX_NODES} nodes", "--max-nodes")
    result, seconds = btlog("run", str(bomb), "-o", "r.mcap", cwd=tmp_path)
    refused(result, seconds, "bomb.xml:", "--max-nodes")
    assert not (tmp_path / "r.mcap").exists()


def test_max_nodes_flag_moves_the_bound(tmp_path: Path) -> None:
    small = tmp_path / "small.xml"
    small.write_text(subtree_bomb(6))  # 1 + 2**7 - 1 + 2**6 ... a few hundred nodes
    assert btlog("validate", str(small), cwd=tmp_path)[0].returncode == 0
    result, seconds = btlog("validate", str(small), "--max-nodes", "100", cwd=tmp_path)
    refused(result, seconds, "small.xml:", "more than 100 nodes")
    result, seconds = btlog("validate", str(small), "--max-nodes", "0", cwd=tmp_path)
    refused(result, seconds, "--max-nodes 0")


@pytest.mark.parametrize("where", ["argument", "include"])
def test_dev_zero_is_refused_at_once(tmp_path: Path, where: str) -> None:
    if where == "argument":
        target = "/dev/zero"
    else:
        target = str(tmp_path / "includes.xml")
        Path(target).write_text(tree("<AlwaysSuccess/>", '<include path="/dev/zero"/>'))
    result, seconds = btlog("validate", target, cwd=tmp_path)
    refused(result, seconds, "not a regular file")  # at once: well before the timeout


def test_fifo_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    fifo = tmp_path / "tree.xml"
    os.mkfifo(fifo)
    result, seconds = btlog("validate", str(fifo), cwd=tmp_path)
    refused(result, seconds, "tree.xml", "not a regular file")


def test_file_size_is_checked_before_reading(tmp_path: Path) -> None:
    big = tmp_path / "big.xml"
    with big.open("wb") as file:  # sparse: 10 GB on paper, nothing on disk
        file.truncate(10 * 1024**3)
    result, seconds = btlog("validate", str(big), cwd=tmp_path)
    refused(result, seconds, "big.xml", f"larger than {limits.MAX_FILE_BYTES} bytes")
    small = tmp_path / "small.xml"
    small.write_text(tree("<AlwaysSuccess/>"))
    result, seconds = btlog("validate", str(small), "--max-file-size", "50", cwd=tmp_path)
    refused(result, seconds, "small.xml", "larger than 50 bytes", "--max-file-size")
    outcomes = tmp_path / "outcomes.yaml"
    with outcomes.open("wb") as file:
        file.truncate(10 * 1024**3)
    result, seconds = btlog("run", str(small), "--outcomes", str(outcomes), cwd=tmp_path)
    refused(result, seconds, "outcomes.yaml", "larger than")


def test_many_attributes_on_one_element(tmp_path: Path) -> None:
    attributes = " ".join(f'_a{i}="x"' for i in range(100_000))
    path = tmp_path / "attributes.xml"
    path.write_text(tree(f"<AlwaysSuccess {attributes}/>"))
    result, seconds = btlog("validate", str(path), cwd=tmp_path)
    refused(result, seconds, "attributes.xml:1", f"more than {limits.MAX_ATTRIBUTES} attributes")


def test_deep_trees_are_refused_naming_the_file(tmp_path: Path) -> None:
    chain = [
        f'<BehaviorTree ID="T{i}">{"<Inverter>" * 9}<SubTree ID="T{i + 1}"/>'
        f"{'</Inverter>' * 9}</BehaviorTree>"
        for i in range(60)
    ]
    chain.append('<BehaviorTree ID="T60"><AlwaysSuccess/></BehaviorTree>')
    path = tmp_path / "deep.xml"
    path.write_text(tree('<SubTree ID="T0"/>', *chain))
    result, seconds = btlog("validate", str(path), cwd=tmp_path)
    refused(result, seconds, "deep.xml:1", f"deeper than {limits.MAX_DEPTH} levels")


def test_the_deepest_tree_allowed_runs_and_is_explained(tmp_path: Path) -> None:
    depth = limits.MAX_DEPTH
    path = tmp_path / "deep.xml"
    path.write_text(
        tree("<Inverter>" * depth + '<AlwaysFailure name="x"/>' + "</Inverter>" * depth)
    )
    result, _ = btlog("run", str(path), "-o", "deep.mcap", cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    result, _ = btlog("explain", "deep.mcap", "--at", "end", cwd=tmp_path, bounded=False)
    assert result.returncode == 0, result.stderr[-2000:]


@pytest.mark.parametrize(
    ("code", "words"),
    [
        ("v := &apos;ab&apos;; " + "; ".join(["v := v..v"] * 40), ["string longer than"]),
        ("v := 2; " + "; ".join(["v := v*v"] * 40), ["integer overflow"]),
    ],
    ids=["string doubling", "integer squaring"],
)
def test_scripts_are_bounded_while_running(tmp_path: Path, code: str, words: list[str]) -> None:
    path = tmp_path / "script.xml"
    path.write_text(tree(f'<Script code="{code}"/>'))
    result, seconds = btlog("run", str(path), "-o", "s.mcap", cwd=tmp_path)
    refused(result, seconds, "script.xml:1", *words)


def test_scripts_are_bounded_when_compiled(tmp_path: Path) -> None:
    nested = tmp_path / "nested.xml"
    nested.write_text(tree('<Script code="v := ' + "(" * 500 + "1" + ")" * 500 + '"/>'))
    result, seconds = btlog("validate", str(nested), cwd=tmp_path)
    refused(result, seconds, "nested.xml:1", "nested more than")
    long = tmp_path / "long.xml"
    long.write_text(tree('<Script code="v := ' + "+".join(["1"] * 40_000) + '"/>'))
    result, seconds = btlog("validate", str(long), cwd=tmp_path)
    refused(result, seconds, "long.xml:1", "longer than")


def test_describing_many_siblings_is_linear() -> None:
    loaded = load_tree_text(tree("<Sequence>" + "<AlwaysSuccess/>" * 100_000 + "</Sequence>"))
    started = time.monotonic()
    records = loaded.describe()["nodes"]
    assert time.monotonic() - started < SECONDS  # quadratic would take hours
    assert [r["idx"] for r in records[1:4]] == [0, 1, 2]
    assert records[-1]["idx"] == 99_999


def test_yaml_alias_bombs_are_refused(tmp_path: Path) -> None:
    tree_file = tmp_path / "small.xml"
    tree_file.write_text(tree('<Action ID="Do" name="a"/>'))
    levels = ['a: &a ["SUCCESS", "SUCCESS", "SUCCESS", "SUCCESS", "SUCCESS", "SUCCESS"]']
    for index in range(1, 10):
        name, previous = "abcdefghij"[index], "abcdefghij"[index - 1]
        levels.append(f"{name}: &{name} [{', '.join([f'*{previous}'] * 6)}]")
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("\n".join([*levels, "nodes:", "  a: *j", ""]))
    assert bomb.stat().st_size < 1000
    result, seconds = btlog("run", tree_file.name, "--outcomes", bomb.name, cwd=tmp_path)
    refused(result, seconds, "bomb.yaml", f"more than {limits.MAX_DOCUMENT_VALUES} values")
    loop = tmp_path / "loop.yaml"
    loop.write_text("nodes:\n  a: &x [SUCCESS, *x]\n")
    result, seconds = btlog("run", tree_file.name, "--outcomes", loop.name, cwd=tmp_path)
    refused(result, seconds, "loop.yaml:2", "refers to itself")
