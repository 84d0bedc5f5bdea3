"""How an answer speaks of nodes (their words) and of times.

The paper's ``d(n)`` is a node's name, or its registration ID when it has none; the
paper's trees name their nodes in English ("look at chuck"), so ``d(n)`` reads as a verb
phrase. Real trees name nodes as identifiers — ``ComputePathToPose``,
``ClearLocalCostmap-Context``, ``follow_path`` — and leave most control nodes unnamed
(BehaviorTree.CPP then gives them their type as a name: a ``<Sequence>`` is named
"Sequence"). An answer that says "I ComputePathToPose in order to Sequence." is no
answer. So, in answers (never in tables, SQL or the timeline, which keep names as
recorded):

- a node's **own description** comes first: its ``_description`` attribute — not a
  port in BehaviorTree.CPP 4 (a leading ``_`` is never one; BT.CPP keeps it as a
  non-port attribute, its docs list it as reserved, Groot2 and MoveIt Pro write it on
  ``<BehaviorTree>``s), taken for the SubTree that runs such a tree too — or what a
  descriptions file (``--descriptions FILE``) gives for its path, name or type; the
  loader stores both as the node's ``_description``, so a recording carries them and
  post-hoc answers equal live ones. A description is documentation as often as a verb
  phrase ("Close the right gripper by default.", "Returns the pose of the frame.", "An
  example showing how to …"), so it is spoken as its first sentence without its full
  stop, its first word in the base form a sentence "I …" needs ("Returns" → "return")
  and in lower case unless it is an acronym; one that starts as a noun phrase (an
  article, a demonstrative or a pronoun: "An example …", "This subtree …") or is longer
  than ``MAX_PHRASE_WORDS`` words is documentation, not words for the node, and the name
  is used instead;
- else its name or type as **words**: an identifier is cut at its case changes,
  underscores and hyphens and lower-cased ("compute path to pose", "clear local costmap
  context"), acronyms kept ("read IMU"); a control node's or decorator's own type
  standing first or last in its name is dropped ("FallbackComputePathToPose" on a
  Fallback is "compute path to pose"), and so is its type's first word in front of more
  ("RecoveryFollowPath" on a RecoveryNode is "follow path") — never a leaf's, whose type
  is what it does ("SpinRecovery" on a Spin is "spin recovery"); a name that already
  has spaces is kept as written but for a capitalised first word ("Drive in a square"
  → "drive in a square") or the capitals of a Title Case name ("Close Gripper" → "close
  gripper"), so the paper's answers do not change;
- in the slots of a sentence that say what the robot does, a condition is the check it
  is (``act``: "check battery OK"; the paper's "check if grasped" as it is);
- a node is **named** when it has such words of its own: a usable description, or a
  name that is neither empty nor its type, nor merely restates a type or a tree's ID
  (``restates_structure``: a Sequence named "root_sequence", "RootSequence" or
  "main_sequence", a SubTree or tree named "MainTree" are no names). Only named nodes
  are purposes, subgoals, steps or goals; an unnamed control node (or SubTree) is never
  spoken of — the answer climbs to the nearest named ancestor instead. The goal is the
  root when it is named, else the main tree's ID when that is a name, else the steps
  the root holds ("get to kitchen, grasp cup and bring coffee").
"""

from __future__ import annotations

import functools
import re

from btlog.tree.descriptions import DESCRIPTION
from btlog.tree.model import CONDITION, CONTROL, DECORATOR, SUBTREE, Node, Tree

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")
_WORD = re.compile(
    r"[A-Z]+(?=[A-Z][a-z])|[0-9]+[A-Z]+(?=[A-Z][a-z]|[^A-Za-z]|$)|[A-Z]?[a-z]+|[A-Z]+|[0-9]+"
)
#: First words that make a name a place, not an action: "ToFridge" is "go to fridge".
_MOTION_PREPOSITIONS = frozenset({"to", "towards", "toward"})
_SENTENCE_END = re.compile(r"(?<=[.!?])\s")
#: A description longer than this (its first sentence) is documentation, not words.
MAX_PHRASE_WORDS = 14
#: First words of a noun phrase: a description starting so is not a verb phrase.
_NOUN_PHRASE_STARTS = frozenset(
    {"a", "an", "the", "this", "that", "these", "those", "it", "its", "here", "there"}
    | {"i", "my", "we", "our", "you", "your"}
)


