"""Compare two sequences with the O(NP) algorithm of Wu, Manber, Myers and Miller (1990).

The edit distance counts the deletions (items only in ``A``) and insertions (items only
in ``B``) that turn ``A`` into ``B``; what is left is a longest common subsequence. The
algorithm walks the edit graph diagonal by diagonal (``k = y - x``), keeping for each
diagonal only its furthest-reaching point ``fp[k]``, and grows the number ``p`` of steps
taken away from the target diagonal ``Δ = N - M`` until ``fp[Δ] == N``. That costs
``O((M + N) · P)``: fast when the sequences are alike, however long they are.

To recover the alignment, each ``fp[k]`` also stores the snake it ended with, linked to
the neighbour it came from; walking those links back yields the path. Within a gap
between matched runs, deletions are listed before insertions (still optimal, and stable).
See docs/design.md, "Divergence".
"""

from __future__ import annotations

from collections.abc import Hashable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

__all__ = [
    "AlignedPair",
    "Alignment",
    "Comparison",
    "TooCostly",
    "compare",
    "edit_distance",
]

Op = Literal["equal", "delete", "insert"]


@dataclass(frozen=True)
class AlignedPair:
    """One step of an alignment between sequences ``A`` and ``B``.

    ``op`` is ``"equal"`` (``A[a_index] == B[b_index]``), ``"delete"`` (the item exists
    only in ``A``; ``b_index``/``b_item`` are ``None``) or ``"insert"`` (the item exists
    only in ``B``; ``a_index``/``a_item`` are ``None``).
    """

    op: Op
    a_index: int | None
    b_index: int | None
    a_item: Any = None
    b_item: Any = None


@dataclass(frozen=True)
class Alignment:
    """An optimal alignment of ``A`` and ``B``: an ordered tuple of :class:`AlignedPair`.

    Reading the ``equal`` and ``delete`` pairs in order yields ``A``; reading the
    ``equal`` and ``insert`` pairs in order yields ``B``.
    """

    ops: tuple[AlignedPair, ...] = ()

    def __iter__(self) -> Iterator[AlignedPair]:
        """Iterate over the aligned pairs in order."""
        return iter(self.ops)

    def __len__(self) -> int:
        """Return the number of aligned pairs."""
        return len(self.ops)


@dataclass(frozen=True)
class Comparison:
    """Result of :func:`compare`: distance, longest common subsequence and alignment.

    ``edit_distance`` counts insertions plus deletions (no substitutions), so
    ``edit_distance == len(a) + len(b) - 2 * lcs_length``.
    """

    edit_distance: int
    lcs: tuple[Any, ...]
    lcs_length: int
    alignment: Alignment

    @property
    def deleted(self) -> list[tuple[int, Any]]:
        """Items only in ``A``, as ``(a_index, item)`` pairs in index order."""
        return [
            (p.a_index, p.a_item)
            for p in self.alignment.ops
            if p.op == "delete" and p.a_index is not None
        ]

    @property
    def inserted(self) -> list[tuple[int, Any]]:
        """Items only in ``B``, as ``(b_index, item)`` pairs in index order."""
        return [
            (p.b_index, p.b_item)
            for p in self.alignment.ops
            if p.op == "insert" and p.b_index is not None
        ]

    @property
    def identical(self) -> bool:
        """True when both sequences are equal (distance 0)."""
        return self.edit_distance == 0


# A path node: (parent node, x, y, snake length). The snake starts at (x, y) in the
# edit graph; the single edit that led there from the parent's snake end is implied.
_Node = tuple[Any, int, int, int]


class TooCostly(Exception):
    """The O(NP) search would keep more path nodes than the ``budget`` given to it."""


def _onp(
    a: Sequence[Hashable], b: Sequence[Hashable], budget: int | None = None
) -> tuple[int, _Node]:
    """Run the O(NP) search on ``a`` (length M) and ``b`` (length N), requiring M <= N.

    Returns the edit distance and the last node of the linked path that reaches
    ``(M, N)``; raises ``TooCostly`` before keeping more than ``budget`` path nodes.
    """
    m, n = len(a), len(b)
    assert m <= n
    delta = n - m
    offset = m + 1  # fp index of diagonal k is k + offset; k ranges over -(m+1) .. n+1
    fp = [-1] * (m + n + 3)
    # nodes[k + offset]: path node whose snake ends at the furthest point of diagonal k.
    nodes: list[_Node | None] = [None] * (m + n + 3)

    def advance(k: int) -> None:
        """Compute fp[k] from its neighbours, follow the snake, and record a node."""
        i = k + offset
        below = fp[i - 1] + 1  # reach diagonal k by an insertion from diagonal k - 1
        right = fp[i + 1]  # reach diagonal k by a deletion from diagonal k + 1
        if below > right:
            y, parent = below, nodes[i - 1]
        else:
            y, parent = right, nodes[i + 1]
        x = y - k
        x0, y0 = x, y
        while x < m and y < n and a[x] == b[y]:
            x += 1
            y += 1
        fp[i] = y
        nodes[i] = (parent, x0, y0, y - y0)

    p = -1
    kept = 0
    while fp[delta + offset] != n:
        p += 1
        kept += delta + 2 * p + 1
        if budget is not None and kept > budget:
            raise TooCostly(f"more than {budget} path nodes")
        for k in range(-p, delta):
            advance(k)
        for k in range(delta + p, delta, -1):
            advance(k)
        advance(delta)
    last = nodes[delta + offset]
    assert last is not None
    return delta + 2 * p, last


