"""``btlog record-py MODULE:FACTORY``: build a py_trees tree from a factory, tick it and
record the run, asking live questions on the way, without a loop of the user's own.

FACTORY is a function of MODULE (a module name on the path, or a ``.py`` file) that takes
no arguments and returns a ``py_trees.trees.BehaviourTree`` or its root behaviour. The
tree is set up (``tree.setup()``), then ticked ``ticks`` times, or until the root
completes with ``until_done``. The clock is simulated (tick k starts at ``(k - 1) *
period`` seconds, nothing waits) unless ``realtime``, which ticks every ``period``
seconds of the wall clock and records wall times. Live questions (``WHEN=QUESTION``,
WHEN as for ``btlog run --ask``) are answered before the first tick after WHEN, as post
hoc answers them; moments counted from the end, when the run is over.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import py_trees

from btlog.explain.questions import Answer
from btlog.live_questions import EventExtent, LiveQuestion, at_the_end, moment_time
from btlog.outputs import refuse_overwrite
from btlog.replay.moments import MomentError, parse_started_at
from btlog.sources.builder import BuildResult
from btlog.sources.py_trees import PyTreesRecorder

#: A root in one of these has completed (``until_done``).
DONE = (py_trees.common.Status.SUCCESS, py_trees.common.Status.FAILURE)
#: Seconds ``tree.setup()`` may take.
SETUP_TIMEOUT = 15.0


class ScriptError(ValueError):
    """A factory that cannot be loaded or used; one line naming it."""


def load_factory(spec: str) -> Callable[[], Any]:
    """The function ``MODULE:FACTORY`` names (MODULE: a module name or a ``.py`` file)."""
    module_name, sep, factory_name = spec.rpartition(":")
    if not sep or not module_name or not factory_name:
        raise ScriptError(f"{spec!r}: expected MODULE:FACTORY, e.g. my_robot.trees:create_root")
    try:
        if module_name.endswith(".py") or os.sep in module_name:
            path = Path(module_name)
            if not path.is_file():
                raise ScriptError(f"{spec!r}: no file {module_name}")
            loader = importlib.util.spec_from_file_location(path.stem, path)
            if loader is None or loader.loader is None:
                raise ScriptError(f"{spec!r}: {module_name} is not a Python module")
            module = importlib.util.module_from_spec(loader)
            sys.modules[path.stem] = module
            loader.loader.exec_module(module)
        else:
            module = importlib.import_module(module_name)
    except ScriptError:
        raise
    except Exception as error:  # the user's module failed to import
        raise ScriptError(f"{spec!r}: cannot import {module_name}: {error}") from None
    factory = getattr(module, factory_name, None)
    if not callable(factory):
        raise ScriptError(f"{spec!r}: {module_name} has no function {factory_name}")
    return factory


def make_tree(spec: str) -> Any:
    """The tree the factory ``spec`` builds (a root behaviour is put in a tree), set up."""
    try:
        made = load_factory(spec)()
    except ScriptError:
        raise
    except Exception as error:  # the user's factory failed
        raise ScriptError(f"{spec!r}: the factory failed: {error}") from None
    if isinstance(made, py_trees.behaviour.Behaviour):
        made = py_trees.trees.BehaviourTree(made)
    if not isinstance(made, py_trees.trees.BehaviourTree):
        raise ScriptError(
            f"{spec!r}: the factory returned a {type(made).__name__}, "
            "not a py_trees BehaviourTree or Behaviour"
        )
    try:
        made.setup(timeout=SETUP_TIMEOUT)
    except Exception as error:  # a behaviour's setup failed
        raise ScriptError(f"{spec!r}: tree.setup() failed: {error}") from None
    return made


@dataclass
class ScriptRun:
    """What ``record_script`` made: the build result, the answers and the refusals."""

    result: BuildResult | None = None
    answers: list[tuple[LiveQuestion, Answer]] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)


def record_script(
    spec: str,
    output: str | os.PathLike,
    ticks: int,
    period: float,
    asked: list[str],
    realtime: bool = False,
    until_done: bool = False,
    on_answer: Callable[[LiveQuestion, Answer], None] | None = None,
) -> ScriptRun:
    """Build, tick and record the tree of ``spec`` (see the module docstring)."""
    if ticks < 1:
        raise ScriptError(f"--ticks {ticks}: must be at least 1")
    if not 0 <= period <= 3600:
        raise ScriptError(f"--period {period}: must be from 0 to 3600 seconds")
    questions = [LiveQuestion.parse(q) for q in asked]
    refuse_overwrite(output, [spec.rpartition(":")[0]])
    tree = make_tree(spec)
    done = [0]
    clock = None if realtime else (lambda: done[0] * period)
    extent = EventExtent()
    metadata = {"py_trees_factory": spec, "tick_period": repr(period), "max_ticks": str(ticks)}
    recorder = PyTreesRecorder(tree, output, metadata=metadata, clock=clock, subscribers=[extent])
    run = ScriptRun()
    started_at = recorder.builder.recorder.metadata["started_at"]
    started_ns = parse_started_at(started_at)[0]
    pending = list(questions)

    def ask(question: LiveQuestion, tree_now: Any, state: Any, at_ns: int) -> None:
        result = recorder.answer_about(question.question, tree_now, state, at_ns)
        run.answers.append((question, result))
        if on_answer is not None:
            on_answer(question, result)

    def ask_due(next_ns: int) -> None:
        history = recorder.live_history()
        for question in [
            q for q in pending if q.due_after(done[0], recorder.builder.seq, next_ns, started_ns)
        ]:
            pending.remove(question)
            at_ns = moment_time(question.moment, history.state, started_ns, extent.end_ns)
            ask(question, history.tree, history.state, at_ns)

    try:
        for _ in range(ticks):
            begin = time.monotonic()
            ask_due(recorder.now_ns())
            tree.tick()
            done[0] += 1
            if until_done and tree.root.status in DONE:
                break
            if realtime:
                time.sleep(max(0.0, period - (time.monotonic() - begin)))
        ask_due(recorder.now_ns())
        for question in list(pending):
            pending.remove(question)
            try:
                tree_then, state, at_ns = at_the_end(
                    question, extent, recorder.live_history(), started_at
                )
            except MomentError as error:
                run.refused.append(f"--ask {question.when}={question.question!r}: {error}")
                continue
            ask(question, tree_then, state, at_ns)
    finally:
        run.result = recorder.close()
    return run