#: Words that say only where a node sits or what kind of node it is: a control's,
#: decorator's, SubTree's or tree's name made of these (and its own type's words and
#: numbers) alone restates a type or a tree's ID, and is no name.
_STRUCTURE_WORDS = frozenset(
    {"root", "main", "top", "level", "tree", "sub", "subtree", "behavior", "behaviour"}
    | {"bt", "node", "control", "decorator", "sequence", "fallback", "selector"}
    | {"parallel", "reactive", "seq", "sel", "my", "inner", "outer", "loop"}
)
#: At most this many steps are named when the goal is said as the root's steps.
MAX_GOAL_STEPS = 4


def split_identifier(text: str) -> list[str]:
    """The words of an identifier: ``ClearLocalCostmap-Context`` → ``clear, local,
    costmap, context``; acronyms stay upper case (``ReadIMUData`` → ``read, IMU, data``),
    but an identifier all in capitals is shouted words, not acronyms (``TEST_ACTION_A`` →
    ``test, action, a``); numbers are words of their own, a dimension kept whole
    (``GoToLocation2`` → ``go, to, location, 2``; ``GetMasks2DFromExemplar`` → ``get,
    masks, 2D, from, exemplar``); a name that starts with "to" is a place to go
    (``ToFridge`` → ``go, to, fridge``)."""
    shouted = not any(c.islower() for c in text)
    words = []
    for part in re.split(r"[_\-]+", text):
        for word in _WORD.findall(part):
            words.append(word if len(word) > 1 and word.isupper() else word.lower())
    words = [w.lower() for w in words] if shouted and len(words) > 1 else words
    return ["go", *words] if len(words) > 1 and words[0] in _MOTION_PREPOSITIONS else words


def _lower_initial(word: str) -> str:
    """``Drive`` → ``drive``; an acronym or a mixed-case word (``ICP``, ``AprilTag``) as
    it is."""
    if len(word) > 1 and word[0].isupper() and word[1:].islower():
        return word[0].lower() + word[1:]
    return word


def _as_written(text: str) -> str:
    """A name with spaces as an answer speaks it: its capitalised first word in lower
    case ("Drive in a square" → "drive in a square"), every capitalised word of a Title
    Case name ("Move Left Home" → "move left home"); acronyms as they are."""
    parts = text.split(" ")
    if len(parts) < 2:
        return text
    long_words = [p for p in parts if len(p) > 3 and p.isalpha()]
    if long_words and all(p[0].isupper() for p in long_words):
        return " ".join(_lower_initial(p) for p in parts)
    return " ".join([_lower_initial(parts[0]), *parts[1:]])


def _base_form(verb: str) -> str:
    """A third-person verb in the base form a sentence "I …" needs: ``returns`` →
    ``return``, ``verifies`` → ``verify``, ``fetches`` → ``fetch``; another word (``move``,
    ``process``, ``focus``) as it is."""
    lower = verb.lower()
    if not lower.isalpha() or len(lower) < 4 or not lower.endswith("s"):
        return verb
    if lower.endswith("ies"):
        return verb[:-3] + "y"
    if lower.endswith(("sses", "xes", "ches", "shes", "zzes", "oes")):
        return verb[:-2]
    if lower.endswith(("ss", "us", "is")):
        return verb
    return verb[:-1]


@functools.lru_cache(maxsize=1 << 16)
def phrase(text: str) -> str | None:
    """A description as an answer speaks it (see the module docstring), or None when it
    is documentation rather than a phrase for the node."""
    sentence = _SENTENCE_END.split(" ".join(text.split()), maxsplit=1)[0].rstrip(" .!;:")
    parts = sentence.split(" ")
    if not sentence or len(parts) > MAX_PHRASE_WORDS:
        return None
    if parts[0].lower() in _NOUN_PHRASE_STARTS:
        return None
    parts[0] = _base_form(_lower_initial(parts[0]))
    return " ".join(parts)


@functools.lru_cache(maxsize=1 << 16)
def humanize(text: str, own_type: str = "") -> str:
    """``text`` as words when it is an identifier (see the module docstring), else as it
    is but for a capitalised first word; ``own_type``, a control's or decorator's type,
    is dropped from either end of the words, or its first word from the front."""
    if not _IDENTIFIER.match(text):
        return _as_written(text)
    words = split_identifier(text)
    if own_type and own_type != text and _IDENTIFIER.match(own_type):
        drop = split_identifier(own_type)
        if len(words) > len(drop) and words[: len(drop)] == drop:
            words = words[len(drop) :]
        elif len(words) > len(drop) and words[-len(drop) :] == drop:
            words = words[: -len(drop)]
        elif len(drop) > 1 and len(words) > 1 and words[0] == drop[0]:
            words = words[1:]
    return " ".join(words) if words else text


