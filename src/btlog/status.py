"""Node statuses, numbered as BehaviorTree.CPP numbers them."""

from enum import IntEnum


class Status(IntEnum):
    """The status of a node: IDLE until ticked, then RUNNING or a result.

    SKIPPED is returned by a node whose precondition skipped it; BehaviorTree.CPP v4 never
    stores it as the node's own status, so it is never seen in a transition.
    """

    IDLE = 0
    RUNNING = 1
    SUCCESS = 2
    FAILURE = 3
    SKIPPED = 4

    def __str__(self) -> str:
        return self.name

    @property
    def completed(self) -> bool:
        """True for SUCCESS and FAILURE."""
        return self is Status.SUCCESS or self is Status.FAILURE


IDLE = Status.IDLE
RUNNING = Status.RUNNING
SUCCESS = Status.SUCCESS
FAILURE = Status.FAILURE
SKIPPED = Status.SKIPPED

#: Status names indexed by value, for hot paths that must not go through the enum.
STATUS_NAMES = tuple(s.name for s in Status)
