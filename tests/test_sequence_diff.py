"""Tests for the O(NP) sequence comparison in :mod:`btlog.algorithms.sequence_diff`."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from btlog.algorithms.sequence_diff import (
    AlignedPair,
    Alignment,
    Comparison,
    compare,
    edit_distance,
)

TAXI_OPTIMAL = [
    "move right",
    "move right",
    "move right",
    "move up",
    "move up",
    "move left",
    "pick up",
]
TAXI_HUMAN = ["move right", "move right", "move up", "move up", "pick up"]

sequences = st.lists(st.sampled_from("abcd"), max_size=12)


def dp_distance(a: list, b: list) -> int:
    """Brute-force insert/delete edit distance by the classic O(MN) dynamic programme."""
    m, n = len(a), len(b)
    table = [[0] * (n + 1) for _ in range(m + 1)]
    for i in range(m + 1):
        for j in range(n + 1):
            if i == 0 or j == 0:
                table[i][j] = i + j
            elif a[i - 1] == b[j - 1]:
                table[i][j] = table[i - 1][j - 1]
            else:
                table[i][j] = 1 + min(table[i - 1][j], table[i][j - 1])
    return table[m][n]


def is_subsequence(sub: tuple | list, seq: list) -> bool:
    """True when ``sub`` occurs in ``seq`` in order (not necessarily contiguously)."""
    it = iter(seq)
    return all(any(item == other for other in it) for item in sub)


def check_alignment(a: list, b: list, result: Comparison) -> None:
    """Assert that the alignment is well formed and reproduces both sequences."""
    ops = result.alignment.ops
    rebuilt_a = [p.a_item for p in ops if p.op in ("equal", "delete")]
    rebuilt_b = [p.b_item for p in ops if p.op in ("equal", "insert")]
    assert rebuilt_a == list(a)
    assert rebuilt_b == list(b)

    a_indices = [p.a_index for p in ops if p.a_index is not None]
    b_indices = [p.b_index for p in ops if p.b_index is not None]
    assert a_indices == list(range(len(a)))
    assert b_indices == list(range(len(b)))

    for pair in ops:
        assert pair.op in ("equal", "delete", "insert")
        if pair.op == "equal":
            assert pair.a_index is not None and pair.b_index is not None
            assert pair.a_item == a[pair.a_index] == b[pair.b_index] == pair.b_item
        elif pair.op == "delete":
            assert pair.a_index is not None and pair.b_index is None
            assert pair.a_item == a[pair.a_index] and pair.b_item is None
        else:
            assert pair.a_index is None and pair.b_index is not None
            assert pair.b_item == b[pair.b_index] and pair.a_item is None

    edits = sum(1 for p in ops if p.op != "equal")
    assert edits == result.edit_distance
    assert tuple(p.a_item for p in ops if p.op == "equal") == result.lcs


def check_gap_order(result: Comparison) -> None:
    """Within every gap between matches, all deletions precede all insertions."""
    seen_insert = False
    for pair in result.alignment.ops:
        if pair.op == "equal":
            seen_insert = False
        elif pair.op == "insert":
            seen_insert = True
        else:
            assert not seen_insert, "deletion reported after an insertion of the same gap"


@settings(max_examples=400)
@given(sequences, sequences)
def test_distance_matches_dynamic_programming(a: list, b: list) -> None:
    result = compare(a, b)
    assert result.edit_distance == dp_distance(a, b)
    assert edit_distance(a, b) == result.edit_distance


@settings(max_examples=300)
@given(sequences, sequences)
def test_lcs_length_and_subsequence(a: list, b: list) -> None:
    result = compare(a, b)
    assert result.lcs_length == len(result.lcs)
    assert 2 * result.lcs_length == len(a) + len(b) - result.edit_distance
    assert is_subsequence(result.lcs, a)
    assert is_subsequence(result.lcs, b)


@settings(max_examples=300)
@given(sequences, sequences)
def test_alignment_reconstructs_both_sequences(a: list, b: list) -> None:
    result = compare(a, b)
    check_alignment(a, b, result)
    check_gap_order(result)
    assert result.deleted == [(p.a_index, p.a_item) for p in result.alignment if p.op == "delete"]
    assert result.inserted == [(p.b_index, p.b_item) for p in result.alignment if p.op == "insert"]
    assert result.identical == (a == b)


@settings(max_examples=300)
@given(sequences, sequences)
def test_distance_is_symmetric(a: list, b: list) -> None:
    forward, backward = compare(a, b), compare(b, a)
    assert forward.edit_distance == backward.edit_distance
    assert forward.lcs_length == backward.lcs_length
    assert len(forward.deleted) == len(backward.inserted)
    assert len(forward.inserted) == len(backward.deleted)


@given(sequences)
def test_sequence_against_itself(a: list) -> None:
    result = compare(a, a)
    assert result.edit_distance == 0
    assert result.identical
    assert result.lcs == tuple(a)
    assert all(p.op == "equal" and p.a_index == p.b_index for p in result.alignment)


def test_identical_sequences() -> None:
    result = compare(TAXI_OPTIMAL, list(TAXI_OPTIMAL))
    assert result.edit_distance == 0
    assert result.identical
    assert result.lcs == tuple(TAXI_OPTIMAL)
    assert result.lcs_length == len(TAXI_OPTIMAL)
    assert result.deleted == [] and result.inserted == []


def test_both_empty() -> None:
    result = compare([], [])
    assert result == Comparison(edit_distance=0, lcs=(), lcs_length=0, alignment=Alignment(()))
    assert result.identical
    assert edit_distance([], []) == 0


def test_one_side_empty() -> None:
    only_b = compare([], ["x", "y"])
    assert only_b.edit_distance == 2
    assert only_b.lcs == ()
    assert only_b.inserted == [(0, "x"), (1, "y")]
    assert only_b.deleted == []
    assert only_b.alignment.ops == (
        AlignedPair("insert", None, 0, None, "x"),
        AlignedPair("insert", None, 1, None, "y"),
    )

    only_a = compare(["x", "y"], [])
    assert only_a.edit_distance == 2
    assert only_a.deleted == [(0, "x"), (1, "y")]
    assert only_a.inserted == []
    assert not only_a.identical


def test_taxi_optimal_versus_human_expectation() -> None:
    result = compare(TAXI_OPTIMAL, TAXI_HUMAN)
    assert result.edit_distance == 2
    assert edit_distance(TAXI_OPTIMAL, TAXI_HUMAN) == 2
    assert result.lcs == tuple(TAXI_HUMAN)
    assert result.lcs_length == 5
    assert result.inserted == []
    assert sorted(item for _, item in result.deleted) == ["move left", "move right"]
    assert (5, "move left") in result.deleted
    check_alignment(TAXI_OPTIMAL, TAXI_HUMAN, result)

    reverse = compare(TAXI_HUMAN, TAXI_OPTIMAL)
    assert reverse.edit_distance == 2
    assert reverse.lcs == tuple(TAXI_HUMAN)
    assert reverse.deleted == []
    assert (5, "move left") in reverse.inserted


def test_swapped_pair_of_actions() -> None:
    a = ["move up", "pick up", "move left", "drop off"]
    b = ["move up", "move left", "pick up", "drop off"]
    result = compare(a, b)
    assert result.edit_distance == 2
    assert result.lcs_length == 3
    assert len(result.deleted) == 1 and len(result.inserted) == 1
    assert result.deleted[0][1] == result.inserted[0][1]
    check_alignment(a, b, result)


def test_divergent_block_reports_deletions_before_insertions() -> None:
    a = ["s", "a1", "a2", "a3", "e"]
    b = ["s", "b1", "b2", "e"]
    result = compare(a, b)
    assert result.edit_distance == 5
    assert [p.op for p in result.alignment] == [
        "equal",
        "delete",
        "delete",
        "delete",
        "insert",
        "insert",
        "equal",
    ]
    assert result.deleted == [(1, "a1"), (2, "a2"), (3, "a3")]
    assert result.inserted == [(1, "b1"), (2, "b2")]


def test_accepts_tuples_strings_and_hashable_items() -> None:
    assert edit_distance("kitten", "sitting") == dp_distance(list("kitten"), list("sitting"))
    result = compare((1, (2, 3), 4), [1, 4, (2, 3)])
    assert result.edit_distance == 2
    check_alignment([1, (2, 3), 4], [1, 4, (2, 3)], result)


@st.composite
def similar_pairs(draw: st.DrawFn) -> tuple[list, list]:
    """A longer base sequence and a copy with a few random insertions and deletions."""
    base = draw(st.lists(st.sampled_from("abcdefgh"), min_size=5, max_size=40))
    edited = list(base)
    for _ in range(draw(st.integers(min_value=0, max_value=6))):
        if edited and draw(st.booleans()):
            del edited[draw(st.integers(min_value=0, max_value=len(edited) - 1))]
        else:
            position = draw(st.integers(min_value=0, max_value=len(edited)))
            edited.insert(position, draw(st.sampled_from("abcdefghxyz")))
    return base, edited


@settings(max_examples=200)
@given(similar_pairs())
def test_similar_longer_sequences(pair: tuple[list, list]) -> None:
    a, b = pair
    for left, right in ((a, b), (b, a)):
        result = compare(left, right)
        assert result.edit_distance == dp_distance(left, right)
        check_alignment(left, right, result)
        check_gap_order(result)
