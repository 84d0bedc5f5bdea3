"""The README's table of questions prints as shown: every example answer in it is what
``btlog ask`` prints for that recording, moment and question (issue #23, item 7).

The table names its recordings by letter: ``K`` the bundled
``recordings/kitting-look-at-chuck-fails.mcap``, ``T`` a taxi run with ``--fail "pick up
passenger"``, ``I`` a kitting run whose "trial and error insert" always fails, and the
fetch tree of ``tests/data/answers``. ``EXAMPLES`` says which question each example
answers; the table may hold no example this file does not check.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.cli_support import ROOT, btlog

README = (ROOT / "README.md").read_text(encoding="utf-8")
ANSWERS = ROOT / "tests" / "data" / "answers"

#: (recording, moment, question, the answer the README shows)
EXAMPLES = [
    ("K", "10.4s", "What are you doing?", "I retreat arm."),
    ("K", "10.4s", "Why are you doing this?", "I retreat arm in order to insert large gear."),
    ("K", "10.4s", "What is your subgoal?", "My subgoal is to go insert large gear."),
    (
        "K",
        "10.4s",
        "How do you achieve your subgoal?",
        'To achieve the subgoal "go insert large gear", I need to do 3 steps. 1. move to '
        "see chuck. 2. detect chuck. 3. insert large gear.",
    ),
    (
        "K",
        "10.4s",
        "What went wrong?",
        "I could not insert large gear because look at chuck failed.",
    ),
    (
        "T",
        "end",
        "What went wrong?",
        "I could not go deliver passenger because pick up passenger failed.",
    ),
    (
        "I",
        "end",
        "What went wrong?",
        "At 40.700 s: I am retrying for attempt 2 to go insert large gear. I could not insert "
        "large gear because trial and error insert failed.",
    ),
    (
        "K",
        "10.4s",
        "Can you insert large gear?",
        "Yes. I will insert large gear after go insert large gear.",
    ),
    ("I", "0.1s", "What will you do next?", "After I move to see chuck, I will lift torso."),
    ("K", "10.4s", "What will you do next?", "After I retreat arm, I will lift torso."),
    (
        "T",
        "end",
        "Why did go pick up passenger fail?",
        "I could not go pick up passenger because pick up passenger failed.",
    ),
    (
        "T",
        "end",
        "Why didn't you drop off passenger?",
        "I did not drop off passenger because pick up passenger failed.",
    ),
    (
        "fetch tree",
        "1.5s",
        "Why didn't you go to the kitchen?",
        "I tried to go to the kitchen, but it failed.",
    ),
    ("K", "end", "When did look at chuck last fail?", "look at chuck last failed at 10.400 s."),
    (
        "T",
        "end",
        "How long did go pick up passenger take?",
        "go pick up passenger took 7.000 s, from 0.000 s to 7.000 s.",
    ),
    (
        "I",
        "3s",
        "How long has move to see chuck been running?",
        "move to see chuck has been running for 3.000 s.",
    ),
]


def _table() -> str:
    start = README.index("| question (case-insensitive")
    return README[start : README.index("\n\n", start)]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("readme-questions")
    (folder / "insert.yaml").write_text('{nodes: {"trial and error insert": [FAILURE]}}\n')
    runs = {
        "T": ["trees/taxi.xml", "--domain", "taxi", "--fail", "pick up passenger"],
        "I": [
            "trees/kitting.xml",
            "--domain",
            "kitting",
            "--outcomes",
            str(folder / "insert.yaml"),
        ],
        "fetch tree": [
            str(ANSWERS / "fetch-coffee.xml"),
            "--outcomes",
            str(ANSWERS / "fetch-coffee.yaml"),
        ],
    }
    made = {"K": ROOT / "recordings" / "kitting-look-at-chuck-fails.mcap"}
    for letter, args in runs.items():
        out = folder / f"{letter.replace(' ', '-')}.mcap"
        done = btlog("run", *args, "-o", str(out), "--quiet", cwd=ROOT)
        assert done.returncode == 0, done.stderr
        made[letter] = out
    return made


def test_every_example_of_the_table_is_checked() -> None:
    shown = re.findall(r"((?:[KTI]|fetch tree) at [^:`|]+): `([^`]*)`", _table())
    checked = [(f"{letter} at {at}", said) for letter, at, _question, said in EXAMPLES]
    assert sorted(shown) == sorted(checked)


@pytest.mark.parametrize(("letter", "at", "question", "said"), EXAMPLES)
def test_the_table_prints_as_shown(
    recordings: dict[str, Path], letter: str, at: str, question: str, said: str
) -> None:
    done = btlog("ask", str(recordings[letter]), "--at", at, question)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == said
