"""The two lake tables computed at export from one run's read model.

- ``causes``: every FAILURE of a control node, decorator or subtree with its causal leaf
  (``btlog.explain.causes``), in event order.
- ``activations``: one row per activation of a node (a start out of IDLE up to its
  completion or the end of the run): when it started, when it completed, whether it
  completed and whether it failed. The fleet report aggregates these rows instead of
  every transition, so its cost grows with activations, not with events; the durations
  are kept one per activation, so percentiles stay exact (no sketch).
"""

from __future__ import annotations

import duckdb

from btlog.explain.causes import by_design, cause
from btlog.history import COMPLETIONS
from btlog.replay.database import Run
from btlog.status import FAILURE

#: Per activation of a node: ``activation`` counts the node's starts (``btlog.history.
#: resumes``: a result returned right after the node's own halt ends the activation it
#: halted) in event order (1 = its first); ``end_ns`` is NULL for an activation never
#: completed.
ACTIVATIONS = """
WITH changes AS (
  SELECT run_id, uid, seq, t_ns, CAST(prev_status AS VARCHAR) AS prev,
         CAST(status AS VARCHAR) AS status,
         lag(seq) OVER (PARTITION BY run_id, uid ORDER BY seq) AS before_seq,
         CAST(lag(prev_status) OVER (PARTITION BY run_id, uid ORDER BY seq) AS VARCHAR)
           AS before_prev,
         CAST(lag(status) OVER (PARTITION BY run_id, uid ORDER BY seq) AS VARCHAR)
           AS before_status
  FROM {source} WHERE run_id = $run
),
numbered AS (
  SELECT run_id, uid, seq, t_ns, status,
         sum(CASE WHEN prev = 'IDLE' AND status <> 'IDLE'
                   AND NOT (status IN ('SUCCESS', 'FAILURE') AND before_seq = seq - 1
                            AND before_prev = 'RUNNING' AND before_status = 'IDLE')
                  THEN 1 ELSE 0 END)
           OVER (PARTITION BY run_id, uid ORDER BY seq
                 ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW) AS activation
  FROM changes
)
SELECT run_id, uid, CAST(activation AS INTEGER) AS activation,
       min(t_ns) AS start_ns,
       max(CASE WHEN status IN ('SUCCESS', 'FAILURE') THEN t_ns END) AS end_ns,
       CAST(max(CASE WHEN status IN ('SUCCESS', 'FAILURE') THEN 1 ELSE 0 END) AS INTEGER)
         AS completed,
       CAST(max(CASE WHEN status = 'FAILURE' THEN 1 ELSE 0 END) AS INTEGER) AS failed
FROM numbered
WHERE activation > 0 AND status <> 'IDLE'
GROUP BY run_id, uid, activation
ORDER BY uid, activation
"""


def create_derived(run: Run, con: duckdb.DuckDBPyConnection) -> int:
    """Create the temp tables ``_btlog_causes`` and ``_btlog_activations`` for ``run``;
    return the number of causes. ``drop_derived`` removes them."""
    con.execute(
        "CREATE TEMP TABLE _btlog_activations AS "
        + ACTIVATIONS.format(source=f"{run.catalog}.transitions"),
        {"run": run.stored_id},
    )
    return _causes_table(run, con)


def drop_derived(con: duckdb.DuckDBPyConnection) -> None:
    """Drop what ``create_derived`` made."""
    con.execute("DROP TABLE IF EXISTS _btlog_causes")
    con.execute("DROP TABLE IF EXISTS _btlog_activations")


def _causes_table(run: Run, con: duckdb.DuckDBPyConnection) -> int:
    """Create ``_btlog_causes``: every FAILURE of a non-execution node with its causal
    leaf, in event order; return its row count."""
    # the final shape, with no snapshot fold (``run.tree_at("end")`` would do one for the
    # node statuses the export never uses)
    tree = run.final_tree()
    history = run.history()
    inner = [node.uid for node in tree if not node.is_execution]
    failures = [
        done
        for done in history.transitions(inner, COMPLETIONS, 0, run.info.events, 1 << 62)
        if done.status is FAILURE
    ]
    rows = []
    for done in failures:
        node = tree.node(done.uid)
        if by_design(tree, node, done, history):
            continue
        leaf = cause(tree, node, done, history)
        culprit = tree.node(leaf.uid)
        rows.append(
            (
                run.stored_id,
                done.seq,
                done.t_ns,
                node.uid,
                node.path,
                node.description,
                culprit.uid,
                culprit.path,
                culprit.description,
                "succeeded" if leaf.status.name == "SUCCESS" else "failed",
            )
        )
    con.execute(
        "CREATE TEMP TABLE _btlog_causes (run_id VARCHAR, seq BIGINT, t_ns BIGINT, "
        "uid INTEGER, path VARCHAR, name VARCHAR, cause_uid INTEGER, cause_path VARCHAR, "
        "cause_name VARCHAR, verb VARCHAR)"
    )
    if rows:
        con.executemany("INSERT INTO _btlog_causes VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", rows)
    return len(rows)
