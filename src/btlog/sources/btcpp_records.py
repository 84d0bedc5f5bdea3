"""BT.CPP's transition record and status codes, shared by FileLogger2 files, the Groot2
protocol's ``t`` replies and the SQLite logger's ``state`` column.

A record is 9 bytes, little-endian: a u48 time in µs since the start, a u16 node uid and
a u8 status (0 IDLE, 1 RUNNING, 2 SUCCESS, 3 FAILURE, 4 SKIPPED).
"""

from __future__ import annotations

import struct
from collections.abc import Iterator

from btlog.sources.builder import SourceError
from btlog.status import Status

RECORD_SIZE = 9
MAX_UID = 0xFFFF
MAX_US = (1 << 48) - 1
_STATUSES = tuple(Status)
#: A record as struct fields: the time's low 32 and high 16 bits, the uid, the status.
_RECORD = struct.Struct("<IHHB")


def status_of(code: object, where: str) -> Status:
    """The status of a BT.CPP status code (``SourceError`` naming ``where`` if none)."""
    if isinstance(code, int) and 0 <= code < len(_STATUSES):
        return _STATUSES[code]
    raise SourceError(f"{where}: status {code!r} is not 0-4")


def decode_records(
    data: bytes, where: str, base: int = 0, first: int = 0
) -> Iterator[tuple[int, int, Status]]:
    """``(µs since start, uid, status)`` of each whole record in ``data``; errors name
    the record and its byte (``base``: where the records start in their file; ``first``:
    the number of ``data``'s first record among them). The records before a bad status
    are yielded before the error is raised."""
    whole = len(data) - len(data) % RECORD_SIZE
    codes = data[8:whole:RECORD_SIZE]
    bad = len(codes)
    if codes and max(codes) >= len(_STATUSES):
        bad = next(i for i, code in enumerate(codes) if code >= len(_STATUSES))
    statuses = _STATUSES
    for low, high, uid, code in _RECORD.iter_unpack(memoryview(data)[: bad * RECORD_SIZE]):
        yield low | high << 32, uid, statuses[code]
    if bad < len(codes):
        status_of(codes[bad], f"{where}: {record_at(first + bad, base)}")  # raises


def record_at(number: int, base: int = 0) -> str:
    """How errors name record ``number`` of records starting at byte ``base``."""
    return f"record {number} (byte {base + number * RECORD_SIZE})"


def encode_record(t_us: int, uid: int, status: Status) -> bytes:
    """The 9 bytes of one transition."""
    return t_us.to_bytes(6, "little") + uid.to_bytes(2, "little") + bytes([int(status)])
