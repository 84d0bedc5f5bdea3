"""The binary columns of schema version 3: what is packed is read back, by every reader.

Properties over random rows: ``pack_events``/``pack_ticks`` then the format's decoding
give the rows back (statuses as ``Status``), the scan locates every column where the
layout says, and a message of any other length is refused.
"""

from __future__ import annotations

import struct

import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from btlog.events import BlackboardWrite, StatusChange, TickRecord
from btlog.record import columns
from btlog.record import format as fmt
from btlog.status import Status

I64 = st.integers(-(2**63), 2**63 - 1)
STATUS = st.sampled_from(list(Status))
STATUS_ROW = st.tuples(
    st.integers(0, 2**63 - 1),
    I64,
    st.integers(0, 2**63 - 1),
    st.integers(1, 2**31 - 1),
    STATUS,
    STATUS,
)
WRITE_ROW = st.tuples(
    st.integers(0, 2**53),
    st.integers(-(2**53), 2**53),
    st.integers(0, 2**53),
    st.text(max_size=8),
    st.text(min_size=1, max_size=8),
    st.one_of(st.none(), st.integers(-(2**53), 2**53), st.text(max_size=20), st.booleans()),
    st.sampled_from(["int", "str", "bool", "null", "unset"]),
    st.one_of(st.none(), st.integers(1, 2**31 - 1)),
)
TICK_ROW = st.tuples(st.integers(0, 2**63 - 1), I64, I64, STATUS)


@settings(max_examples=150, deadline=None)
@given(
    st.integers(0, 2**63 - 1), st.lists(STATUS_ROW, max_size=60), st.lists(WRITE_ROW, max_size=8)
)
def test_an_events_message_reads_back_as_written(tick, status, writes):
    data = fmt.encode_events(fmt.EventsMessage(tick, status, [list(w) for w in writes]))
    start, end = columns.locate(data, 0, len(data)).writes
    assert start == columns.HEAD.size + columns.EVENT_ROW_BYTES * len(status)
    assert data[start:end] == (orjson.dumps([list(w) for w in writes]) if writes else b"")
    message = fmt.parse_events(data)
    assert message.tick == tick
    assert message.status == status
    assert all(type(row[4]) is Status and type(row[5]) is Status for row in message.status)
    assert message.writes == [list(w) for w in writes]
    events = fmt.decode_events(data)
    assert [e.seq for e in events] == sorted(
        [row[0] for row in status] + [row[0] for row in writes]
    )
    assert {e for e in events if type(e) is StatusChange} == {StatusChange(*r) for r in status}
    assert sum(type(e) is BlackboardWrite for e in events) == len(writes)


@settings(max_examples=150, deadline=None)
@given(st.lists(STATUS_ROW, min_size=1, max_size=40), st.integers(0, 5))
def test_the_scan_finds_each_column_where_the_layout_says(rows, offset):
    data = bytes(offset) + columns.pack_event_rows(7, rows, [])
    located = columns.locate(data, offset, len(data))
    assert located.count == len(rows) and located.tick == 7 and not located.teardown
    for index, ((name, code), (start, end)) in enumerate(
        zip(columns.EVENT_COLUMNS, located.columns, strict=True)
    ):
        values = struct.unpack(f"<{len(rows)}{code}", data[start:end])
        assert list(values) == [int(row[index]) for row in rows], name


@settings(max_examples=100, deadline=None)
@given(st.lists(TICK_ROW, max_size=40), st.booleans())
def test_a_ticks_message_reads_back_as_written(rows, teardown):
    data = columns.pack_ticks(rows, teardown)
    assert len(data) == columns.HEAD.size + columns.TICK_ROW_BYTES * len(rows)
    assert fmt.decode_ticks(data) == [TickRecord(*row, teardown) for row in rows]


@settings(max_examples=100, deadline=None)
@given(st.lists(STATUS_ROW, max_size=10), st.integers(-3, 3).filter(bool))
def test_a_message_of_another_length_is_refused(rows, change):
    data = columns.pack_event_rows(1, rows, [])
    damaged = data + bytes(change) if change > 0 else data[:change]
    with pytest.raises(ValueError, match=r"binary message|bytes long, expected"):
        fmt.parse_events(damaged)


def test_a_json_message_of_version_2_reads_as_before():
    data = b'{"tick":3,"status":[[0,5,3,2,"IDLE","RUNNING"]],"writes":[[1,6,3,"","k",1,"int",2]]}'
    assert fmt.decode_events(data) == [
        StatusChange(0, 5, 3, 2, Status.IDLE, Status.RUNNING),
        BlackboardWrite(1, 6, 3, "", "k", 1, "int", 2),
    ]
    ticks = b'{"ticks":[[3,0,9,"SUCCESS"]],"teardown":true}'
    assert fmt.decode_ticks(ticks) == [TickRecord(3, 0, 9, Status.SUCCESS, True)]
