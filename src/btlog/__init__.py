"""btlog: record every moment of a behavior tree's run, and explain any of them.

An executor with BehaviorTree.CPP v4 semantics emits every status change, blackboard
write and tree mutation as an event; a recorder appends them to an MCAP file (the event
store); a read model in DuckDB replays them so that the state at any past moment can be
rebuilt and explained with the algorithms of Han et al. (THRI 2020).
"""

__version__ = "0.1.0"
#: "2": each message's MCAP log_time is the run's start plus its events' ``t_ns`` (the
#: run's own clock); "1" wrote the wall time of writing. Both read the same.
SCHEMA_VERSION = "2"
#: Every schema version this btlog reads.
READABLE_SCHEMA_VERSIONS = ("1", "2")
