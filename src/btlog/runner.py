"""Record a run: load the tree, build the domain's leaves, tick, record, answer live.

``RunConfig`` holds everything that determines a run (tree file, domain, seed, outcomes,
``--fail`` specs, failure rate, tick period, tick limit, live questions). It is stored in
the recording's metadata, so ``btlog check --rerun`` can run the same thing again.
Live questions (``--ask WHEN=QUESTION``) are answered at the tick boundary where WHEN is
reached, with the same code that answers post hoc; "Can you …?" inserts the
self-contained subtree into the running tree and records the mutation.
"""

from __future__ import annotations

import hashlib
import json
import os
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from btlog import SCHEMA_VERSION, __version__, limits
from btlog.domains import make_domain
from btlog.domains.halts import endless_loop_warnings
from btlog.domains.outcomes import (
    FailSpec,
    Outcomes,
    OutcomesError,
    ScriptedLeaf,
    halt_warnings,
    watch_halts,
)
from btlog.executor.clock import SimClock, WallClock
from btlog.executor.engine import Executor
from btlog.explain.questions import Answer
from btlog.live_questions import LiveQuestion, LiveQuestionError, LiveQuestions
from btlog.outputs import refuse_overwrite
from btlog.record.recorder import Recorder
from btlog.replay.moments import TICK, TIME
from btlog.status import Status
from btlog.tree.descriptions import apply_descriptions, load_descriptions
from btlog.tree.loader import load_nodes_model, load_tree
from btlog.tree.model import Tree

DEFAULT_MAX_TICKS = 100_000


class RunError(ValueError):
    """A run that cannot start (bad option or input); one line."""


@dataclass
class RunConfig:
    """Everything that determines a run."""

    tree: str
    domain: str = "scripted"
    outcomes_file: str | None = None
    outcomes: dict | None = None
    fail: list[str] = field(default_factory=list)
    failure_rate: float = 0.0
    seed: int = 0
    tick_period: float = 0.1
    max_ticks: int = DEFAULT_MAX_TICKS
    questions: list[str] = field(default_factory=list)
    realtime: bool = False
    flush_interval: float = 1.0
    nodes_model: str | None = None
    descriptions_file: str | None = None
    descriptions: dict[str, str] | None = None
    #: ``--main-tree``: the tree to create (else as BT.CPP chooses; see ``load_tree``)
    main_tree: str | None = None
    #: ``--trees``: more files and folders registered before the main tree is created
    trees: list[str] = field(default_factory=list)

    def load_tree(self) -> Tree:
        """The tree of this run: the file, ``--trees``, ``--main-tree``, ``--nodes-model``."""
        registry = load_nodes_model(self.nodes_model) if self.nodes_model else None
        return load_tree(self.tree, registry, self.main_tree, trees=self.trees)

    def load_descriptions(self) -> dict[str, str]:
        """The descriptions (recorded mapping, or the file's entries; none by default)."""
        if self.descriptions is not None:
            return dict(self.descriptions)
        return load_descriptions(self.descriptions_file) if self.descriptions_file else {}

    def load_outcomes(self) -> Outcomes:
        """The outcomes (file or mapping) with the --fail specs and failure rate."""
        if self.outcomes is not None:
            outcomes = Outcomes.from_mapping(self.outcomes, "recorded outcomes")
        elif self.outcomes_file:
            outcomes = Outcomes.load(self.outcomes_file)
        else:
            outcomes = Outcomes()
        outcomes.failures = [FailSpec.parse(spec) for spec in self.fail]
        if not 0.0 <= self.failure_rate <= 1.0:
            raise OutcomesError(f"--failure-rate {self.failure_rate}: must be between 0 and 1")
        outcomes.failure_rate = self.failure_rate
        return outcomes

    def to_metadata(self, tree: Tree, run_id: str, outcomes: Outcomes) -> dict[str, str]:
        """The ``btlog.run`` metadata record (``outcomes`` as loaded for this run)."""
        path = Path(self.tree)
        data = path.read_bytes()
        return {
            "run_id": run_id,
            "started_at": datetime.now(UTC).isoformat(),
            "tree_file": self.tree,
            "tree_file_abs": str(path.resolve()),
            "tree_sha256": hashlib.sha256(data).hexdigest(),
            "tree_name": tree.name,
            "domain": self.domain,
            "seed": str(self.seed),
            "outcomes": json.dumps(outcomes.source),
            "outcomes_file": self.outcomes_file or "",
            "fail": json.dumps(self.fail),
            "failure_rate": repr(self.failure_rate),
            "questions": json.dumps(self.questions),
            "tick_period": repr(self.tick_period),
            "max_ticks": str(self.max_ticks),
            "clock": "wall" if self.realtime else "sim",
            "nodes_model": self.nodes_model or "",
            "main_tree": self.main_tree or "",
            "trees": json.dumps([str(Path(t).resolve()) for t in self.trees]),
            "descriptions": json.dumps(self.load_descriptions()),
            "descriptions_file": self.descriptions_file or "",
            "btlog_version": __version__,
            "schema_version": SCHEMA_VERSION,
        }

    @classmethod
    def from_metadata(cls, metadata: dict, tree: str | None = None) -> RunConfig:
        """The configuration of a recorded run (for re-running it)."""

        def loaded(key: str, default: Any) -> Any:
            value = metadata.get(key, default)
            return json.loads(value) if isinstance(value, str) else value

        return cls(
            tree=tree or _recorded_tree(metadata),
            domain=metadata.get("domain", "scripted"),
            outcomes=loaded("outcomes", {}),
            fail=list(loaded("fail", [])),
            failure_rate=float(metadata.get("failure_rate", 0.0)),
            seed=int(metadata.get("seed", 0)),
            tick_period=float(metadata.get("tick_period", 0.1)),
            max_ticks=int(metadata.get("max_ticks", DEFAULT_MAX_TICKS)),
            questions=list(loaded("questions", [])),
            realtime=metadata.get("clock") == "wall",
            nodes_model=metadata.get("nodes_model") or None,
            descriptions=dict(loaded("descriptions", {})),
            main_tree=metadata.get("main_tree") or None,
            trees=list(loaded("trees", [])),
        )


