"""A writer of BehaviorTree.CPP v3 ``FileLogger`` files (``.fbl``), for the tests.

It does what BT.CPP 3.8's ``FileLogger`` does (``src/loggers/bt_file_logger.cpp``,
``flatbuffers/bt_flatbuffer_helper.h``): an i32 size, a flatbuffer built by
``CreateFlatbuffersBehaviorTree``, then one 12-byte ``SerializeTransition`` per status
change. ``Builder`` is the algorithm of the ``flatbuffers::FlatBufferBuilder`` BT.CPP 3
vendors (back to front, scalars aligned to their size, each table's vtable written in
front of it and shared with an identical earlier one), and ``header`` calls it in the
helper's order, the arguments of each ``Create…`` call evaluated right to left as GCC
does, so the bytes are those BT.CPP writes (checked against a real file: the optional
test in ``tests/test_import_fbl.py``).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path


class Builder:
    """``flatbuffers::FlatBufferBuilder``, the parts the logger uses."""

    def __init__(self) -> None:
        self.buf = bytearray()  # the buffer's tail: it grows at the front
        self.minalign = 1
        self.vtables: list[int] = []
        self.fields: list[tuple[int, int]] = []  # (offset of the value, vtable slot)
        self.max_voffset = 0
        self.table_start = 0

    def size(self) -> int:
        return len(self.buf)

    def _pad(self, count: int) -> None:
        self.buf[0:0] = bytes(count)

    def align(self, size: int) -> None:
        self.minalign = max(self.minalign, size)
        self._pad((-len(self.buf)) % size)

    def prealign(self, length: int, alignment: int) -> None:
        self.minalign = max(self.minalign, alignment)
        self._pad((-(len(self.buf) + length)) % alignment)

    def push(self, fmt: str, value: int) -> int:
        self.align(struct.calcsize(fmt))
        self.buf[0:0] = struct.pack(fmt, value)
        return self.size()

    def refer_to(self, offset: int) -> int:
        self.align(4)
        return self.size() - offset + 4

    def string(self, text: str) -> int:
        data = text.encode()
        self.prealign(len(data) + 1, 4)
        self.buf[0:0] = data + b"\0"
        return self.push("<I", len(data))

    def scalars(self, fmt: str, values: Sequence[int]) -> int:
        width = struct.calcsize(fmt)
        self.prealign(len(values) * width, 4)
        self.prealign(len(values) * width, width)
        self.buf[0:0] = b"".join(struct.pack(fmt, v) for v in values)
        return self.push("<I", len(values))

    def offsets(self, values: Sequence[int]) -> int:
        self.prealign(len(values) * 4, 4)
        for value in reversed(values):
            self.push("<I", self.refer_to(value))
        return self.push("<I", len(values))

    def start_table(self) -> None:
        self.fields, self.max_voffset = [], 0
        self.table_start = self.size()

    def add(self, slot: int, fmt: str, value: int, default: int = 0) -> None:
        if value != default:
            self.fields.append((self.push(fmt, value), slot))
            self.max_voffset = max(self.max_voffset, slot)

    def add_offset(self, slot: int, offset: int) -> None:
        if offset:
            self.add(slot, "<I", self.refer_to(offset))

    def end_table(self) -> int:
        location = self.push("<i", 0)
        size = max(self.max_voffset + 2, 4)
        vtable = bytearray(size)
        struct.pack_into("<HH", vtable, 0, size, location - self.table_start)
        for offset, slot in self.fields:
            struct.pack_into("<H", vtable, slot, location - offset)
        self.buf[0:0] = vtable
        use = self.size()
        for earlier in self.vtables:
            at = self.size() - earlier
            if (
                self.buf[at : at + size] == vtable
                and struct.unpack_from("<H", self.buf, at)[0] == size
            ):
                use = earlier
                del self.buf[: self.size() - location]
                break
        if use == self.size():
            self.vtables.append(use)
        struct.pack_into("<i", self.buf, self.size() - location, use - location)
        self.fields = []
        return location

    def finish(self, root: int) -> bytes:
        self.prealign(4, self.minalign)
        self.push("<I", self.refer_to(root))
        return bytes(self.buf)


#: ``Serialization::NodeType``.
UNDEFINED, ACTION, CONDITION, CONTROL, DECORATOR, SUBTREE = range(6)


@dataclass
class Node:
    """A node of the tree the logger sees: its uid (BT.CPP 3's global counter), names,
    status when the logger starts, ports as configured, and children."""

    uid: int
    name: str
    type: str
    ports: list[tuple[str, str]] = field(default_factory=list)
    children: list[Node] = field(default_factory=list)
    status: int = 0

    def walk(self) -> Iterable[Node]:
        yield self
        for child in self.children:
            yield from child.walk()


@dataclass
class Model:
    """A type's manifest: its kind and ports ``(name, direction, type, description)``."""

    type: str
    kind: int
    ports: list[tuple[str, int, str, str]] = field(default_factory=list)


def header(root: Node, models: Sequence[Model]) -> bytes:
    """``CreateFlatbuffersBehaviorTree(builder, tree)`` then ``builder.Finish``."""
    b = Builder()
    nodes = []
    for node in root.walk():  # applyRecursiveVisitor: pre-order
        ports = []
        for name, value in node.ports:  # CreatePortConfigDirect
            name_at, value_at = b.string(name), b.string(value)
            b.start_table()
            b.add_offset(6, value_at)  # add_remap
            b.add_offset(4, name_at)  # add_port_name
            ports.append(b.end_table())
        # CreateTreeNode(builder, uid, CreateVector(children), status, CreateString(name),
        # CreateString(registration), CreateVector(ports)): arguments right to left
        ports_at = b.offsets(ports)
        type_at = b.string(node.type)
        name_at = b.string(node.name)
        children_at = b.scalars("<H", [c.uid for c in node.children])
        b.start_table()
        b.add_offset(14, ports_at)
        b.add_offset(12, type_at)
        b.add_offset(10, name_at)
        b.add_offset(6, children_at)
        b.add(4, "<H", node.uid)
        b.add(8, "<b", node.status)
        nodes.append(b.end_table())
    models_at = []
    for model in models:
        port_models = []
        for name, direction, type_info, description in model.ports:
            # CreatePortModel(builder, CreateString(name), direction, CreateString(type),
            # CreateString(description)): right to left
            description_at, type_at = b.string(description), b.string(type_info)
            name_at = b.string(name)
            b.start_table()
            b.add_offset(10, description_at)
            b.add_offset(8, type_at)
            b.add_offset(4, name_at)
            b.add(6, "<b", direction)
            port_models.append(b.end_table())
        ports_at = b.offsets(port_models)
        type_at = b.string(model.type)
        b.start_table()
        b.add_offset(8, ports_at)
        b.add_offset(4, type_at)
        b.add(6, "<b", model.kind)
        models_at.append(b.end_table())
    node_models_at = b.offsets(models_at)
    nodes_at = b.offsets(nodes)
    b.start_table()
    b.add_offset(8, node_models_at)
    b.add_offset(6, nodes_at)
    b.add(4, "<H", root.uid)
    return b.finish(b.end_table())


def transition(t_us: int, uid: int, prev: int, status: int) -> bytes:
    """``SerializeTransition``: seconds and microseconds each written as an int64, the
    second over the first's high word, then the uid and the two statuses."""
    buffer = bytearray(12)
    struct.pack_into("<q", buffer, 0, t_us // 1_000_000)
    struct.pack_into("<q", buffer, 4, t_us % 1_000_000)
    struct.pack_into("<Hbb", buffer, 8, uid, prev, status)
    return bytes(buffer)


def write_fbl(
    path: Path, root: Node, models: Sequence[Model], changes: Iterable[tuple[int, int, int, int]]
) -> bytes:
    """Write ``path`` as ``FileLogger`` does: the header's size, the header, then each
    change ``(µs since the epoch, uid, previous, status)``; returns the bytes."""
    head = header(root, models)
    data = struct.pack("<i", len(head)) + head + b"".join(transition(*c) for c in changes)
    path.write_bytes(data)
    return data


def read_header(buffer: bytes) -> tuple[Node, list[Model]]:
    """The tree and models of a header, as ``header`` takes them (read with btlog's
    bounds-checked reader), to write it again."""
    from btlog.sources.btcpp_fbl import _Buffer

    data = _Buffer(buffer)
    top = data.table(data.follow(0))
    nodes: dict[int, tuple[list[int], Node]] = {}
    for t in top.tables(1):
        ports = [(p.string(0), p.string(1)) for p in t.tables(5)]
        node = Node(t.scalar(0, "<H"), t.string(3), t.string(4), ports, [], t.scalar(2, "<b"))
        nodes[node.uid] = (t.scalars(1, "<H"), node)
    for children, node in nodes.values():
        node.children = [nodes[uid][1] for uid in children]
    models = []
    for m in top.tables(2):
        ports_ = [(p.string(0), p.scalar(1, "<b"), p.string(2), p.string(3)) for p in m.tables(2)]
        models.append(Model(m.string(0), m.scalar(1, "<b"), ports_))
    return nodes[top.scalar(0, "<H")][1], models
