"""Moments: what ``--at WHEN`` means, and how many events it covers.

A moment names a point of a run (docs/design.md, "Moments"). Whatever its form, it comes down to one
number: how many events to apply. The state at a moment is the fold of the first
``count`` events (seq ``0 … count-1``); for a time ``t`` that is every event with
``t_ns <= t``, because event times never decrease along ``seq``.

The forms, parsed by ``parse_moment`` into a ``Moment``:

==================  ===============================================================
``12.5`` ``12.5s``  seconds since the run started (``1500ms``, ``250us``, ``100ns``)
``-2s``             two seconds before the end of the run
``tick:N``          right after tick N: every event of ticks ``<= N`` (tick 0 holds
                    the writes made before the first tick)
``seq:N``           right after event N: ``N + 1`` events
``end``             every event
ISO-8601            a wall time, e.g. ``2025-01-31T12:00:03.5+00:00``; measured from
                    the run's start wall time (metadata ``started_at``). A time
                    without a zone is read in the zone of the start time.
==================  ===============================================================

Parsing needs nothing but the text. ``resolve_moment`` then checks the moment against a
run, given as a ``RunExtent`` (its duration, its event count, its last tick, its start
wall time, and three look-ups answered by the read model) and returns a ``Resolved``
moment. Every problem is a ``MomentError`` whose one-line message names the value and
the reason, e.g. ``moment '99s' is after the end of the run (12.3 s)``.
"""

from __future__ import annotations

import re
from bisect import bisect_right
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime

from btlog.limits import MAX_INT64

TIME = "time"
BEFORE_END = "before_end"
TICK = "tick"
SEQ = "seq"
END = "end"
WALL = "wall"

