"""Run one tree in BehaviorTree.CPP (through behaviortreepy) and print its transitions.

Usage (from the project root)::

    echo '{"xml": "...", "outcomes": {...}, "max_ticks": 20}' | python -m tests.oracle.btcpp_oracle

or ``python tests/oracle/btcpp_oracle.py``. The input may also carry ``"tick_mode"``:
``"once"`` (default, ``Tree::tickOnce``, which re-ticks the root in the same call while a node
has emitted the wake-up signal and the root is RUNNING) or ``"exactly_once"``
(``Tree::tickExactlyOnce``). ``"file_log": PATH`` also records the run with BT.CPP's
``FileLogger2`` (a ``.btlog``, released before the process exits so its writer thread has
written everything); ``"tick_sleep_ms": N`` sleeps between ticks (so ticks are apart in time).
``"groot2_port": P`` serves the tree with a ``Groot2Publisher``; with ``"sync_dir": DIR`` the
oracle creates DIR/ready once it serves, waits for DIR/go before the first tick, creates
DIR/ran after the last, and waits for DIR/quit before it prints and exits.
``"leaf_ids": {"actions": [...], "conditions": [...]}`` registers more type IDs as scripted
actions and conditions (trees written with their own leaf types).

Output, one JSON object on stdout::

    {"transitions": [[tick, name, prev, new], ...],
     "root": ["RUNNING", ..., "SUCCESS"],
     "error": null,
     "ticks": 3, "halted": false, "other_output": []}

* ``tick`` counts the calls of ``tick_once`` from 1. After the last tick the tree is
  destroyed, as when a program ends: BT.CPP's destructor halts the whole tree
  (``haltTree``), which halts what still runs and resets every node left non-IDLE; those
  transitions carry the number of the last tick + 1 (``teardown_tick``); with a Groot2
  publisher the tree is not destroyed, and a run still RUNNING after ``max_ticks`` is
  halted with ``halt_tree()`` in its last tick instead. ``halted`` is
  true when the root was still RUNNING or SKIPPED after ``max_ticks``.
* ``root`` holds the status returned by each ``tick_once``.
* ``error`` is null, or ``"create: <message>"`` when BT.CPP refused the XML, or
  ``"tick N: <message>"`` when a tick threw (transitions up to the throw are kept; no
  halt is made), or ``"tick N: scripted leaf: <message>"`` when the outcomes were invalid
  (behaviortreepy would silently turn the callback's exception into FAILURE).
* ``other_output`` holds any line BT.CPP printed on stdout that is not a transition.

Transitions are read from ``StdCoutLogger``, which prints every status change
synchronously (``[time]: NAME<pad> PREV -> NEW``): file descriptor 1 is redirected to a
temporary file while BT.CPP runs, and restored before the JSON is printed.
"""

from __future__ import annotations

import ctypes
import gc
import json
import os
import re
import sys
import tempfile
import time
from typing import Any

if __package__:
    from .scripted import ScriptedLeaves
else:  # run as a script
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from scripted import ScriptedLeaves  # type: ignore[no-redef]

ACTION_ID = "ScriptedAction"
CONDITION_ID = "ScriptedCondition"

_STATUS = "IDLE|RUNNING|SUCCESS|FAILURE|SKIPPED"
_LINE = re.compile(rf"^\[[-+0-9.eE]+\]: (.*) ({_STATUS}) -> ({_STATUS})$")
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_NAME_PAD = 25  # StdCoutLogger pads names shorter than this with spaces


def parse_logger_line(line: str) -> tuple[str, str, str] | None:
    """Parse one ``StdCoutLogger`` line into ``(name, prev, new)``; None if it is not one."""
    match = _LINE.match(_ANSI.sub("", line.rstrip("\r\n")))
    if match is None:
        return None
    padded, prev, new = match.groups()
    name = padded if len(padded) > _NAME_PAD else padded.rstrip(" ")
    return name, prev, new


