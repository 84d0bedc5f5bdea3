"""Real logs, from a folder you gather (public repositories' test data, your robots'
logs; never committed): ``BTLOG_REAL_LOGS=DIR pytest tests/test_real_logs.py``.

- every ``*.fbl`` (BT.CPP 3 FileLogger) imports, and ``tests/fbl_support.py`` writes its
  header byte for byte from what btlog read of it (the writer is BT.CPP 3's);
- every rosbag2 bag (a folder with ``metadata.yaml``) imports when it has Nav2's
  ``/behavior_tree_log``, with the tree XML found nearest to it (the first folder up from
  the bag holding a ``*.xml`` with a ``<BehaviorTree>``; a model-only XML there is the
  nodes model), and is refused in one line naming the file when it has no such topic.

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


def _nearest_tree(bag: Path, top: Path) -> tuple[Path | None, Path | None]:
    """The tree XML and nodes model nearest above ``bag`` (within ``top``)."""
    folder = bag.parent
    while top in (folder, *folder.parents):
        trees, models = [], []
        for xml in sorted(folder.rglob("*.xml")):
            text = xml.read_text(errors="replace")
            (trees if "<BehaviorTree" in text else models).append(xml)
        if trees:
            model = next((m for m in models if "<TreeNodesModel" in m.read_text()), None)
            return trees[0], model
        folder = folder.parent
    return None, None


def test_real_rosbag2_bags_import_or_are_refused_in_one_line(tmp_path: Path) -> None:
    top = Path(str(REAL)).resolve()
    bags = sorted(p.parent for p in top.rglob("metadata.yaml"))
    imported = refused = 0
    for index, bag in enumerate(bags):
        tree, model = _nearest_tree(bag, top)
        args = ["import", str(bag), "-o", str(tmp_path / f"bag{index}.mcap")]
        if tree is not None:
            args += ["--tree", str(tree)]
        if model is not None:
            args += ["--nodes-model", str(model)]
        result = btlog(*args)
        if result.returncode == 0:
            imported += 1
            continue
        assert result.returncode == 2, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and str(bag) in lines[0], result.stderr
        assert "no /behavior_tree_log topic" in lines[0], result.stderr
        refused += 1
    print(f"\n{len(bags)} bags: {imported} imported, {refused} without a behavior tree log")
