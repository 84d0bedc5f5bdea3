"""A Groot2 publisher that replays a FileLogger2 ``.btlog`` as fast as it is polled.

For ``bench_day.py --import``: ``btlog attach`` records it as it would a BT.CPP process
running a ``Groot2Publisher``. It answers the protocol's ``T`` (the log's tree XML),
``r start`` (the log's start time) and ``r stop``, and each ``t`` with the next
``PER_POLL`` records of the log, read from the file as they are asked for (fewer than
BT.CPP's 1,000 a poll, so no poll looks like one that dropped transitions). Once every
record is served it stops answering and exits: ``attach --timeout S --reconnect 0`` then
ends S seconds later, keeping everything.

    python benchmarks/groot2_replay.py RUN.btlog PORT     # prints "ready" once bound
"""

from __future__ import annotations

import os
import sys

import zmq

from btlog.sources.btcpp_filelog import read_filelog
from btlog.sources.btcpp_records import RECORD_SIZE

#: Records in each ``t`` reply (BT.CPP keeps at most 1,000 between two polls).
PER_POLL = 999


def serve(path: str, port: int) -> int:
    """Serve the log on ``tcp://127.0.0.1:PORT`` until every record is taken; the count."""
    log = read_filelog(path)
    tree_id = os.urandom(16)
    left = len(log)
    context = zmq.Context()
    sock = context.socket(zmq.REP)
    sock.setsockopt(zmq.LINGER, 0)
    sock.bind(f"tcp://127.0.0.1:{port}")
    print("ready", flush=True)
    with open(path, "rb") as stream:
        stream.seek(log.records_offset)
        while True:
            request = sock.recv_multipart()
            head = request[0]
            header = b"\x02" + head[1:6] + tree_id
            kind = chr(head[1])
            if kind == "T":
                reply = [header, log.xml]
            elif kind == "r" and request[1:] == [b"start"]:
                reply = [header, str(log.start_us).encode()]
            elif kind == "r":
                reply = [header]
            elif kind == "t" and left:
                count = min(PER_POLL, left)
                left -= count
                reply = [header, stream.read(count * RECORD_SIZE)]
            elif kind == "t":
                break  # all served: fall silent, as a process that ended
            else:
                reply = [b"error", b"Request not recognized"]
            sock.send_multipart(reply)
    sock.close(0)
    context.term()
    return len(log)


if __name__ == "__main__":
    print(f"served {serve(sys.argv[1], int(sys.argv[2])):,} transitions", flush=True)