class _StdoutCapture:
    """Redirect file descriptor 1 to a temporary file and hand out what was written since."""

    def __init__(self) -> None:
        sys.stdout.flush()
        self._libc = ctypes.CDLL(None)
        self.saved_fd = os.dup(1)
        self._file = tempfile.TemporaryFile()  # noqa: SIM115
        os.dup2(self._file.fileno(), 1)
        self._offset = 0
        self._partial = b""

    def read_lines(self) -> list[str]:
        """Flush C stdio and return the complete lines written since the last call."""
        self._libc.fflush(None)
        size = os.fstat(self._file.fileno()).st_size
        data = b""
        while self._offset < size:
            chunk = os.pread(self._file.fileno(), size - self._offset, self._offset)
            if not chunk:
                break
            data += chunk
            self._offset += len(chunk)
        data = self._partial + data
        *lines, self._partial = data.split(b"\n")
        return [line.decode("utf-8", "replace") for line in lines]

    def restore(self) -> list[str]:
        """Restore file descriptor 1; return any unterminated trailing output."""
        rest = self.read_lines()
        if self._partial:
            rest.append(self._partial.decode("utf-8", "replace"))
            self._partial = b""
        os.dup2(self.saved_fd, 1)
        os.close(self.saved_fd)
        self._file.close()
        return rest


def _make_factory(
    bt: Any, leaves: ScriptedLeaves, errors: list[str], leaf_ids: dict[str, list[str]] | None = None
) -> Any:
    """Register the scripted leaves; exceptions in them are appended to ``errors``.

    behaviortreepy turns an exception raised by a Python callback into a plain FAILURE
    of the node, so the callbacks catch their own exceptions to report them.
    """
    status = {
        "RUNNING": bt.NodeStatus.RUNNING,
        "SUCCESS": bt.NodeStatus.SUCCESS,
        "FAILURE": bt.NodeStatus.FAILURE,
    }

    def guarded(method: Any) -> Any:
        def callback(node: Any) -> Any:
            try:
                result = method(node.name(), node.uid())
            except Exception as exc:
                errors.append(f"{method.__name__}({node.name()!r}): {exc}")
                return bt.NodeStatus.FAILURE
            return None if result is None else status[result]

        return callback

    factory = bt.BehaviorTreeFactory()
    factory.register_simple_stateful_action(
        ACTION_ID, guarded(leaves.start), guarded(leaves.running), guarded(leaves.halted)
    )
    factory.register_simple_condition(CONDITION_ID, guarded(leaves.condition))
    for type_id in (leaf_ids or {}).get("actions", []):
        factory.register_simple_stateful_action(
            type_id, guarded(leaves.start), guarded(leaves.running), guarded(leaves.halted)
        )
    for type_id in (leaf_ids or {}).get("conditions", []):
        factory.register_simple_condition(type_id, guarded(leaves.condition))
    return factory


def run_case(
    xml: str,
    outcomes: dict[str, Any] | None,
    max_ticks: int,
    tick_mode: str = "once",
    file_log: str | None = None,
    tick_sleep_ms: float = 0.0,
    groot2_port: int | None = None,
    sync_dir: str | None = None,
    leaf_ids: dict[str, list[str]] | None = None,
) -> dict[str, Any]:
    """Run ``xml`` in BT.CPP for at most ``max_ticks`` ticks; return the result dict.

    Must run in a process of its own: it redirects file descriptor 1 while BT.CPP runs, so
    call it once and exit.
    """
    import behaviortreepy as bt

    leaves = ScriptedLeaves(outcomes or {})
    result: dict[str, Any] = {
        "transitions": [],
        "root": [],
        "error": None,
        "ticks": 0,
        "halted": False,
        "teardown_tick": None,
        "other_output": [],
    }
    transitions: list[list[Any]] = result["transitions"]
    other: list[str] = result["other_output"]

    def collect(lines: list[str], tick: int) -> None:
        for line in lines:
            parsed = parse_logger_line(line)
            if parsed is None:
                if line.strip():
                    other.append(line)
            else:
                transitions.append([tick, *parsed])

    callback_errors: list[str] = []
    file_logger: list[Any] = []
    capture = _StdoutCapture()
    keep_alive: list[Any] = []
    try:
        factory = _make_factory(bt, leaves, callback_errors, leaf_ids)
        try:
            tree = factory.create_tree_from_text(xml)
        except Exception as exc:
            result["error"] = f"create: {exc}"
            return result
        logger = bt.StdCoutLogger(tree)
        keep_alive += [factory, tree, logger]
        if file_log:
            file_logger.append(bt.FileLogger(tree, file_log))
        if groot2_port:
            keep_alive.append(bt.Groot2Publisher(tree, groot2_port))
        _handshake(sync_dir, "ready", "go")
        tick_fn = tree.tick_exactly_once if tick_mode == "exactly_once" else tree.tick_once
        last = "IDLE"
        for tick in range(1, max_ticks + 1):
            if tick > 1 and tick_sleep_ms:
                time.sleep(tick_sleep_ms / 1000)
            result["ticks"] = tick
            try:
                last = tick_fn().name
            except Exception as exc:
                collect(capture.read_lines(), tick)
                result["error"] = f"tick {tick}: {exc}"
                return result
            collect(capture.read_lines(), tick)
            result["root"].append(last)
            if callback_errors:
                result["error"] = f"tick {tick}: scripted leaf: {callback_errors[0]}"
                return result
            if last in ("SUCCESS", "FAILURE"):
                break
        result["halted"] = last not in ("SUCCESS", "FAILURE")
        if groot2_port:  # the publisher refers to the tree: halt it, never destroy it
            if result["halted"]:
                try:
                    tree.halt_tree()
                except Exception as exc:
                    result["error"] = f"halt: {exc}"
                collect(capture.read_lines(), result["ticks"])
        else:
            result["teardown_tick"] = result["ticks"] + 1
            keep_alive.remove(tree)
            if tick_sleep_ms:  # the teardown comes as late as a tick would
                time.sleep(tick_sleep_ms / 1000)
            del tree, tick_fn  # the destructor halts the tree; the loggers, still alive, see it
            gc.collect()
            collect(capture.read_lines(), result["teardown_tick"])
        _handshake(sync_dir, "ran", "quit")
    finally:
        if file_logger:  # let its writer thread drain its queue, then release it
            _drain(file_logger[0], file_log or "", len(transitions))
            file_logger.clear()
        collect(capture.restore(), result["teardown_tick"] or result["ticks"])
        _KEEP.extend(keep_alive)
    return result


