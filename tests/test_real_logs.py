"""Real logs, from a folder you gather (public repositories' test data, your robots'
logs; never committed): ``BTLOG_REAL_LOGS=DIR pytest tests/test_real_logs.py``.

- every ``*.fbl`` (BT.CPP 3 FileLogger) imports, and ``tests/fbl_support.py`` writes its
  header byte for byte from what btlog read of it (the writer is BT.CPP 3's);
- every rosbag2 bag (a folder with ``metadata.yaml``) imports with one of the tree XMLs
  nearest to it (those of the first folder up from the bag holding a ``*.xml`` with a
  ``<BehaviorTree>``; a model-only XML there is the nodes model), or is refused in one
  line naming it (no ``/behavior_tree_log``, or no tree there fits: put the tree that
  ran beside the bag).

The counts are printed (``-s``)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.cli_support import btlog
from tests.fbl_support import header, read_header

REAL = os.environ.get("BTLOG_REAL_LOGS")
pytestmark = pytest.mark.skipif(not REAL, reason="set BTLOG_REAL_LOGS=DIR to import real logs")


def test_real_fbl_files_import_and_the_writer_is_byte_exact(tmp_path: Path) -> None:
    files = sorted(Path(str(REAL)).rglob("*.fbl"))
    for file in files:
        result = btlog("import", str(file), "-o", str(tmp_path / f"{file.stem}.mcap"))
        assert result.returncode == 0, result.stderr
        data = file.read_bytes()
        size = int.from_bytes(data[:4], "little")
        assert header(*read_header(data[4 : 4 + size])) == data[4 : 4 + size], file
    print(f"\n{len(files)} .fbl files imported, each header written again byte for byte")


def _nearest_trees(bag: Path, top: Path) -> tuple[list[Path], Path | None]:
    """The tree XMLs and the nodes model nearest above ``bag`` (within ``top``): those of
    the first folder up from the bag that holds a tree."""
    folder = bag.parent
    while top in (folder, *folder.parents):
        trees, models = [], []
        for xml in sorted(folder.rglob("*.xml")):
            text = xml.read_text(errors="replace")
            (trees if "<BehaviorTree" in text else models).append(xml)
        if trees:
            model = next((m for m in models if "<TreeNodesModel" in m.read_text()), None)
            return trees, model
        folder = folder.parent
    return [], None


def test_real_rosbag2_bags_import_or_are_refused_in_one_line(tmp_path: Path) -> None:
    """Each bag is imported with each of its nearest trees until one fits; a bag no tree
    fits (or with no behavior tree log) is refused in one line naming it."""
    top = Path(str(REAL)).resolve()
    bags = sorted(p.parent for p in top.rglob("metadata.yaml"))
    imported = no_log = no_tree = 0
    for index, bag in enumerate(bags):
        trees, model = _nearest_trees(bag, top)
        for tree in trees or [None]:
            args = ["import", str(bag), "-o", str(tmp_path / f"bag{index}.mcap")]
            if tree is not None:
                args += ["--tree", str(tree)]
            if model is not None:
                args += ["--nodes-model", str(model)]
            result = btlog(*args)
            if result.returncode == 0:
                break
            assert result.returncode == 2, result.stderr
            lines = result.stderr.strip().splitlines()
            assert len(lines) == 1 and str(bag) in lines[0], result.stderr
            if "no /behavior_tree_log topic" in lines[0]:
                break
        imported += result.returncode == 0
        no_log += "no /behavior_tree_log topic" in result.stderr
        no_tree += result.returncode == 2 and "no /behavior_tree_log topic" not in result.stderr
    print(
        f"\n{len(bags)} bags: {imported} imported, {no_log} without a behavior tree log, "
        f"{no_tree} that no tree near them fits"
    )
