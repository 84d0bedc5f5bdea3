"""Scripted leaves shared by the BT.CPP oracle and the btlog executor.

The outcomes are plain data, the subset of design.md section 9 that counts ticks::

    {
        "default": {"status": "SUCCESS", "ticks": 0},
        "nodes": {
            "a3": [{"status": "FAILURE", "ticks": 2}, {"status": "SUCCESS", "ticks": 0}],
            "c1": [{"status": "FAILURE"}, {"status": "SUCCESS"}],
        },
    }

Actions behave as BT.CPP's ``StatefulActionNode``:

* ``start`` (tick from IDLE) takes the entry of this activation (the n-th start of this node
  instance; the last entry repeats). With ``ticks == 0`` it returns the entry's status at once,
  otherwise it returns RUNNING and remembers ``ticks`` remaining ticks.
* ``running`` (tick while RUNNING) decrements the remaining ticks and returns the status when
  they reach 0, RUNNING before.
* ``halted`` forgets the activation: the next start takes the next entry.

Conditions use only the ``status`` of their entries; every tick of a condition is one
activation. Entries are counted per node instance: ``key`` (a uid or a path) tells instances
that share a name apart, and defaults to the name.
"""

from __future__ import annotations

from typing import Any

RUNNING = "RUNNING"
SUCCESS = "SUCCESS"
FAILURE = "FAILURE"

DEFAULT_ENTRY: dict[str, Any] = {"status": SUCCESS, "ticks": 0}


def entry_for(outcomes: dict[str, Any], name: str, activation: int) -> dict[str, Any]:
    """Return the outcome entry of ``name`` for its ``activation``-th start (0-based)."""
    entries = (outcomes.get("nodes") or {}).get(name)
    if entries is None:
        entry = outcomes.get("default") or DEFAULT_ENTRY
    else:
        if isinstance(entries, dict):
            entries = [entries]
        entry = entries[min(activation, len(entries) - 1)] if entries else DEFAULT_ENTRY
    status = str(entry.get("status", SUCCESS)).upper()
    if status not in (SUCCESS, FAILURE):
        raise ValueError(f"scripted status must be SUCCESS or FAILURE, not {status!r}")
    ticks = int(entry.get("ticks", 0))
    if ticks < 0:
        raise ValueError(f"scripted ticks must be >= 0, not {ticks}")
    return {"status": status, "ticks": ticks}


class ScriptedLeaves:
    """Per-instance state of the scripted actions and conditions of one run."""

    def __init__(self, outcomes: dict[str, Any] | None = None) -> None:
        """Keep ``outcomes`` (the dict described in the module docstring)."""
        self.outcomes: dict[str, Any] = outcomes or {}
        self.activations: dict[Any, int] = {}
        self.remaining: dict[Any, tuple[int, str]] = {}
        self.log: list[tuple[str, str, str]] = []

    def _next_entry(self, name: str, key: Any) -> dict[str, Any]:
        count = self.activations.get(key, 0)
        self.activations[key] = count + 1
        return entry_for(self.outcomes, name, count)

    def start(self, name: str, key: Any = None) -> str:
        """Start an activation of action ``name`` (ticked from IDLE); return its status."""
        key = name if key is None else key
        entry = self._next_entry(name, key)
        self.remaining.pop(key, None)
        if entry["ticks"] == 0:
            result = entry["status"]
        else:
            self.remaining[key] = (entry["ticks"], entry["status"])
            result = RUNNING
        self.log.append(("start", name, result))
        return result

    def running(self, name: str, key: Any = None) -> str:
        """Tick action ``name`` while RUNNING; return SUCCESS/FAILURE when done, else RUNNING."""
        key = name if key is None else key
        left, status = self.remaining.get(key, (1, SUCCESS))
        left -= 1
        if left <= 0:
            self.remaining.pop(key, None)
            result = status
        else:
            self.remaining[key] = (left, status)
            result = RUNNING
        self.log.append(("running", name, result))
        return result

    def halted(self, name: str, key: Any = None) -> None:
        """Halt action ``name`` while RUNNING: its activation is consumed."""
        key = name if key is None else key
        self.remaining.pop(key, None)
        self.log.append(("halted", name, "IDLE"))

    def condition(self, name: str, key: Any = None) -> str:
        """Evaluate condition ``name`` (one activation per tick); return SUCCESS or FAILURE."""
        key = name if key is None else key
        result = self._next_entry(name, key)["status"]
        self.log.append(("condition", name, result))
        return result
