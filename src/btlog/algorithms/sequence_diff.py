"""Compare two action sequences with the O(NP) algorithm of Wu, Manber, Myers and Miller.

Reference: S. Wu, U. Manber, G. Myers and W. Miller, "An O(NP) Sequence Comparison
Algorithm", Information Processing Letters 35(6), 1990.

The problem
-----------
Given two sequences ``A`` (length ``M``) and ``B`` (length ``N``), find the smallest
number of single-item *deletions* (an item only in ``A``) and *insertions* (an item
only in ``B``) that turn ``A`` into ``B``. There are no substitutions: replacing one
item by another costs one deletion plus one insertion. Equivalently we look for a
longest common subsequence (LCS): ``distance = M + N - 2 * len(LCS)``.

The edit graph
--------------
Picture a grid whose point ``(x, y)`` means "the first ``x`` items of ``A`` and the
first ``y`` items of ``B`` have been accounted for". From ``(x, y)`` one may step

* right, to ``(x + 1, y)``: delete ``A[x]`` (cost 1);
* down, to ``(x, y + 1)``: insert ``B[y]`` (cost 1);
* diagonally, to ``(x + 1, y + 1)``, only when ``A[x] == B[y]`` (cost 0).

A cheapest path from ``(0, 0)`` to ``(M, N)`` is an optimal alignment. A maximal run of
free diagonal steps is called a *snake*: after any edit it always pays to follow the
snake as far as it goes, because matching items never hurt.

Diagonals and furthest-reaching points
--------------------------------------
Number the diagonals of the grid by ``k = y - x``. The path starts on diagonal ``0`` and
must end on diagonal ``Δ = N - M``. An insertion moves the path one diagonal up
(``k + 1``), a deletion one diagonal down (``k - 1``), and a snake stays on its diagonal.

Instead of filling the whole ``M × N`` table (as the classic dynamic programme does),
the algorithm only remembers, for every diagonal ``k``, the *furthest-reaching point*
``fp[k]``: the largest ``y`` reachable on diagonal ``k`` with the current budget of
edits. A point further along a diagonal is always at least as good as an earlier one
(anything the earlier point can still do, the later one can do as well), so this single
number per diagonal is all that must be kept.

Why P, and why ``N >= M``
-------------------------
Assume ``N >= M`` (otherwise swap the sequences; deletions and insertions swap roles).
Any path to diagonal ``Δ`` uses ``D`` deletions and ``D + Δ`` insertions, for some ``D``;
its cost is ``Δ + 2D``, so minimising the cost means minimising the deletions. Call a
step *away from* ``Δ`` a deletion taken below ``Δ`` or an insertion taken above it.
Excursions above ``Δ`` must come back, so their insertions are paid for by as many
deletions: a complete path has exactly ``D`` steps away from ``Δ``.

The algorithm searches in rounds ``p = 0, 1, 2, ...``; round ``p`` computes, for every
diagonal, the furthest point reachable with at most ``p`` steps away from ``Δ``. Such
a path can only visit diagonals ``-p .. Δ + p``, so round ``p`` updates just those,
each from its two neighbours::

    fp[k] = snake(k, max(fp[k - 1] + 1, fp[k + 1]))

(``fp[k - 1] + 1``: come from diagonal ``k - 1`` by an insertion; ``fp[k + 1]``: come
from diagonal ``k + 1`` by a deletion; then slide along the snake). Diagonals below
``Δ`` are swept upwards (``-p .. Δ - 1``), those above ``Δ`` downwards
(``Δ + p .. Δ + 1``), and ``Δ`` last. So when ``fp[k]`` is computed, its neighbour
farther from ``Δ`` has already been updated in round ``p`` (stepping from it towards
``Δ`` is free), while its neighbour nearer to ``Δ`` still holds its round ``p - 1``
value (stepping from it away from ``Δ`` uses up this round's extra away-step). The
snake on ``Δ`` itself is computed from two fresh neighbours.

The search stops in the first round ``P`` where ``fp[Δ] == N``; then the edit distance
is ``Δ + 2P``, and ``P`` is exactly the number of deletions of an optimal script. Each
round costs ``O(Δ + p)`` plus the snake lengths, which gives ``O((M + N) · P)`` time
overall: very fast when the sequences are similar, however long they are, which is
exactly the situation of "what the agent did" versus "what a human expected".

Recovering the alignment
------------------------
``fp`` alone only gives the distance. To recover the actual edit script, every time a
diagonal's furthest point is computed we also store a small node ``(parent, x, y,
length)``: the snake that starts at ``(x, y)`` and is ``length`` long, linked to the
node of the neighbouring diagonal it was reached from. The edit between two nodes (one
deletion or one insertion) is implied by where the parent's snake ended. Walking the
chain back from ``fp[Δ]`` yields the whole path. This keeps the time bound and costs
one node per evaluation of ``fp[k]``, i.e. ``O((P + 1) · (Δ + P + 1))`` nodes in the
worst case (at most ``O((M + N) · P)``), on top of the ``O(M + N)`` ``fp`` array.

Finally, within each gap between two matched runs, the deletions are reported before
the insertions (in index order), which gives a stable, readable diff; it is still an
optimal alignment because the matched items are unchanged.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

__all__ = [
    "AlignedPair",
    "Alignment",
    "Comparison",
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


def _onp(a: Sequence[Hashable], b: Sequence[Hashable]) -> tuple[int, _Node]:
    """Run the O(NP) search on ``a`` (length M) and ``b`` (length N), requiring M <= N.

    Returns the edit distance and the last node of the linked path that reaches
    ``(M, N)``.
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
    while fp[delta + offset] != n:
        p += 1
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


def compare(a: Sequence[Hashable], b: Sequence[Hashable]) -> Comparison:
    """Compare sequences ``a`` and ``b`` with the O(NP) algorithm.

    Returns a :class:`Comparison` with the insert/delete edit distance, one longest
    common subsequence and the corresponding optimal alignment ("delete" = only in
    ``a``, "insert" = only in ``b``). Runs in ``O((len(a) + len(b)) * P)`` time, where
    ``P`` is the number of deletions (of the shorter-to-longer script), and keeps
    ``O((P + 1) * (|len(a) - len(b)| + P + 1))`` path nodes in memory.
    """
    a = a if isinstance(a, Sequence) else list(a)
    b = b if isinstance(b, Sequence) else list(b)
    swapped = len(a) > len(b)
    short, long_ = (b, a) if swapped else (a, b)
    distance, last = _onp(short, long_)
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