_UNITS = {"": 1_000_000_000, "s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "µs": 1_000, "ns": 1}
_DURATION = re.compile(
    r"^(?P<sign>[+-]?)(?P<number>\d+(?:\.\d*)?|\.\d+)\s*"
    r"(?P<unit>s|ms|us|µs|ns)?$"
)
_COUNTER = re.compile(r"^(?P<kind>tick|seq)\s*:\s*(?P<number>\d+)$")
_ISO_HINT = re.compile(r"^\d{4}-\d{2}-\d{2}")


class MomentError(ValueError):
    """A moment that cannot be parsed or lies outside the run; one line, naming the value."""


@dataclass(frozen=True)
class Moment:
    """A parsed moment: its ``kind`` (time, before_end, tick, seq, end, wall) and ``value``
    (ns for time and before_end, N for tick and seq, ns since the epoch for wall;
    ``naive`` for a wall time written without a zone, its value read as if UTC)."""

    kind: str
    value: int
    text: str
    naive: bool = False

    def __str__(self) -> str:
        return self.text


@dataclass(frozen=True)
class Resolved:
    """A moment resolved against a run: what every header shows (``show``, ``explain``,
    ``--json``, ``replay``, the viewer), computed here and nowhere else.

    ``count``: apply the events with seq below it (the first ``count`` events, seqs being
    gap-free); ``seq`` is then the last event applied (None before the first).
    ``t_ns``: the moment's own time since the run started: the time asked for a time,
    the end of tick N for ``tick:N``, event N's time for ``seq:N``, the run's end for
    ``end``. ``tick``: the moment's tick: N for ``tick:N``, event N's tick for ``seq:N``,
    for a time the last tick started at or before it (0 before the first tick).
    ``last_event_t_ns``: the time of the last event applied (None before the first), given
    separately because a moment often falls between events.
    """

    moment: Moment
    count: int
    t_ns: int
    tick: int = 0
    last_event_t_ns: int | None = None

    @property
    def seq(self) -> int | None:
        """The last event applied (None when none is)."""
        return self.count - 1 if self.count else None

    def to_json(self) -> dict:
        """The moment as JSON: ``at`` as asked, ``seq``, ``tick``, ``t_ns`` and
        ``last_event_t_ns`` as above, and ``count``."""
        return {
            "at": self.moment.text,
            "seq": self.seq,
            "tick": self.tick,
            "t_ns": self.t_ns,
            "last_event_t_ns": self.last_event_t_ns,
            "count": self.count,
        }


@dataclass(frozen=True)
class RunExtent:
    """What resolving a moment needs to know about a run.

    ``count_at(t_ns)`` is the number of events with ``t_ns`` at most ``t_ns``;
    ``count_after_tick(n)`` the number of events of ticks up to ``n``; ``keys_of(count)``
    the (time, tick) of event ``count - 1`` ((0, 0) for ``count == 0``);
    ``tick_end(n)`` the end time of the last tick up to ``n`` that has a record (None
    when none has); ``tick_at(t_ns)`` the last tick that started at or before ``t_ns``
    (0 when none did). ``started_at_ns`` is the start wall time in ns since the epoch
    (None when the recording has none).
    """

    events: int
    duration_ns: int
    last_tick: int
    started_at_ns: int | None
    count_at: Callable[[int], int]
    count_after_tick: Callable[[int], int]
    keys_of: Callable[[int], tuple[int, int]]
    tick_end: Callable[[int], int | None]
    tick_at: Callable[[int], int]
    started_at_zone: object = UTC

    @classmethod
    def from_events(
        cls,
        times: Sequence[int],
        ticks: Sequence[int],
        tick_records: Sequence[tuple[int, int, int]],
        started_at: str | None,
    ) -> RunExtent:
        """The extent of a run given its events' ``t_ns`` and ``tick`` in seq order (both
        never decrease), its tick records ``(tick, start_ns, end_ns)`` in order and its
        ``started_at`` metadata: what a live run knows of itself, resolved exactly as the
        read model resolves it."""
        started_ns, zone = parse_started_at(started_at)
        numbers = [record[0] for record in tick_records]
        starts = [record[1] for record in tick_records]
        end_ns = max((record[2] for record in tick_records), default=0)

        def tick_end(tick: int) -> int | None:
            index = bisect_right(numbers, tick) - 1
            return tick_records[index][2] if index >= 0 else None

        def tick_at(t_ns: int) -> int:
            index = bisect_right(starts, t_ns) - 1
            return numbers[index] if index >= 0 else 0

        return cls(
            events=len(times),
            duration_ns=max(end_ns, times[-1] if times else 0),
            last_tick=max(numbers[-1] if numbers else 0, ticks[-1] if ticks else 0),
            started_at_ns=started_ns,
            count_at=lambda t_ns: bisect_right(times, t_ns),
            count_after_tick=lambda tick: bisect_right(ticks, tick),
            keys_of=lambda count: (times[count - 1], ticks[count - 1]) if count > 0 else (0, 0),
            tick_end=tick_end,
            tick_at=tick_at,
            started_at_zone=zone,
        )


def before_start() -> Resolved:
    """The moment before the run's first event (the viewer's ``#seq=-1``)."""
    return Resolved(Moment(SEQ, -1, "seq:-1"), 0, 0, 0, None)


def time_moment(t_ns: int) -> str:
    """The moment text of a time since the start, exact and short: ``8.4s``, ``0s``."""
    whole, fraction = divmod(t_ns, 1_000_000_000)
    digits = f"{fraction:09d}".rstrip("0")
    return f"{whole}.{digits}s" if digits else f"{whole}s"


def parse_moment(text: str | Moment) -> Moment:
    """Parse ``--at WHEN`` (see the module docstring); MomentError if it is no moment."""
    if isinstance(text, Moment):
        return text
    if not isinstance(text, str):
        raise MomentError(f"unparseable moment {text!r}: expected text such as '12.5s'")
    value = text.strip()
    if value.lower() == "end":
        return Moment(END, 0, text)
    counter = _COUNTER.match(value.lower())
    if counter:
        return _in_range(Moment(counter["kind"], _integer(counter["number"], text), text))
    duration = _DURATION.match(value)
    if duration:
        return _in_range(_duration(duration, text))
    if _ISO_HINT.match(value):
        return _wall(value, text)
    raise MomentError(
        f"unparseable moment {text!r}: expected seconds (12.5, 12.5s, 1500ms, "
        "250us, 100ns), -2s, tick:N, seq:N, end or an ISO-8601 time"
    )


def _integer(digits: str, text: str) -> int:
    """The digits' value; more digits than any 64-bit count are refused before ``int``."""
    if len(digits.lstrip("0")) > len(str(MAX_INT64)):
        raise MomentError(f"moment {text!r} is out of range (at most {MAX_INT64})")
    return int(digits)


def _in_range(moment: Moment) -> Moment:
    """A tick, seq or time past what 64 bits count is refused, not answered at the end."""
    if moment.value > MAX_INT64:
        raise MomentError(f"moment {moment.text!r} is out of range (at most {MAX_INT64})")
    return moment


def _duration(match: re.Match, text: str) -> Moment:
    number = match["number"]
    whole, _, fraction = number.partition(".")
    scale = _UNITS[match["unit"] or ""]
    ns = _integer(whole or "0", text) * scale
    fraction = fraction[:30]  # digits far below a nanosecond change nothing
    if fraction:
        denominator = 10 ** len(fraction)
        ns += (int(fraction) * scale + denominator // 2) // denominator
    if match["sign"] == "-":
        return Moment(BEFORE_END, ns, text)
    return Moment(TIME, ns, text)


def _wall(value: str, text: str) -> Moment:
    """An ISO-8601 time; one without a zone keeps its clock reading (``naive``)."""
    try:
        moment = datetime.fromisoformat(value)
    except ValueError:
        raise MomentError(f"unparseable moment {text!r}: not a valid ISO-8601 time") from None
    naive = moment.tzinfo is None
    return Moment(WALL, _epoch_ns(moment.replace(tzinfo=UTC) if naive else moment), text, naive)


def _epoch_ns(moment: datetime) -> int:
    delta = moment - datetime(1970, 1, 1, tzinfo=UTC)
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000


def parse_started_at(text: str | None) -> tuple[int | None, object]:
    """(ns since the epoch, zone) of the metadata's ``started_at``; (None, UTC) if absent
    or unreadable."""
    if not text:
        return None, UTC
    try:
        moment = datetime.fromisoformat(text)
    except ValueError:
        return None, UTC
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    return _epoch_ns(moment), moment.tzinfo


def resolve_moment(moment: str | Moment, run: RunExtent) -> Resolved:
    """How many events the moment covers in ``run``, and its seq, tick and time
    (``Resolved``); MomentError when it is outside the run."""
    moment = parse_moment(moment)
    if moment.kind == END:
        return _resolved(moment, run, run.events, run.duration_ns, run.last_tick)
    if moment.kind == SEQ:
        return _at_seq(moment, run)
    if moment.kind == TICK:
        return _at_tick(moment, run)
    return _at_time(moment, _time_since_start(moment, run), run)


def _resolved(moment: Moment, run: RunExtent, count: int, t_ns: int, tick: int) -> Resolved:
    last = run.keys_of(count)[0] if count else None
    return Resolved(moment, count, t_ns, tick, last)


def _at_seq(moment: Moment, run: RunExtent) -> Resolved:
    if run.events == 0:
        raise MomentError(f"moment {moment.text!r} is outside the run: it has no events")
    if moment.value >= run.events:
        raise MomentError(
            f"moment {moment.text!r} is after the end of the run (last event seq:{run.events - 1})"
        )
    count = moment.value + 1
    t_ns, tick = run.keys_of(count)
    return Resolved(moment, count, t_ns, tick, t_ns)


def _at_tick(moment: Moment, run: RunExtent) -> Resolved:
    if moment.value > run.last_tick:
        raise MomentError(
            f"moment {moment.text!r} is after the end of the run (last tick {run.last_tick})"
        )
    count = run.count_after_tick(moment.value)
    end = run.tick_end(moment.value)
    t_ns = max(end if end is not None else 0, run.keys_of(count)[0])
    return _resolved(moment, run, count, t_ns, moment.value)


def _time_since_start(moment: Moment, run: RunExtent) -> int:
    if moment.kind == TIME:
        return moment.value
    if moment.kind == BEFORE_END:
        t_ns = run.duration_ns - moment.value
        if t_ns < 0:
            raise MomentError(
                f"moment {moment.text!r} is before the start of the run "
                f"(it lasts {_seconds(run.duration_ns)})"
            )
        return t_ns
    return wall_offset_ns(moment, run.started_at_ns, run.started_at_zone)


def wall_offset_ns(moment: Moment, started_at_ns: int | None, zone: object = UTC) -> int:
    """A wall-time moment as ns since the run's start (``started_at_ns`` since the epoch,
    a time without a zone read in ``zone``); MomentError before the start."""
    if started_at_ns is None:
        raise MomentError(
            f"moment {moment.text!r} is a wall time, but the recording has "
            "no start time (metadata started_at)"
        )
    wall = moment.value
    if moment.naive:
        wall -= _zone_offset_ns(zone)
    t_ns = wall - started_at_ns
    if t_ns < 0:
        raise MomentError(
            f"moment {moment.text!r} is before the start of the run ({_iso(started_at_ns, zone)})"
        )
    return t_ns


def _zone_offset_ns(zone: object) -> int:
    offset = datetime.now(zone).utcoffset()  # type: ignore[arg-type]
    return 0 if offset is None else round(offset.total_seconds() * 1e9)


def _at_time(moment: Moment, t_ns: int, run: RunExtent) -> Resolved:
    if t_ns > run.duration_ns:
        raise MomentError(
            f"moment {moment.text!r} is after the end of the run ({_seconds(run.duration_ns)})"
        )
    return _resolved(moment, run, run.count_at(t_ns), t_ns, run.tick_at(t_ns))


def _seconds(ns: int) -> str:
    return f"{ns / 1e9:.6g} s"


def _iso(ns: int, zone: object) -> str:
    moment = datetime.fromtimestamp(ns / 1e9, tz=zone)  # type: ignore[arg-type]
    return moment.isoformat(timespec="microseconds")
