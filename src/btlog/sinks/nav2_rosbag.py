"""Write a btlog recording as a ROS 2 MCAP bag that Nav2 tools and Foxglove read.

``/behavior_tree_log`` (``nav2_msgs/msg/BehaviorTreeLog``, CDR, written with
``mcap-ros2-support``) carries one message per tick with that tick's status changes,
as Nav2's BT navigators publish it; ``/behavior_tree_xml`` (``std_msgs/msg/String``)
carries the tree as BT.CPP's ``WriteTreeToXML`` writes it (every node with its
``_uid``), which Foxglove's behavior-tree panel matches against the log's uids. A node's
``node_name`` is BT.CPP's ``name()``: its name, or its registration ID when it has none. Times are
the run's clock: the recording's start plus each event's time. Blackboard writes have no
place in these messages and are left out (counted).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap_ros2.writer import Writer

from btlog.events import BlackboardWrite, StatusChange, TreeMutation
from btlog.record.reader import Recording
from btlog.record.recorder import start_time_ns
from btlog.sinks.btcpp_filelog import tree_xml
from btlog.sources.builder import SourceError
from btlog.sources.nav2_rosbag import LOG_TOPIC, LOG_TYPE, XML_TOPIC, XML_TYPE
from btlog.sources.rosbag2 import shipped_definition

#: ``nav2_msgs/msg/BehaviorTreeLog`` with uids (Nav2 since Jazzy), as rosbag2 stores it.
LOG_MSGDEF = shipped_definition(LOG_TYPE, "jazzy").text
XML_MSGDEF = shipped_definition(XML_TYPE, "all").text
_MAX_UID = 0xFFFF


@dataclass
class ExportResult:
    """What was written: the file, messages, transitions and the writes left out."""

    path: Path
    messages: int
    transitions: int
    writes_left_out: int


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000}


def export_nav2(recording: Recording, output: str | os.PathLike) -> ExportResult:
    """Write ``recording`` as the ROS 2 MCAP bag ``output``."""
    where = os.fspath(recording.path)
    if any(isinstance(e, TreeMutation) for e in recording.events):
        raise SourceError(f"{where}: the tree changed during the run; a Nav2 log has one tree")
    too_big = [n.uid for n in recording.tree if n.uid > _MAX_UID]
    if too_big:
        raise SourceError(f"{where}: uid {too_big[0]} does not fit the log's uint16")
    start = start_time_ns(recording.metadata["started_at"])
    ticks: dict[int, list[StatusChange]] = {}
    writes = 0
    for event in recording.events:
        if isinstance(event, StatusChange):
            ticks.setdefault(event.tick, []).append(event)
        elif isinstance(event, BlackboardWrite):
            writes += 1
    ends = {record.tick: record.end_ns for record in recording.ticks}
    # BT.CPP's name(): the instance name, else the registration ID (what Nav2 logs)
    names = {node.uid: node.description for node in recording.tree}
    with open(output, "wb") as stream:
        writer = Writer(stream)
        xml_schema = writer.register_msgdef(XML_TYPE, XML_MSGDEF)
        log_schema = writer.register_msgdef(LOG_TYPE, LOG_MSGDEF)
        writer.write_message(
            XML_TOPIC, xml_schema, {"data": tree_xml(recording.tree).decode()}, log_time=start
        )
        for tick, changes in ticks.items():
            sent = start + max(ends.get(tick, 0), changes[-1].t_ns)
            message: dict[str, Any] = {
                "timestamp": _stamp(sent),
                "event_log": [
                    {
                        "timestamp": _stamp(start + change.t_ns),
                        "node_name": names[change.uid],
                        "uid": change.uid,
                        "previous_status": change.prev.name,
                        "current_status": change.status.name,
                    }
                    for change in changes
                ],
            }
            writer.write_message(LOG_TOPIC, log_schema, message, log_time=sent)
        writer.finish()
    transitions = sum(len(c) for c in ticks.values())
    return ExportResult(Path(output), len(ticks), transitions, writes)