def restates_structure(name: str, own_type: str = "") -> bool:
    """True when ``name`` says nothing but where a node sits or what kind it is: every
    word of it is a structure word ("root", "main", "tree", "seq", …), a word of
    ``own_type``, that type in lower case or a number (``root_sequence``,
    ``RootSequence``, ``main_seq``, ``root_reactivefallback``, ``MainTree``,
    ``Fallback2``)."""
    found = [w.lower() for part in re.split(r"\s+", name) for w in split_identifier(part)]
    own = {w.lower() for w in [*split_identifier(own_type), own_type]} if own_type else set()
    return bool(found) and all(w in _STRUCTURE_WORDS or w in own or w.isdigit() for w in found)


def own_phrase(node: Node) -> str | None:
    """The node's description as an answer speaks it (``phrase``), if it has one."""
    described = node.attributes.get(DESCRIPTION, "")
    return phrase(described) if described.strip() else None


def is_named(node: Node) -> bool:
    """True when the node has words of its own (see the module docstring): a usable
    description, or a name that is neither empty nor its type and, on a control,
    decorator or SubTree (whose name is the subtree's), does not merely restate a type or
    a tree's ID."""
    if own_phrase(node):
        return True
    if not node.name or (node.name == node.type and node.kind != SUBTREE):
        return False
    return node.is_execution or not restates_structure(node.name, node.type)


def words(node: Node) -> str:
    """The node as an answer speaks of it (see the module docstring)."""
    own = own_phrase(node)
    if own:
        return own
    if node.name and node.name != node.type:
        structural = node.kind in (CONTROL, DECORATOR)
        return humanize(node.name, node.type if structural else "")
    return humanize(node.description)


def act(node: Node) -> str:
    """The node as what the robot does, for the verb slots of answers ("I {…}", "in
    order to …", "I will …", "I did …"): its words, a condition's as the check it is
    ("check battery OK", "check goal updated") unless its own words already begin with
    "check" or come from its description."""
    said = words(node)
    if node.kind != CONDITION or own_phrase(node) or said.split(" ", 1)[0].lower() == "check":
        return said
    return f"check {said}"


def named_ancestor(node: Node, *, skip_decorators: bool = False) -> Node | None:
    """The nearest ancestor that is named (a decorator too, unless ``skip_decorators``)."""
    for ancestor in node.ancestors():
        if is_named(ancestor) and not (skip_decorators and ancestor.kind == "decorator"):
            return ancestor
    return None


def first_named(node: Node) -> Node:
    """``node`` when it is named, else the first named node below it (depth first) —
    what an unnamed branch does first ("fell back to clear local costmap context");
    ``node`` itself when nothing below is named."""
    for inner in node.walk():
        if is_named(inner) and inner.kind != "decorator":
            return inner
    return node


def goal_words(tree: Tree) -> str:
    """The goal as an answer speaks of it: the root when it is named or an execution
    node (whose type is what it does), else the main tree's own name (its
    ``BehaviorTree`` ID) when it is a name, else what the root holds: its first named
    nodes (or actions) below, joined ("get to kitchen, grasp cup and bring coffee"; past
    ``MAX_GOAL_STEPS``, "… and N more")."""
    root = tree.root
    if is_named(root) or root.is_execution:
        return words(root)
    if tree.name and not restates_structure(tree.name):
        return humanize(tree.name)
    held = [words(n) for n in _tops(root)]
    if not held:
        return words(root)
    if len(held) > MAX_GOAL_STEPS:
        held = [*held[: MAX_GOAL_STEPS - 1], f"{len(held) - MAX_GOAL_STEPS + 1} more"]
    return held[0] if len(held) == 1 else ", ".join(held[:-1]) + " and " + held[-1]


def _tops(node: Node) -> list[Node]:
    """Depth first below ``node``, the first nodes that are named (not decorators) or
    execution nodes; their branches are not explored further."""
    found: list[Node] = []
    stack = list(reversed(node.children))
    while stack:
        inner = stack.pop()
        if inner.is_execution or (is_named(inner) and inner.kind != DECORATOR):
            found.append(inner)
        else:
            stack.extend(reversed(inner.children))
    return found


def seconds(t_ns: int) -> str:
    """A time or duration as answers and the commands print it: seconds, millisecond
    precision."""
    return f"{t_ns / 1e9:.3f}"
