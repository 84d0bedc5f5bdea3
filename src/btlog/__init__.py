"""btlog: record every moment of a behavior tree's run, and explain any of them.

An executor with BehaviorTree.CPP v4 semantics emits every status change, blackboard
write and tree mutation as an event; a recorder appends them to an MCAP file (the event
store); a read model in DuckDB replays them so that the state at any past moment can be
rebuilt and explained with the algorithms of Han et al. (THRI 2020).
"""

__version__ = "0.1.0"
#: "3": status changes and tick records are binary columns (``btlog.record.columns``);
#: "2" wrote them as JSON rows; "2" and "3" set each message's MCAP log_time to the run's
#: start plus its events' ``t_ns`` (the run's own clock), "1" to the wall time of
#: writing. All three read the same.
SCHEMA_VERSION = "3"
#: Every schema version this btlog reads.
READABLE_SCHEMA_VERSIONS = ("1", "2", "3")