def _recorded_tree(metadata: dict) -> str:
    """The recorded tree file: as given (relative to here) if it exists, else absolute."""
    given = metadata.get("tree_file", "")
    if given and Path(given).exists():
        return given
    return metadata.get("tree_file_abs") or given


@dataclass
class RunResult:
    """What a recorded run produced."""

    path: Path
    run_id: str
    final_status: Status
    ticks: int
    events: int
    answers: list[tuple[LiveQuestion, Answer, int]]
    #: One line per live question whose moment lies outside the run (not answered).
    refused: list[str] = field(default_factory=list)
    #: One line per --fail spec or outcomes entry that never applied.
    warnings: list[str] = field(default_factory=list)


def default_output(tree_path: str, run_id: str) -> Path:
    """``<tree stem>-<run id>.mcap`` in the current folder."""
    return Path(f"{Path(tree_path).stem}-{run_id}.mcap")


def _refuse_unreachable(question: LiveQuestion, config: RunConfig) -> None:
    """On the simulated clock a run lasts at most ``max_ticks`` ticks of
    ``tick_period``: a ``tick:N`` or time past that is refused before anything is run or
    written (other moments outside the run are only known once it is over)."""
    moment = question.moment
    last_ns = round(config.max_ticks * config.tick_period * 1e9)
    if (moment.kind == TICK and moment.value > config.max_ticks) or (
        moment.kind == TIME and moment.value > last_ns
    ):
        raise RunError(
            f"--ask {question.when}={question.question!r}: moment {moment.text!r} is after "
            f"the end of any run of --max-ticks {config.max_ticks} "
            f"({config.max_ticks} ticks, {last_ns / 1e9:g} s)"
        )


