"""BehaviorTree.CPP v3 ``FileLogger`` files (``.fbl``, what Groot 1 replays).

The layout (BT.CPP 3.x ``src/loggers/bt_file_logger.cpp`` and
``flatbuffers/bt_flatbuffer_helper.h``; the same from 3.0 to 3.8), little-endian:

- an i32 N, then N bytes: a flatbuffer whose root table is ``Serialization.BehaviorTree``
  (``flatbuffers/BT_logger.fbs``): ``root_uid`` (u16), ``nodes`` (each ``TreeNode``: its
  ``uid``, ``children_uid``, ``status`` when the logger started, ``instance_name``,
  ``registration_name`` and ``port_remaps``, in depth-first pre-order) and
  ``node_models`` (each registered type's ``type`` — action, condition, control,
  decorator, subtree — and ``ports`` with their directions);
- 12-byte transitions until the end (``SerializeTransition``, written by hand, not as
  flatbuffers): u32 seconds, u32 microseconds (the low words of two 64-bit writes, the
  second overwriting the first's high word), u16 uid, i8 previous and i8 new status
  (0 IDLE, 1 RUNNING, 2 SUCCESS, 3 FAILURE). Times are the logger's clock: since the
  Unix epoch (BT.CPP's default, ``TimestampType::absolute``), or since the logger
  started (``relative``).

The flatbuffer is read by hand, every offset checked against the buffer (the
``flatbuffers`` package would need generated code and checks nothing; the layout is five
small tables). The tree is rebuilt from the header as BT.CPP 3 XML and loaded by
``btlog.tree.loader`` like any tree (built-in types btlog knows keep their semantics,
others take their kind from the header's models), then checked node by node against the
header; v3 uids come from a process-wide counter, so each is mapped to btlog's (the
header's pre-order position). ``--tree`` gives your own XML instead, checked the same
way. A logger created while the tree ran (a node not IDLE in the header, or a first
transition from another status) begins mid-run: the state it began in is recorded as
the first tick (``btlog.sources.builder.begin_mid_run``).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from lxml import etree

from btlog import limits
from btlog.sources.btcpp_tree import check_same_tree
from btlog.sources.builder import (
    DEFAULT_TICK_GAP_NS,
    BuildResult,
    RecordingBuilder,
    Source,
    SourceError,
    omitted_changes,
    state_at_first_entry,
    wall_start,
)
from btlog.sources.name_matching import logged_names
from btlog.status import Status
from btlog.tree.loader import TreeError, load_tree, load_tree_text
from btlog.tree.model import Tree
from btlog.tree.registry import Registry

FORMAT = "btcpp-fbl"
RECORD = struct.Struct("<IIHbb")
#: ``Serialization::NodeType`` values, as btlog's kinds (UNDEFINED: from the children).
KINDS = {1: "Action", 2: "Condition", 3: "Control", 4: "Decorator", 5: "SubTree"}
#: ``Serialization::PortDirection`` values, as ``<TreeNodesModel>`` elements.
DIRECTIONS = {0: "input_port", 1: "output_port", 2: "inout_port"}
SUBTREES = ("SubTree", "SubTreePlus")
#: A first transition earlier than this (2001-09-09) is in relative time.
_EPOCH_LIKE_US = 10**15
MID_RUN = (
    "the log begins mid-run (the FileLogger was created while the tree ran): the state it "
    "began in (the header's statuses, each node's previous status in its first "
    "transition, RUNNING for their ancestors) is recorded as the first tick"
)
OMITTED = (
    "changes the log leaves out were added, each at the time of the transition whose "
    "previous status shows it"
)


@dataclass
class HeaderNode:
    """A ``TreeNode`` of the header."""

    uid: int
    children: list[int]
    status: int
    name: str
    type: str
    ports: list[tuple[str, str]]


#: Transitions read at a time: the import's memory does not grow with the file.
BLOCK_RECORDS = 65536


@dataclass
class FblLog:
    """A parsed ``.fbl`` header: the tree (nodes in pre-order from the root, each type's
    kind and ports) and where the transitions lie; they are read when iterated."""

    file: str
    nodes: list[HeaderNode]
    kinds: dict[str, int]
    ports: dict[str, list[tuple[str, int]]]
    count: int
    records_offset: int
    trailing: int
    warnings: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return self.count

    def transitions(self, block: int = BLOCK_RECORDS) -> Iterator[tuple[int, int, Status, Status]]:
        """``(µs of the logger's clock, header uid, previous, new status)`` of each whole
        record, in file order, read ``block`` records at a time (``SourceError`` naming
        the record's byte otherwise)."""
        statuses = tuple(Status)[:4]
        try:
            with open(self.file, "rb") as stream:
                stream.seek(self.records_offset)
                for first in range(0, self.count, block):
                    want = min(block, self.count - first) * RECORD.size
                    data = stream.read(want)
                    whole = memoryview(data)[: len(data) - len(data) % RECORD.size]
                    for index, (sec, usec, uid, prev, new) in enumerate(
                        RECORD.iter_unpack(whole), first
                    ):
                        if not (0 <= prev < 4 and 0 <= new < 4):
                            offset = self.records_offset + index * RECORD.size
                            bad = prev if not 0 <= prev < 4 else new
                            raise SourceError(
                                f"{self.file}: byte {offset}: status {bad} is not 0-3"
                            )
                        yield sec * 1_000_000 + usec, uid, statuses[prev], statuses[new]
                    if len(data) < want:
                        offset = self.records_offset + first * RECORD.size + len(data)
                        raise SourceError(
                            f"{self.file}: byte {offset}: the file was cut while read"
                        )
        except OSError as error:
            raise SourceError(f"{self.file}: cannot read the file: {error.strerror}") from None


class _Damaged(ValueError):
    def __init__(self, offset: int, what: str) -> None:
        super().__init__(what)
        self.offset = offset


class _Buffer:
    """A flatbuffer's bytes, every read bounds-checked (``_Damaged`` with the offset)."""

    def __init__(self, data: bytes) -> None:
        self.data = data

    def scalar(self, fmt: str, position: int) -> int:
        size = struct.calcsize(fmt)
        if not 0 <= position <= len(self.data) - size:
            raise _Damaged(position, "an offset points outside the header")
        return int(struct.unpack_from(fmt, self.data, position)[0])

    def follow(self, position: int) -> int:
        """The position a uoffset at ``position`` points to."""
        return position + self.scalar("<I", position)

    def table(self, position: int) -> _Table:
        vtable = position - self.scalar("<i", position)
        size = self.scalar("<H", vtable)
        if size < 4 or size % 2 or vtable + size > len(self.data):
            raise _Damaged(vtable, "a table's vtable is malformed")
        return _Table(self, position, vtable, size)

    def string(self, position: int) -> str:
        length = self.scalar("<I", position)
        start = position + 4
        if start + length > len(self.data):
            raise _Damaged(position, "a string runs past the header")
        try:
            return self.data[start : start + length].decode("utf-8")
        except UnicodeDecodeError:
            raise _Damaged(position, "a string is not UTF-8") from None

    def vector(self, position: int, width: int) -> tuple[int, int]:
        """``(first element's position, length)`` of the vector at ``position``."""
        length = self.scalar("<I", position)
        if position + 4 + length * width > len(self.data):
            raise _Damaged(position, "a vector runs past the header")
        return position + 4, length


@dataclass(frozen=True)
class _Table:
    buffer: _Buffer
    position: int
    vtable: int
    size: int

    def _field(self, index: int) -> int | None:
        slot = 4 + 2 * index
        if slot >= self.size:
            return None
        offset = self.buffer.scalar("<H", self.vtable + slot)
        return self.position + offset if offset else None

    def scalar(self, index: int, fmt: str) -> int:
        at = self._field(index)
        return 0 if at is None else self.buffer.scalar(fmt, at)

    def string(self, index: int) -> str:
        at = self._field(index)
        return "" if at is None else self.buffer.string(self.buffer.follow(at))

    def scalars(self, index: int, fmt: str) -> list[int]:
        at = self._field(index)
        if at is None:
            return []
        start, length = self.buffer.vector(self.buffer.follow(at), struct.calcsize(fmt))
        step = struct.calcsize(fmt)
        return [self.buffer.scalar(fmt, start + i * step) for i in range(length)]

    def tables(self, index: int) -> list[_Table]:
        at = self._field(index)
        if at is None:
            return []
        start, length = self.buffer.vector(self.buffer.follow(at), 4)
        return [self.buffer.table(self.buffer.follow(start + 4 * i)) for i in range(length)]


def read_fbl(path: str | os.PathLike) -> FblLog:
    """Parse a ``.fbl`` file's header (``SourceError`` naming the file and the damaged
    byte); its transitions are read when ``FblLog.transitions`` is iterated."""
    file = os.fspath(path)
    try:
        with open(path, "rb") as stream:
            length = os.fstat(stream.fileno()).st_size
            head = stream.read(4)
            if length < 8:
                raise SourceError(f"{file}: {length} bytes: too short for a FileLogger header")
            (size,) = struct.unpack("<i", head)
            if not 8 <= size <= length - 4:
                raise SourceError(
                    f"{file}: byte 0: header size {size} does not fit in the file ({length} bytes)"
                )
            buffer = _Buffer(stream.read(size))
    except OSError as error:
        raise SourceError(f"{file}: cannot read the file: {error.strerror}") from None
    try:
        nodes, kinds, ports = _header(buffer)
    except _Damaged as error:
        raise SourceError(
            f"{file}: byte {error.offset + 4}: the FileLogger header is damaged ({error})"
        ) from None
    count, trailing = divmod(length - 4 - size, RECORD.size)
    return FblLog(file, nodes, kinds, ports, count, 4 + size, trailing)


def _header(
    buffer: _Buffer,
) -> tuple[list[HeaderNode], dict[str, int], dict[str, list[tuple[str, int]]]]:
    root = buffer.table(buffer.follow(0))
    root_uid = root.scalar(0, "<H")
    by_uid: dict[int, HeaderNode] = {}
    for table in root.tables(1):
        uid = table.scalar(0, "<H")
        by_uid.setdefault(
            uid,
            HeaderNode(
                uid,
                table.scalars(1, "<H"),
                table.scalar(2, "<b"),
                table.string(3),
                table.string(4),
                [(p.string(0), p.string(1)) for p in table.tables(5)],
            ),
        )
    kinds: dict[str, int] = {}
    ports: dict[str, list[tuple[str, int]]] = {}
    for table in root.tables(2):
        name = table.string(0)
        kinds[name] = table.scalar(1, "<b")
        ports[name] = [(p.string(0), p.scalar(1, "<b")) for p in table.tables(2)]
    return _preorder(by_uid, root_uid), kinds, ports


def _preorder(by_uid: dict[int, HeaderNode], root_uid: int) -> list[HeaderNode]:
    """The nodes reachable from the root, depth first; a uid reached twice, a missing
    child or a tree past btlog's bounds is damage."""
    if root_uid not in by_uid:
        raise _Damaged(0, f"the root uid {root_uid} is not among the nodes")
    bound = limits.current().max_nodes
    order: list[HeaderNode] = []
    seen: set[int] = set()
    stack = [(root_uid, 0)]
    while stack:
        uid, depth = stack.pop()
        node = by_uid.get(uid)
        if node is None or uid in seen:
            raise _Damaged(0, f"node {uid} is {'missing' if node is None else 'reached twice'}")
        if depth > limits.MAX_DEPTH or len(order) >= bound:
            raise _Damaged(0, "the tree is deeper or larger than btlog's bounds")
        seen.add(uid)
        order.append(node)
        stack.extend((child, depth + 1) for child in reversed(node.children))
    return order


# -- the tree ---------------------------------------------------------------------------------
def header_xml(log: FblLog, registry: Registry | None) -> bytes:
    """The header's tree as BT.CPP 3 XML (no ``BTCPP_format``): each SubTree instance's
    nodes as a ``<BehaviorTree>`` of its ID, types btlog does not know declared in a
    ``<TreeNodesModel>`` with the header's kinds and ports."""
    known = registry or Registry()
    root = etree.Element("root")
    definitions: dict[str, bytes] = {}
    by_uid = {node.uid: node for node in log.nodes}
    ids = {n.name for n in log.nodes if n.type in SUBTREES}
    main = next(
        f"MainTree{i or ''}" for i in range(len(ids) + 1) if f"MainTree{i or ''}" not in ids
    )
    root.set("main_tree_to_execute", main)

    def element(node: HeaderNode, parent: etree._Element) -> None:
        if node.type in SUBTREES:
            etree.SubElement(parent, node.type, ID=node.name)
            definition = etree.Element("BehaviorTree", ID=node.name)
            for child in node.children:
                element(by_uid[child], definition)
            text = etree.tostring(definition)
            if definitions.setdefault(node.name, text) != text:
                raise SourceError(
                    f"{log.file}: two SubTrees {node.name!r} hold different trees; "
                    "give the tree file with --tree"
                )
            return
        kind = KINDS.get(log.kinds.get(node.type, 0))
        if kind is None or kind == "SubTree":
            count = len(node.children)
            kind = "Action" if count == 0 else "Decorator" if count == 1 else "Control"
        item = etree.SubElement(parent, kind, ID=node.type)
        if node.name != node.type:  # BT.CPP 3 names a nameless node by its ID as written
            item.set("name", node.name)
        for port, value in node.ports:
            item.set(port, value)
        for child in node.children:
            element(by_uid[child], item)

    try:
        main_tree = etree.SubElement(root, "BehaviorTree", ID=main)
        element(log.nodes[0], main_tree)
        for text in definitions.values():
            root.append(etree.fromstring(text))
        model = etree.SubElement(root, "TreeNodesModel")
        for type_id in sorted({n.type for n in log.nodes} - set(SUBTREES)):
            if known.get(type_id) is not None:
                continue
            tag = KINDS.get(log.kinds.get(type_id, 0), "Action")
            declared = etree.SubElement(model, "SubTree" if tag == "SubTree" else tag, ID=type_id)
            for port, direction in log.ports.get(type_id, []):
                etree.SubElement(declared, DIRECTIONS.get(direction, "input_port"), name=port)
    except ValueError as error:  # a name or port XML cannot hold
        raise SourceError(
            f"{log.file}: the header's tree cannot be written as XML ({error})"
        ) from None
    return etree.tostring(root, xml_declaration=True, encoding="utf-8")


def fbl_tree(log: FblLog, tree_file: str | os.PathLike | None, registry: Registry | None) -> Tree:
    """The run's tree: the header's, or ``tree_file`` checked against it."""
    where = f"{log.file} (header)"
    try:
        own = load_tree_text(header_xml(log, registry), registry, file=where, accept_unknown=True)
    except TreeError as error:
        raise SourceError(f"the tree in the log: {error}") from None
    nodes = list(own)
    if len(nodes) != len(log.nodes) or any(
        h.name not in logged_names(n) or n.uid != i
        for i, (n, h) in enumerate(zip(nodes, log.nodes, strict=False), 1)
    ):
        raise SourceError(f"{where}: the tree rebuilt from the header differs from it")
    if tree_file is None:
        return own
    try:
        tree = load_tree(tree_file, registry, accept_unknown=True)
    except TreeError as error:
        raise SourceError(str(error)) from None
    check_same_tree(tree, own, os.fspath(tree_file))
    return tree


def import_fbl(
    path: str | os.PathLike,
    output: str | os.PathLike,
    tree_file: str | os.PathLike | None = None,
    registry: Registry | None = None,
    tick_gap_ns: int = DEFAULT_TICK_GAP_NS,
) -> BuildResult:
    """Import a ``.fbl`` file into the recording ``output``."""
    log = read_fbl(path)
    tree = fbl_tree(log, tree_file, registry)
    uids = {node.uid: index for index, node in enumerate(log.nodes, 1)}

    def changes() -> Iterator[tuple[int, int, Status, Status]]:
        """The transitions with btlog's uids, read from the file (each pass anew)."""
        for index, (t_us, uid, prev, new) in enumerate(log.transitions()):
            if uid not in uids:
                offset = log.records_offset + index * RECORD.size
                raise SourceError(f"{log.file}: byte {offset}: node uid {uid} is not in the header")
            yield t_us, uids[uid], prev, new

    # three passes over the file, none holding the transitions: the state the log began
    # in, the changes it leaves out, then the recording
    first: dict[int, Status] = {i: Status(n.status) for i, n in enumerate(log.nodes, 1)}
    seen: set[int] = set()
    start_us: int | None = None
    for t_us, uid, prev, _new in changes():
        start_us = t_us if start_us is None else start_us
        if uid not in seen:
            seen.add(uid)
            first[uid] = prev
    began = state_at_first_entry(tree, first)
    start_us = start_us or 0
    warnings: list[str] = []
    started = wall_start(start_us, log.file, warnings)
    if len(log) and start_us < _EPOCH_LIKE_US:
        warnings.append(
            f"{log.file}: the logger's times are relative (its first transition at "
            f"{start_us} µs): the run's wall-clock start is unknown"
        )
    omitted = omitted_changes(((u, p, n) for _t, u, p, n in changes()), began)
    metadata = {"mid_run": MID_RUN} if began else {}
    if omitted:
        metadata["omitted"] = f"{omitted} {OMITTED}"
    source = Source.of_file(FORMAT, path, records=len(log), nodes=len(log.nodes))
    attachments = [("btcpp-v3-tree.xml", header_xml(log, registry))]
    if tree_file is not None:
        attachments.append((Path(tree_file).name, Path(tree_file).read_bytes()))
    builder = RecordingBuilder(output, tree, source, started_at=started, attachments=attachments,
                               metadata=metadata, tick_gap_ns=tick_gap_ns)  # fmt: skip
    builder.warnings.extend(warnings)
    try:
        if began:
            count = builder.begin_mid_run(began)
            builder.warnings.append(f"{log.file}: {MID_RUN} ({count} nodes not IDLE)")
        for t_us, uid, prev, new in changes():
            builder.logged((t_us - start_us) * 1000, uid, prev, new)
    except BaseException:
        builder.close()
        Path(output).unlink(missing_ok=True)
        raise
    if omitted:
        builder.warnings.append(f"{log.file}: {omitted} {OMITTED}")
    if log.trailing:
        builder.warnings.append(
            f"{log.file}: the file ends inside a transition ({log.trailing} of 12 bytes); "
            f"imported the {len(log)} whole transitions"
        )
    return builder.close()
