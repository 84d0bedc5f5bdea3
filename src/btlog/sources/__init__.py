"""Sources and sinks: runs made by other tools, in and out of btlog recordings.

Shaped like BehaviorTree.CPP's loggers: one small interface per direction, each format a
small module of its own.

- Sources turn another tool's log into an ordinary btlog recording through the one
  ``RecordingBuilder`` (``btlog.sources.builder``): a tree, a stream of transitions
  with times, optional blackboard writes, and where it came from. BT.CPP's FileLogger2
  (``btcpp_filelog``), SQLite logger (``btcpp_sqlite``) and v3 FileLogger (``btcpp_fbl``)
  files are imported; a running
  BT.CPP process is recorded live through the Groot2 protocol (``groot2``).
  ``btcpp_tree`` reads the tree XML BT.CPP writes for its loggers. ``rosbag2`` reads
  ROS 2 bags (MCAP or SQLite storage); Nav2's ``/behavior_tree_log`` is imported from
  them (``nav2_rosbag``), and py_trees_ros' tree snapshots (``py_trees_ros_bag``).
- Sinks write a btlog recording in another tool's format (``btlog.sinks``):
  FileLogger2 for Groot2.

``detect`` tells the import format of a file from its first bytes.
"""

from __future__ import annotations

import os

FILELOG_MAGIC = b"BTCPP4-FileLogger2"
SQLITE_MAGIC = b"SQLite format 3\x00"
MCAP_MAGIC = b"\x89MCAP0\r\n"


def detect(path: str | os.PathLike) -> str:
    """The import format of ``path``: ``"rosbag2"`` (a bag folder, an MCAP file, a
    SQLite file with rosbag2's tables, a ``.zstd`` storage file), ``"btcpp-filelog2"``,
    ``"btcpp-sqlite"`` (any other SQLite file: ``btcpp_sqlite`` checks its tables) or
    ``"btcpp-fbl"`` (BT.CPP 3's FileLogger: a ``.fbl`` name, or a header that fits)."""
    from btlog.sources.builder import SourceError
    from btlog.sources.rosbag2 import is_rosbag2_sqlite, storage_of

    if os.path.isdir(path):
        return "rosbag2"
    try:
        with open(path, "rb") as stream:
            head = stream.read(32)
    except OSError as error:
        raise SourceError(f"{os.fspath(path)}: cannot read the file: {error.strerror}") from None
    if head.startswith(FILELOG_MAGIC):
        return "btcpp-filelog2"
    if head.startswith(SQLITE_MAGIC):
        return "rosbag2" if is_rosbag2_sqlite(path) else "btcpp-sqlite"
    if storage_of(path) is not None:
        return "rosbag2"
    if os.fspath(path).endswith(".fbl") or _fbl_header(head, os.path.getsize(path)):
        return "btcpp-fbl"
    raise SourceError(
        f"{os.fspath(path)}: not a BT.CPP log or a rosbag2 bag (no 'BTCPP4-FileLogger2' "
        "or MCAP magic, not SQLite, not a v3 FileLogger header); "
        f"first bytes {head[:18]!r}"
    )


def _fbl_header(head: bytes, size: int) -> bool:
    """Whether ``head`` starts like a BT.CPP v3 FileLogger file (which has no magic): an
    i32 header size that fits the file, then a flatbuffer's root offset inside it, and
    transitions of 12 bytes after it."""
    if len(head) < 12:
        return False
    length, root = (
        int.from_bytes(head[:4], "little", signed=True),
        int.from_bytes(head[4:8], "little"),
    )
    return 8 <= length <= size - 4 and 4 <= root < length and (size - 4 - length) % 12 == 0