def _handshake(sync_dir: str | None, done: str, then: str, timeout: float = 60.0) -> None:
    """Create ``sync_dir/done``, then wait for ``sync_dir/then`` (no-op without a folder)."""
    if not sync_dir:
        return
    with open(os.path.join(sync_dir, done), "w"):
        pass
    deadline = time.monotonic() + timeout
    while not os.path.exists(os.path.join(sync_dir, then)) and time.monotonic() < deadline:
        time.sleep(0.005)


def _records_written(path: str) -> int:
    """How many 9-byte transition records a FileLogger2 file holds so far."""
    try:
        with open(path, "rb") as file:
            data = file.read()
    except OSError:
        return 0
    head = len(b"BTCPP4-FileLogger2") + 1  # the magic, then a version byte
    if len(data) < head + 4:
        return 0
    body = head + 4 + int.from_bytes(data[head : head + 4], "little") + 8  # XML, start time
    return max(0, (len(data) - body) // 9)


def _drain(logger: Any, path: str, expected: int, timeout: float = 20.0) -> None:
    """Wait until FileLogger2's writer thread has written ``expected`` transitions.

    Its destructor stops the thread without emptying the queue, so releasing it while
    transitions wait there (its thread wakes every 10 ms; later under load) loses them.
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        logger.flush()
        if _records_written(path) >= expected:
            return
        time.sleep(0.005)


_KEEP: list[Any] = []  # what is left is never destroyed: main() leaves with os._exit


MAX_OUTPUT_BYTES = 64 * 1024 * 1024


def _limit_output_size() -> None:
    """Cap the size of the files this process writes.

    Some trees livelock inside one ``tick_once`` (e.g. a ReactiveSequence of two
    ``Repeat``s of synchronous children: each halts the other and re-emits the wake-up
    signal), and the logger would fill the disk before the parent's timeout. Going over
    the cap kills the process (SIGXFSZ), which the runner reports as a crash.
    """
    try:
        import resource

        resource.setrlimit(resource.RLIMIT_FSIZE, (MAX_OUTPUT_BYTES, MAX_OUTPUT_BYTES))
    except (ImportError, ValueError, OSError):
        pass


def main() -> None:
    """Read a case as JSON on stdin, run it, print the result as JSON and exit."""
    _limit_output_size()
    case = json.loads(sys.stdin.read())
    result = run_case(
        case["xml"],
        case.get("outcomes"),
        int(case.get("max_ticks", 20)),
        case.get("tick_mode", "once"),
        case.get("file_log"),
        float(case.get("tick_sleep_ms", 0.0)),
        case.get("groot2_port"),
        case.get("sync_dir"),
        case.get("leaf_ids"),
    )
    sys.stdout.write(json.dumps(result) + "\n")
    sys.stdout.flush()
    os._exit(0)


if __name__ == "__main__":
    main()