@dataclass
class Prepared:
    """A run ready for its first tick: everything ``prepare`` loaded and checked."""

    tree: Tree
    outcomes: Outcomes
    questions: list[LiveQuestion]
    executor: Executor
    #: descriptions file entries that name no node
    undescribed: list[str]


def prepare(config: RunConfig) -> Prepared:
    """Load and check everything a run needs before its first tick (``btlog validate``
    makes these checks too): the tree, descriptions, outcomes, questions, domain, clock
    settings, and the executor with its leaves."""
    tree = config.load_tree()
    undescribed = apply_descriptions(tree, config.load_descriptions())
    outcomes = config.load_outcomes()
    outcomes.check_keys(tree)
    try:
        questions = [LiveQuestion.parse(q) for q in config.questions]
    except LiveQuestionError as error:
        raise RunError(str(error)) from None
    try:
        domain = make_domain(config.domain, config.seed)
    except ValueError as error:
        raise RunError(str(error)) from None
    try:
        limits.seconds(config.tick_period, "--tick-period", positive=True)
        limits.seconds(config.flush_interval, "--flush-interval")  # 0: every tick
    except limits.LimitError as error:
        raise RunError(str(error)) from None
    if not 1 <= config.max_ticks <= limits.MAX_INT64:
        raise RunError(f"--max-ticks {config.max_ticks}: must be from 1 to {limits.MAX_INT64}")
    if not config.realtime:
        for question in questions:
            _refuse_unreachable(question, config)
    clock = WallClock(config.tick_period) if config.realtime else SimClock(config.tick_period)
    executor = Executor(tree, clock=clock, leaf_factory=domain.leaf_factory(tree, outcomes))
    for key, value in outcomes.typed_blackboard(executor).items():
        executor.preset(key, value)
    watch_halts(executor)
    return Prepared(tree, outcomes, questions, executor, undescribed)


def execute(
    config: RunConfig,
    output: str | os.PathLike | None = None,
    on_answer: Callable[[LiveQuestion, Answer, int], None] | None = None,
    on_tick: Callable[[int], None] | None = None,
) -> RunResult:
    """Run ``config`` and record it; returns where the recording is and how it ended."""
    prepared = prepare(config)
    tree, outcomes, questions, executor = (
        prepared.tree,
        prepared.outcomes,
        prepared.questions,
        prepared.executor,
    )
    run_id = uuid.uuid4().hex[:12]
    path = Path(output) if output else default_output(config.tree, run_id)
    refuse_overwrite(
        path, [config.tree, *tree.files, config.outcomes_file, config.descriptions_file]
    )
    attachments = [(Path(f).name, Path(f).read_bytes()) for f in tree.files]
    metadata = config.to_metadata(tree, run_id, outcomes)
    recorder = Recorder(path, tree, metadata, attachments, flush_interval=config.flush_interval)
    executor.subscribe(recorder)
    live = None
    if questions:
        live = LiveQuestions(executor, questions, recorder, on_answer, metadata["started_at"])

    def before_tick(ex: Executor) -> None:
        if on_tick is not None:  # first: a progress bar shows the tick an answer is at
            on_tick(ex.runtime.tick)
        if live is not None:
            live.before_tick(ex)

    try:
        status = executor.run(config.max_ticks, before_tick)
        ticks = executor.runtime.tick
        looping = [] if status.completed else endless_loop_warnings(executor.behaviors)
        executor.teardown()  # BT.CPP halts the tree it destroys; the answers at end see it
        if live is not None:
            live.finish()
    except BaseException:
        executor.close(teardown=False)
        raise
    executor.close()
    activations = {
        uid: behavior.activations
        for uid, behavior in executor.behaviors.items()
        if isinstance(behavior, ScriptedLeaf)
    }
    return RunResult(
        path,
        run_id,
        status,
        ticks,
        executor.seq,
        live.answered if live is not None else [],
        live.refused if live is not None else [],
        [
            *tree.warnings,
            *halt_warnings(executor),
            *looping,
            *outcomes.unapplied(executor.tree, activations),
            *(f"{config.descriptions_file}: {key!r} names no node" for key in prepared.undescribed),
        ],
    )
