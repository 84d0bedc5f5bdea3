"""Reading a long recording in several processes at once, each a part of its chunks.

Cutting a recording's messages into columns costs Python a few microseconds a message
(``btlog.replay.scan``), and a day-long run has a million messages: one core's work, and
what a first answer about a long run waits for. A finished recording's summary lists
where each chunk starts, so the file can be cut at chunk boundaries into parts of about
equal size (``plan``), each scanned by a process of its own with its own loader
(``btlog.replay.load``). A part's status changes go to a Parquet file of their own
(``btlog.replay.transitions_file``); its ticks and blackboard writes are loaded into a
DuckDB of the part's own and handed over as Parquet files, which the caller inserts
into its tables; what else the scan collected (the tree, mutations, answers, warnings)
comes back with them (``merge``). The first part is the caller's own, scanned while the
others run.

A file without a sound summary (a cut recording), a small file, or a machine of one
core is read in one part; the tables are the same, row for row, however many parts.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from btlog.errors import one_line
from btlog.record.reader import seq_of
from btlog.record.walk import MAGIC, RecordingError, chunk_starts, mapped, summary_message_count
from btlog.replay.connections import connect
from btlog.replay.load import Destination, load_part
from btlog.replay.scan import Collected
from btlog.replay.tables import create_schema, literal
from btlog.replay.transitions_file import TransitionsFile

#: Bytes of a recording below which one process reads it (a process takes ~0.5 s to start).
MIN_PART_BYTES = 48 << 20
#: Messages of a recording below which one process reads it: the cost of reading is
#: mostly per message (a few microseconds of Python each), so a run of small ticks
#: (a message each) is worth parts well below ``MIN_PART_BYTES``.
MIN_PART_MESSAGES = 250_000
#: The most parts: each process holds its own batches and DuckDB (a few hundred MB).
MAX_PARTS = 4


@dataclass(frozen=True)
class Part:
    """The records of a recording from byte ``start`` up to byte ``stop`` (None: its end)."""

    start: int
    stop: int | None


def plan(path: str) -> list[Part]:
    """The parts to read ``path`` in: one per core (at most ``MAX_PARTS``), each about
    ``MIN_PART_BYTES`` (``$BTLOG_PART_BYTES``) or ``MIN_PART_MESSAGES`` (as the summary
    counts them) or more, cut where a chunk starts; one part for a file whose summary
    does not list its chunks."""
    size = os.path.getsize(path)
    try:
        part_bytes = max(int(os.environ.get("BTLOG_PART_BYTES", MIN_PART_BYTES)), 1)
    except ValueError:
        part_bytes = MIN_PART_BYTES
    whole = [Part(len(MAGIC), None)]
    if _cores() < 2:
        return whole
    with mapped(path) as (data, mapped_size):
        messages = summary_message_count(data, mapped_size) or 0
        count = min(_cores(), MAX_PARTS, max(size // part_bytes, messages // MIN_PART_MESSAGES))
        if count < 2:
            return whole
        starts = chunk_starts(data, mapped_size)
    cuts: list[int] = []
    for number in range(1, count):
        target = size * number // count
        cut = next((start for start in starts if start >= target), None)
        if cut is not None and cut > max(cuts, default=len(MAGIC)):
            cuts.append(cut)
    if not cuts:
        return whole
    return [Part(a, b) for a, b in zip([len(MAGIC), *cuts], [*cuts, None], strict=True)]


def _cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


@dataclass
class PartRows:
    """What a part's scan gives back: what it collected, and its ticks and blackboard
    rows as Parquet files (its status changes are in the transitions file it was given)."""

    collected: Collected
    ticks: Path
    blackboard: Path


def scan_part(path: str, part: Part, run_id: str, transitions: Path, folder: Path) -> PartRows:
    """Scan ``part`` of the recording ``path`` as run ``run_id``: its status changes into
    the Parquet file ``transitions``, its ticks and writes into files in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    con = connect()
    try:
        create_schema(con)
        to = Destination(run_id, TransitionsFile(transitions))
        try:
            collected = load_part(con, to, path, folder, part.start, part.stop)
        finally:
            if to.transitions is not None:
                to.transitions.close()
        rows = PartRows(collected, folder / "ticks.parquet", folder / "blackboard.parquet")
        for table, file in (("ticks", rows.ticks), ("blackboard", rows.blackboard)):
            con.execute(f"COPY {table} TO {literal(str(file))} (FORMAT parquet)")
        return rows
    finally:
        con.close()


