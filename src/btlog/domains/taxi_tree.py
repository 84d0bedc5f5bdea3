"""Semi-automatic tree generation (section 7.2): the actions a policy takes, cut into
subgoals where the kind of action switches, written as a BehaviorTree.CPP v4 tree with
meaning (a goal, subgoals, steps and actions).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from lxml import etree

from btlog.domains.taxi_mdp import (
    ACTIONS,
    DROP_OFF,
    MOVES,
    PICK_UP,
    TaxiState,
    TaxiWorld,
    rollout,
)

_SUBGOAL_NAMES: Mapping[str, tuple[str, str, str]] = MappingProxyType(
    {
        PICK_UP: ("go pick up passenger", "navigate to passenger", "pick up passenger"),
        DROP_OFF: ("go drop off passenger", "navigate to destination", "drop off passenger"),
    }
)


@dataclass(frozen=True)
class Subgoal:
    """One subgoal cut out of an action sequence by the :class:`SwitchListener`.

    ``moves`` is the run of move actions (the step ``step_name``, possibly empty) that led to
    ``action`` (``pick up`` or ``drop off``), whose node is named ``action_name``.
    """

    name: str
    step_name: str
    moves: tuple[str, ...]
    action: str
    action_name: str


class SwitchListener:
    """Listens to the actions a policy takes and cuts them into subgoals at switches.

    Moves are collected until the action switches from moving to ``pick up`` or ``drop off``;
    the switch closes a :class:`Subgoal` ("go pick up passenger" with its step "navigate to
    passenger", or "go drop off passenger" with "navigate to destination").
    """

    def __init__(self) -> None:
        """Start listening with no actions seen."""
        self._moves: list[str] = []
        self.subgoals: list[Subgoal] = []

    @property
    def pending_moves(self) -> tuple[str, ...]:
        """Moves seen since the last switch, not yet part of a subgoal."""
        return tuple(self._moves)

    def observe(self, action: str) -> Subgoal | None:
        """Take the next action; return the subgoal it completes, if it is a switch."""
        if action in MOVES:
            self._moves.append(action)
            return None
        if action not in _SUBGOAL_NAMES:
            raise ValueError(f"unknown action {action!r}; expected one of {', '.join(ACTIONS)}")
        name, step_name, action_name = _SUBGOAL_NAMES[action]
        subgoal = Subgoal(name, step_name, tuple(self._moves), action, action_name)
        self._moves.clear()
        self.subgoals.append(subgoal)
        return subgoal

    def finish(self) -> list[Subgoal]:
        """The subgoals found; raises ValueError if moves are left over after the last switch."""
        if self._moves:
            raise ValueError(
                f"the action sequence ends with {len(self._moves)} move action(s) that lead to "
                f"neither {PICK_UP!r} nor {DROP_OFF!r}"
            )
        return list(self.subgoals)


def generate_tree_xml(
    actions: Iterable[str], goal: str = "go deliver passenger", *, comment: str | None = None
) -> str:
    """A BehaviorTree.CPP v4 tree (XML text) for an action sequence, in the paper's structure.

    The goal is the main tree's root ``<Sequence name=goal>`` holding one ``<SubTree>`` per
    subgoal found by :class:`SwitchListener`. Each subgoal is its own ``<BehaviorTree>`` whose
    root ``<Sequence>`` carries the subgoal's name and holds the step ``<Sequence name="navigate
    to ...">`` of nameless move actions (left out when there are no moves) and then the named
    ``pick up``/``drop off`` action. A subgoal that occurs again gets a numbered ID ("go pick up
    passenger 2"). A ``<TreeNodesModel>`` declares every action used, so Groot2 can open the
    file. ``comment``, if given, is written as an XML comment before the root element.
    """
    if not goal:
        raise ValueError("the goal needs a name")
    listener = SwitchListener()
    for action in actions:
        listener.observe(action)
    subgoals = listener.finish()
    if not subgoals:
        raise ValueError(f"no {PICK_UP!r} or {DROP_OFF!r} in the action sequence: no subgoals")

    root = etree.Element("root")
    root.set("BTCPP_format", "4")
    root.set("main_tree_to_execute", "MainTree")
    main_tree = etree.SubElement(root, "BehaviorTree", ID="MainTree")
    goal_node = etree.SubElement(main_tree, "Sequence", name=goal)

    seen: dict[str, int] = {}
    used: set[str] = set()
    for subgoal in subgoals:
        seen[subgoal.name] = seen.get(subgoal.name, 0) + 1
        count = seen[subgoal.name]
        tree_id = subgoal.name if count == 1 else f"{subgoal.name} {count}"
        etree.SubElement(goal_node, "SubTree", ID=tree_id, name=tree_id)
        tree = etree.Element("BehaviorTree", ID=tree_id)
        subgoal_node = etree.SubElement(tree, "Sequence", name=tree_id)
        if subgoal.moves:
            step_node = etree.SubElement(subgoal_node, "Sequence", name=subgoal.step_name)
            for move in subgoal.moves:
                etree.SubElement(step_node, "Action", ID=move, name="")
        etree.SubElement(subgoal_node, "Action", ID=subgoal.action, name=subgoal.action_name)
        used.update(subgoal.moves)
        used.add(subgoal.action)
        root.append(tree)

    model = etree.SubElement(root, "TreeNodesModel")
    for action in ACTIONS:
        if action in used:
            etree.SubElement(model, "Action", ID=action)

    etree.indent(root, space="    ")
    header = '<?xml version="1.0" encoding="UTF-8"?>\n'
    if comment is not None:
        header += etree.tostring(etree.Comment(f" {comment} "), encoding="unicode") + "\n"
    return header + etree.tostring(root, encoding="unicode") + "\n"


def generate_tree_xml_for(
    world: TaxiWorld,
    policy: Mapping[TaxiState, str],
    goal: str = "go deliver passenger",
    *,
    comment: str | None = None,
    max_steps: int = 100,
) -> str:
    """The tree of ``policy`` in ``world``: :func:`rollout`, then :func:`generate_tree_xml`."""
    return generate_tree_xml(rollout(world, policy, max_steps), goal, comment=comment)
