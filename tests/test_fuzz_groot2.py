"""Fuzzed Groot2 replies (``tests/fuzz_support.py``): the protocol's checks take any bytes
and either accept a reply of the protocol's shape or raise ``BadReply`` naming the
endpoint; and ``btlog attach`` fed odd replies by the fake publisher keeps every
transition the robot logged, or marks a gap where it could not."""

from __future__ import annotations

import struct
import tempfile
import time
from pathlib import Path

import msgpack
from hypothesis import given
from hypothesis import strategies as st

from btlog.sources.btcpp_records import RECORD_SIZE
from btlog.sources.groot2 import BadReply, check_reply, decode_blackboards, decode_transitions
from tests.fuzz_support import fuzz
from tests.groot2_support import FakePublisher
from tests.test_attach_faults import XML, Robot, assert_lost_only_in_gaps, attached, wait_polls

ENDPOINT = "tcp://robot:1667"
REQUEST = struct.pack("<BBI", 2, ord("t"), 0xC0FFEE)
REPLY_HEADER = REQUEST + bytes(range(16))
#: Reply parts: a right header, a near miss, or anything; then payloads.
HEADERS = st.sampled_from([REPLY_HEADER, REPLY_HEADER[:21], b"error", REQUEST]) | st.binary(
    max_size=30
)
PARTS = st.lists(st.binary(max_size=40), max_size=3).flatmap(
    lambda rest: HEADERS.map(lambda head: [head, *rest])
) | st.lists(st.binary(max_size=30), min_size=1, max_size=1)  # ZMQ: a frame at least


@given(reply=PARTS)
@fuzz(examples=150, seconds=3)
def test_any_reply_is_accepted_only_in_the_protocols_shape(reply: list[bytes]) -> None:
    try:
        tree_id, payload = check_reply(ENDPOINT, "t", REQUEST, reply)
    except BadReply as error:
        assert str(error).startswith(ENDPOINT)
        return
    assert len(reply) == 2 and reply[0][1:6] == REQUEST[1:] and len(reply[0]) == 22
    assert (tree_id, payload) == (reply[0][6:], reply[1])


@given(payload=st.binary(max_size=200))
@fuzz(examples=100, seconds=2)
def test_transitions_keep_every_whole_record_and_tell_the_cut(payload: bytes) -> None:
    reply = decode_transitions(payload)
    assert reply.records + payload[len(reply.records) :] == payload
    assert len(reply.records) % RECORD_SIZE == 0 and reply.cut == len(payload) % RECORD_SIZE


MSGPACK_VALUES = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(1 << 63), (1 << 64) - 1)
    | st.floats()
    | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner),
    max_leaves=12,
)


@given(value=MSGPACK_VALUES, noise=st.binary(max_size=30), use_noise=st.booleans())
@fuzz(examples=100, seconds=3)
def test_blackboard_replies_are_maps_of_maps_or_refused(value, noise, use_noise) -> None:
    payload = noise if use_noise else msgpack.packb(value)
    try:
        boards = decode_blackboards(ENDPOINT, payload)
    except BadReply as error:
        assert str(error).startswith(ENDPOINT)
        return
    assert isinstance(boards, dict)
    assert all(isinstance(board, dict) for board in boards.values())


def _crafted(parts: list[bytes], good_header: bool):
    return lambda header: [header, *parts[1:]] if good_header else parts


@given(
    replies=st.lists(st.tuples(PARTS, st.booleans()), min_size=1, max_size=3),
)
@fuzz(examples=10, seconds=15)
def test_attach_fed_odd_replies_loses_nothing_without_a_gap(replies) -> None:
    with tempfile.TemporaryDirectory(prefix="btlog-fuzz-groot2-") as folder:
        out = Path(folder) / "odd.mcap"
        with FakePublisher(XML) as publisher, attached(publisher, out) as attaching:
            robot = Robot(publisher)
            wait_polls(publisher, polls=3)
            publisher.craft("t", *(_crafted(parts, good) for parts, good in replies))
            wait_polls(publisher, polls=len(replies) + 3)
            robot.stop()
            time.sleep(0.05)
            result = attaching.finish()
        assert not result.gone, result.build.warnings
        assert_lost_only_in_gaps(publisher, out)
