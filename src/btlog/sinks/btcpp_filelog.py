"""Write a btlog recording as a BehaviorTree.CPP v4 FileLogger2 file (``.btlog``).

The layout is the one ``btlog.sources.btcpp_filelog`` reads. The tree XML is written the
way BT.CPP's ``WriteTreeToXML`` writes it, so Groot2 and BT.CPP's tools read it: each
subtree instance as its own ``<BehaviorTree ID=… _fullpath=…>``, every node with its
``_uid``, and a ``<TreeNodesModel>`` of the types used. FileLogger2 holds status
transitions only: blackboard writes are left out (and counted); a run whose tree changed
while it ran ("Can you …?" insertions) cannot be written, since the file has one tree.
"""

from __future__ import annotations

import os
import re
import struct
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from lxml import etree

from btlog.events import BlackboardWrite, StatusChange, TreeMutation
from btlog.record.reader import Recording
from btlog.sources import FILELOG_MAGIC
from btlog.sources.btcpp_filelog import VERSION
from btlog.sources.btcpp_records import MAX_UID, MAX_US, encode_record
from btlog.sources.builder import SourceError
from btlog.tree.model import SUBTREE, Node, Tree

MODEL_TAGS = {
    "action": "Action",
    "condition": "Condition",
    "control": "Control",
    "decorator": "Decorator",
}
PORT_TAGS = {"input": "input_port", "output": "output_port", "inout": "inout_port"}
#: btlog's own bookkeeping attributes, not BT.CPP attributes
_INTERNAL = ("subtree_id", "shared_blackboard")
_XML_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")


@dataclass
class ExportResult:
    """What was written: the file, the transitions and the writes left out."""

    path: Path
    transitions: int
    writes_left_out: int


def tree_xml(tree: Tree) -> bytes:
    """The tree as BT.CPP's ``WriteTreeToXML(tree, true, true)`` writes it."""
    root = etree.Element("root", BTCPP_format="4")
    instances: list[tuple[str, str, Node]] = [(tree.name, "", tree.root)]
    for node in tree:
        if node.kind == SUBTREE and node.children:
            subtree_id = node.attributes.get("subtree_id", node.name)
            instances.append((subtree_id, node.children[0].scope, node.children[0]))
    for tree_id, fullpath, top in instances:
        element = etree.SubElement(root, "BehaviorTree", ID=tree_id, _fullpath=fullpath)
        _add_node(element, top)
    model = etree.SubElement(root, "TreeNodesModel")
    declared: dict[str, Node] = {}
    for node in tree:
        if node.kind != SUBTREE:
            declared.setdefault(node.type, node)
    for type_id in sorted(declared):
        node = declared[type_id]
        entry = etree.SubElement(model, MODEL_TAGS[node.kind], ID=type_id)
        for name, port in node.ports.items():
            etree.SubElement(entry, PORT_TAGS.get(port.direction, "input_port"), name=name)
    return etree.tostring(root, pretty_print=True)


def _add_node(parent: etree._Element, node: Node) -> None:
    if node.kind == SUBTREE:
        element = etree.SubElement(parent, "SubTree")
        element.set("ID", node.attributes.get("subtree_id", node.name))
        element.set("_fullpath", node.path)
    elif _XML_NAME.match(node.type):
        element = etree.SubElement(parent, node.type)
        element.set("name", node.name)
    else:  # a type that is no XML name ("move to"): the generic form BT.CPP also reads
        element = etree.SubElement(parent, MODEL_TAGS[node.kind])
        element.set("ID", node.type)
        element.set("name", node.name)
    element.set("_uid", str(node.uid))
    for name, port in node.ports.items():
        element.set(name, port.value)
    for name, value in node.attributes.items():
        if name not in _INTERNAL:
            element.set(name, value)
    if node.kind != SUBTREE:
        for child in node.children:
            _add_node(element, child)


def export_filelog(recording: Recording, output: str | os.PathLike) -> ExportResult:
    """Write ``recording`` as the FileLogger2 file ``output``."""
    where = os.fspath(recording.path)
    mutations = sum(isinstance(e, TreeMutation) for e in recording.events)
    if mutations:
        changed = "once" if mutations == 1 else f"{mutations} times"
        raise SourceError(
            f"{where}: the tree changed {changed} during the run ('Can you …?'); "
            "a FileLogger2 file holds one tree"
        )
    too_big = [n.uid for n in recording.tree if n.uid > MAX_UID]
    if too_big:
        raise SourceError(f"{where}: uid {too_big[0]} does not fit FileLogger2's 16 bits")
    xml = tree_xml(recording.tree)
    start_us = start_us_of(recording.metadata.get("started_at"), where)
    records = bytearray()
    transitions = writes = 0
    for event in recording.events:
        if isinstance(event, BlackboardWrite):
            writes += 1
        elif isinstance(event, StatusChange):
            t_us = event.t_ns // 1000
            if not 0 <= t_us <= MAX_US:
                raise SourceError(f"{where}: event {event.seq} at {t_us} µs is out of range")
            records += encode_record(t_us, event.uid, event.status)
            transitions += 1
    data = FILELOG_MAGIC + bytes([VERSION]) + struct.pack("<i", len(xml)) + xml
    data += struct.pack("<q", start_us) + bytes(records)
    Path(output).write_bytes(data)
    return ExportResult(Path(output), transitions, writes)


def start_us_of(started_at: object, where: str) -> int:
    """The run's ``started_at`` metadata as FileLogger2's start time (µs since the epoch);
    SourceError naming ``where`` when it is not a time."""
    try:
        moment = datetime.fromisoformat(str(started_at))
    except ValueError:
        raise SourceError(f"{where}: started_at {started_at!r} is not a time") from None
    return round(moment.timestamp() * 1e6)
