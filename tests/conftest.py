"""Shared fixtures: the paper's original trees, found outside the project when present.

The paper's trees (Han et al., THRI 2020; github.com/uml-robotics) carry no licence, so the
project does not copy them. Tests that need the originals take the ``paper_trees``
fixture: the folder named by ``$BTLOG_PAPER_TREES``, else ``../shared/reference/uml-robotics``
beside the checkout; without it they are skipped with the reason. Every other test runs
on the project's own trees (``trees/`` and ``tests/data/``).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAPER_TREE_FILES = ("kitting-tree.xml", "taxi-domain-tree.xml")
#: Parametrize ids of the form ``paper/NAME`` name the paper's original ``NAME``.
PAPER_PREFIX = "paper/"


def find_paper_trees() -> Path | None:
    """The folder holding the paper's original trees, or None when it is absent."""
    given = os.environ.get("BTLOG_PAPER_TREES")
    folder = Path(given) if given else ROOT.parent / "shared" / "reference" / "uml-robotics"
    if all((folder / name).is_file() for name in PAPER_TREE_FILES):
        return folder
    return None


@pytest.fixture(scope="session")
def paper_trees() -> Path:
    """The folder of the paper's original trees; skips the test when it is absent."""
    folder = find_paper_trees()
    if folder is None:
        pytest.skip(
            "the paper's original trees are absent: set BTLOG_PAPER_TREES to the folder "
            "holding kitting-tree.xml and taxi-domain-tree.xml, or put it at "
            "../shared/reference/uml-robotics"
        )
    return folder


@pytest.fixture
def tree_file(request: pytest.FixtureRequest) -> Path:
    """A tree from ``parametrize(..., indirect=["tree_file"])``: ``paper/NAME`` is the
    paper's original (skipped when absent), anything else is relative to the project."""
    spec: str = request.param
    if spec.startswith(PAPER_PREFIX):
        folder: Path = request.getfixturevalue("paper_trees")
        return folder / spec.removeprefix(PAPER_PREFIX)
    return ROOT / spec


@pytest.fixture(scope="session", autouse=True)
def cache_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The read model's caches of the whole session (CLI subprocesses included) go to a
    temporary folder, never to the user's cache folder."""
    folder = tmp_path_factory.mktemp("btlog-cache")
    os.environ["BTLOG_CACHE_DIR"] = str(folder)
    return folder
