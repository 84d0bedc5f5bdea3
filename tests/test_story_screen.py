"""The story of a tree with many subgoals stays one screen: those that did not succeed
are always told, the successes past ``SUBGOALS`` counted (``btlog run`` and ``btlog
explain`` in subprocesses)."""

from __future__ import annotations

from pathlib import Path

from btlog.explain.story import SUBGOALS
from tests.cli_support import btlog


def test_many_subgoals_fit_a_screen_and_the_failed_one_is_told(tmp_path: Path) -> None:
    steps = "".join(f'<Step name="step {i}"/>' for i in range(1, SUBGOALS + 7))
    tree = tmp_path / "steps.xml"
    tree.write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="Steps">'
        f'<Sequence name="do the steps">{steps}</Sequence></BehaviorTree></root>'
    )
    out = tmp_path / "steps.mcap"
    done = btlog("run", str(tree), "--fail", f"step {SUBGOALS + 3}", "-o", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    told = btlog("explain", str(out))
    assert told.returncode == 0, told.stderr
    lines = told.stdout.splitlines()
    listed = lines[lines.index("Subgoals:") + 1 :]
    assert len(listed) == SUBGOALS + 1
    assert f"  step {SUBGOALS + 3}: FAILURE in 0.500 s" in "\n".join(listed)
    assert [line for line in listed if "not started" in line] == [
        f"  step {i}: not started" for i in range(SUBGOALS + 4, SUBGOALS + 7)
    ]
    assert listed[-1] == "  … and 6 more subgoals (6 SUCCESS)."
