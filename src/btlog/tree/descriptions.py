"""Descriptions: what a node does, in the words an answer should use.

Trees name their nodes for programmers (``ComputePathToPose``, ``RecoveryFallback``);
answers speak to people ("I plan a path to the goal."). A node's own description is its
``_description`` attribute — BehaviorTree.CPP 4 reserves it on every node, and on a
``<BehaviorTree>`` for the SubTree that runs it (the loader copies that one onto the
SubTree node) — or what a **descriptions file** says (``--descriptions FILE``, YAML or
JSON, validated by ``schemas/descriptions.schema.json``)::

    ComputePathToPose: plan a path to the goal     # a type, or a name
    NavigateRecovery: navigate to the goal
    "MainTree/Sequence::3": check the battery      # a path

Each node takes the entry of its path, else of its name, else of its type; a file's
entry wins over the XML's ``_description``. The chosen words are stored as the node's
``_description`` attribute, so a recording carries them (the ``/btlog/tree`` message)
and a question asked after the run, from the file alone, gets the live answer's words;
the file's entries are also kept in the run's metadata (``descriptions``).
"""

from __future__ import annotations

import os

from btlog.tree.model import Tree

#: The attribute that holds a node's own description.
DESCRIPTION = "_description"


def load_descriptions(path: str | os.PathLike[str]) -> dict[str, str]:
    """The entries of a descriptions file (``documents.DocumentError`` when it is not
    one: one line naming the file, line and key)."""
    from btlog import documents  # YAML and JSON Schema: only when a file is read

    data = documents.load(path, "descriptions", "descriptions file")
    return {str(key): " ".join(str(value).split()) for key, value in (data or {}).items()}


def apply_descriptions(tree: Tree, entries: dict[str, str]) -> list[str]:
    """Give each node of ``tree`` the description its path, name or type has in
    ``entries``; return the keys that name no node (a user's typo to warn about)."""
    used: set[str] = set()
    for node in tree:
        for key in (node.path, node.name, node.type):
            if key and key in entries:
                node.attributes[DESCRIPTION] = entries[key]
                used.add(key)
                break
    return [key for key in entries if key not in used]