class PartScan:
    """``scan_part`` running in a process of its own (``python -m btlog.replay.parts``:
    not forked, so the caller's DuckDB threads stay its own, and not
    ``multiprocessing``'s spawn, which imports the caller's main script again);
    ``rows`` waits for it, ``stop`` ends it early. What the process prints on stderr (a
    traceback of its own, if it fails before it can answer) is kept for the error."""

    def __init__(self, path: str, part: Part, *args: Any) -> None:
        package = str(Path(__file__).resolve().parents[2])  # the btlog this one is
        paths = [package, os.environ.get("PYTHONPATH", "")]
        environment = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p)}
        self.path, self.part = path, part
        request, send = os.pipe()
        try:
            self._process = subprocess.Popen(
                [sys.executable, "-m", "btlog.replay.parts"],
                stdin=request,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                env=environment,
            )
        finally:
            os.close(request)
        with contextlib.suppress(BrokenPipeError), open(send, "wb", buffering=0) as sending:
            sending.write(pickle.dumps((path, part, *args)))  # (ended already: rows tells)

    def rows(self) -> PartRows:
        """The part's rows once its scan ends; its error, raised here, if it failed; a
        ``RecordingError`` naming the file and the part if the process ended without an
        answer (killed, or failed before it could answer)."""
        output, errors = self._process.communicate()
        code = self._process.returncode
        if code != 0 or not output:
            last = errors.decode(errors="replace").strip().splitlines()[-1:]
            said = f": {' '.join(last[0].split())}" if last else ""
            raise RecordingError(
                f"{self.path}: the process reading bytes {self.part.start} to "
                f"{'the end' if self.part.stop is None else self.part.stop} of the recording "
                f"ended without an answer (exit code {code}){said}"
            )
        outcome = pickle.loads(output)  # our own child's answer
        if isinstance(outcome, BaseException):
            raise outcome
        return outcome

    def stop(self) -> None:
        """End the scan if it still runs."""
        if self._process.poll() is None:
            self._process.kill()
        self._process.wait()
        for stream in (self._process.stdout, self._process.stderr):
            if stream is not None:
                stream.close()


def _outcome(path: str, *args: Any) -> Any:
    """``scan_part(path, *args)``'s rows, or its error as one that survives pickling: the
    error itself when it does (a ``RecordingError``, an ``OSError``, DuckDB's: the same
    error as reading in one process gives), else its message as a ``RuntimeError``."""
    try:
        return scan_part(path, *args)
    except RecordingError as error:
        return error
    except (ValueError, TypeError, IndexError) as error:
        return RecordingError(
            f"{path}: rows that do not follow the btlog format: {type(error).__name__}: {error}"
        )
    except Exception as error:
        try:
            pickle.loads(pickle.dumps(error))
        except Exception:  # not every error survives pickling
            return RuntimeError(one_line(error))
        return error


class Disagree(Exception):
    """The parts of a recording were not read as one read of the whole file reads them
    (``agree``): it is to be read again in one part."""


def agree(collected: list[Collected]) -> bool:
    """Whether the scans of consecutive parts read their records as one scan of the whole
    file would: each part knows the channels of the summary only, so none but the last
    may meet a channel record that changes them (a hostile summary, CRC and all, that
    leaves out a channel the chunks define: the parts after it would skip its messages)."""
    return not any(scanned.redefined for scanned in collected[:-1])


def merge(first: Collected, others: list[Collected]) -> Collected:
    """What the scans of consecutive parts collected, as one scan of the whole file
    would have."""
    for other in others:
        if first.metadata is None:
            first.metadata = other.metadata
        if first.tree is None:
            first.tree = other.tree
        first.mutations.extend(other.mutations)
        first.answers.extend(other.answers)
        first.other_events.extend(other.other_events)
        first.other_ticks.extend(other.other_ticks)
        first.unknown_channel += other.unknown_channel
        first.walk.warnings.extend(other.walk.warnings)
        first.walk.dropped.extend(other.walk.dropped)
        first.walk.truncated = other.walk.truncated  # the last part's end is the file's
        first.walk.summary = first.walk.summary or other.walk.summary
    first.mutations.sort(key=seq_of)
    first.answers.sort(key=seq_of)
    return first


def main() -> None:
    """A part's process: the arguments of ``scan_part`` in, its outcome out (pickled)."""
    request = pickle.load(sys.stdin.buffer)
    sys.stdout.buffer.write(pickle.dumps(_outcome(*request)))


if __name__ == "__main__":  # run as a script: its classes must pickle as the module's
    from btlog.replay.parts import main as module_main

    module_main()
