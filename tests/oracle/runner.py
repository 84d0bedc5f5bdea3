"""Run the BT.CPP oracle in a subprocess (BT.CPP may crash on some trees)."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from typing import Any

ORACLE_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "btcpp_oracle.py")


def have_behaviortreepy() -> bool:
    """Return True if ``behaviortreepy`` can be imported by this interpreter."""
    try:
        import behaviortreepy  # noqa: F401
    except ImportError:
        return False
    return True


def case_payload(case: Any) -> dict[str, Any]:
    """Turn a ``Case`` (or a dict with xml/outcomes/max_ticks) into the oracle's input."""
    if dataclasses.is_dataclass(case) and not isinstance(case, type):
        data = dataclasses.asdict(case)
    else:
        data = dict(case)
    payload = {
        "xml": data["xml"],
        "outcomes": data.get("outcomes") or {},
        "max_ticks": int(data.get("max_ticks", 20)),
    }
    keys = ("tick_mode", "file_log", "tick_sleep_ms", "groot2_port", "sync_dir", "leaf_ids")
    for key in keys:
        if data.get(key):
            payload[key] = data[key]
    return payload


def run_oracle(case: Any, timeout: float = 20) -> dict[str, Any] | None:
    """Run ``case`` through BT.CPP in a child process and return the oracle's result.

    The result is ``{"transitions": [[tick, name, prev, new], ...], "root": [...],
    "error": None | str, ...}`` (see ``btcpp_oracle``). Returns None when the child process
    crashed (e.g. a segmentation fault inside BT.CPP), timed out or printed no valid JSON,
    so that the caller can skip the case and count it.
    """
    payload = json.dumps(case_payload(case))
    try:
        proc = subprocess.run(
            [sys.executable, ORACLE_SCRIPT],
            input=payload,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return None
    if proc.returncode != 0:
        return None
    for line in reversed(proc.stdout.splitlines()):
        line = line.strip()
        if line.startswith("{"):
            try:
                return json.loads(line)
            except ValueError:
                return None
    return None


def tick_boundaries(transitions: list[list[Any]]) -> set[int]:
    """The indexes of the ``[tick, …]`` rows that start a tick (empty ticks leave no trace
    in a log of transitions, so logs are compared by where their ticks start)."""
    return {i for i, row in enumerate(transitions) if i == 0 or row[0] != transitions[i - 1][0]}
