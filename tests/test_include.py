"""``<include path=…>``: trees split over files, resolved against the including file."""

from __future__ import annotations

from pathlib import Path

import pytest

from btlog.domains.outcomes import Outcomes, scripted_leaf_factory
from btlog.executor.engine import Executor
from btlog.status import SUCCESS
from btlog.tree.loader import TreeError, load_tree

MAIN = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <include path="{path}"/>
  <BehaviorTree ID="Main">
    <Sequence name="deliver">
      <SubTree ID="Fetch" name="fetch part"/>
      <Action ID="hand over" name="hand over"/>
    </Sequence>
  </BehaviorTree>
</root>
"""

FETCH = """<root BTCPP_format="4">
  <BehaviorTree ID="Fetch">
    <Sequence name="fetch">
      <Action ID="go to shelf" name="go to shelf"/>
      <Action ID="pick" name="pick"/>
    </Sequence>
  </BehaviorTree>
</root>
"""


def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def test_an_included_subtree_is_expanded_and_runs(tmp_path: Path) -> None:
    included = _write(tmp_path / "parts", "fetch.xml", FETCH)
    main = _write(tmp_path, "main.xml", MAIN.format(path="parts/fetch.xml"))
    tree = load_tree(str(main))
    names = [node.name for node in tree]
    assert names[:5] == ["deliver", "fetch part", "fetch", "go to shelf", "pick"]
    pick = tree.lookup_one("pick")
    assert Path(pick.file).resolve() == included.resolve()
    assert pick.line == 5
    outcomes = Outcomes.from_mapping({"default": {"status": "SUCCESS", "duration": 0}})
    executor = Executor(tree, leaf_factory=scripted_leaf_factory(tree, outcomes))
    try:
        assert executor.run(20) is SUCCESS
    finally:
        executor.close()


def test_includes_resolve_against_the_including_file(tmp_path: Path) -> None:
    """An include inside an included file is relative to that file, not to the main one."""
    _write(tmp_path / "a" / "b", "fetch.xml", FETCH)
    _write(
        tmp_path / "a",
        "middle.xml",
        '<root BTCPP_format="4"><include path="b/fetch.xml"/></root>',
    )
    main = _write(tmp_path, "main.xml", MAIN.format(path="a/middle.xml"))
    assert "pick" in [node.name for node in load_tree(str(main))]


@pytest.mark.parametrize(
    ("include", "words"),
    [
        ("<include/>", "needs a path attribute"),
        ('<include path="missing.xml"/>', "cannot read included file 'missing.xml'"),
        ('<include path="main.xml"/>', "include cycle"),
        ('<include ros_pkg="x" path="y.xml"/>', "needs ROS"),
    ],
)
def test_a_bad_include_names_the_including_file_and_line(
    tmp_path: Path, include: str, words: str
) -> None:
    main = _write(
        tmp_path,
        "main.xml",
        f'<root BTCPP_format="4">\n  {include}\n'
        '  <BehaviorTree ID="Main"><AlwaysSuccess/></BehaviorTree>\n</root>\n',
    )
    with pytest.raises(TreeError) as raised:
        load_tree(str(main))
    message = str(raised.value)
    assert f"{main}:2: " in message and words in message
    assert "\n" not in message