def _raw_ops(last: _Node) -> list[tuple[Op, int | None, int | None]]:
    """Turn the linked chain of nodes ending at ``last`` into ``(op, x, y)`` steps."""
    chain: list[_Node] = []
    node: _Node | None = last
    while node is not None:
        chain.append(node)
        node = node[0]
    chain.reverse()

    steps: list[tuple[Op, int | None, int | None]] = []
    for parent, x, y, length in chain:
        if parent is not None:
            _, _, py, plen = parent
            if y == py + plen:  # same y as the parent's snake end: x moved, a deletion
                steps.append(("delete", x - 1, None))
            else:  # y moved by one: an insertion
                steps.append(("insert", None, y - 1))
        steps.extend(("equal", x + j, y + j) for j in range(length))
    return steps


def _order_gaps(
    steps: list[tuple[Op, int | None, int | None]],
) -> list[tuple[Op, int | None, int | None]]:
    """Within each run of edits between matches, put deletions before insertions."""
    ordered: list[tuple[Op, int | None, int | None]] = []
    deletes: list[tuple[Op, int | None, int | None]] = []
    inserts: list[tuple[Op, int | None, int | None]] = []
    for step in steps:
        if step[0] == "delete":
            deletes.append(step)
        elif step[0] == "insert":
            inserts.append(step)
        else:
            ordered.extend(deletes)
            ordered.extend(inserts)
            deletes.clear()
            inserts.clear()
            ordered.append(step)
    ordered.extend(deletes)
    ordered.extend(inserts)
    return ordered


def compare(a: Sequence[Hashable], b: Sequence[Hashable], budget: int | None = None) -> Comparison:
    """Compare sequences ``a`` and ``b`` with the O(NP) algorithm.

    Returns a :class:`Comparison` with the insert/delete edit distance, one longest
    common subsequence and the corresponding optimal alignment ("delete" = only in
    ``a``, "insert" = only in ``b``). Runs in ``O((len(a) + len(b)) * P)`` time, where
    ``P`` is the number of deletions (of the shorter-to-longer script), and keeps
    ``O((P + 1) * (|len(a) - len(b)| + P + 1))`` path nodes in memory: ``TooCostly``
    is raised before more than ``budget`` of them are kept.
    """
    a = a if isinstance(a, Sequence) else list(a)
    b = b if isinstance(b, Sequence) else list(b)
    swapped = len(a) > len(b)
    short, long_ = (b, a) if swapped else (a, b)
    distance, last = _onp(short, long_, budget)
    steps = _raw_ops(last)
    if swapped:  # x indexed the original b, y the original a: swap roles back
        flip: dict[Op, Op] = {"equal": "equal", "delete": "insert", "insert": "delete"}
        steps = [(flip[op], y, x) for op, x, y in steps]
    steps = _order_gaps(steps)

    pairs = tuple(
        AlignedPair(
            op=op,
            a_index=i,
            b_index=j,
            a_item=a[i] if i is not None else None,
            b_item=b[j] if j is not None else None,
        )
        for op, i, j in steps
    )
    lcs = tuple(pair.a_item for pair in pairs if pair.op == "equal")
    return Comparison(
        edit_distance=distance,
        lcs=lcs,
        lcs_length=len(lcs),
        alignment=Alignment(pairs),
    )


def edit_distance(a: Sequence[Hashable], b: Sequence[Hashable]) -> int:
    """Return the insert/delete edit distance between ``a`` and ``b`` (O(NP) algorithm)."""
    a = a if isinstance(a, Sequence) else list(a)
    b = b if isinstance(b, Sequence) else list(b)
    short, long_ = (b, a) if len(a) > len(b) else (a, b)
    return _onp(short, long_)[0]
