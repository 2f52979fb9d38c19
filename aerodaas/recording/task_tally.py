"""The analytics scheduler's tasks as the recording holds them: a tally of the task records
(``/<robot>/<analytics>/tasks``, :class:`~aerodaas.recording.schemas.AnalyticsTask`) per scheduler.

The recorder adds every task record it writes (:meth:`TaskTally.add`) and writes the tally into the recording's
last message, ``/run/accounting`` (key ``tasks``, :class:`~aerodaas.recording.schemas.TaskCounts` per scheduler).
A dispatcher actor that Ray restarts counts from zero again; the recording does not, so the run's summary takes
the scheduler's task counts, utility and cost from this tally. A restarted recorder actor opens a new segment: it
tallies the task records of the earlier segments from their files (:func:`tally_recordings`) and adds its own,
the same way the per-channel message counts are carried across segments.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Iterable

__all__ = ["TASK_SCHEMA", "TaskCounts", "TaskTally", "tally_recording", "tally_recordings"]

#: the JSON schema name of a task record
TASK_SCHEMA = "aerodaas.AnalyticsTask"


@dataclass
class TaskCounts:
    """One scheduler's tasks in the recording: ``tasks`` records, per terminal ``states`` and per ``tiers`` (edge,
    cloud, none: never run), ``on_time`` (done_on_time), the sum of their ``utility`` and of their ``cost`` (edge
    or cloud cost charged, workload units), and the cost per tier (``cost_by_tier``)."""

    tasks: int = 0
    states: dict[str, int] = field(default_factory=dict)
    tiers: dict[str, int] = field(default_factory=dict)
    on_time: int = 0
    utility: float = 0.0
    cost: float = 0.0
    cost_by_tier: dict[str, float] = field(default_factory=dict)

    def add(self, record: dict[str, Any]) -> None:
        """Count one task record (a decoded ``aerodaas.AnalyticsTask``; a missing utility or cost counts 0)."""
        state = str(record.get("state"))
        tier = str(record.get("tier") or "none")
        cost = float(record.get("cost") or 0.0)
        self.tasks += 1
        self.states[state] = self.states.get(state, 0) + 1
        self.tiers[tier] = self.tiers.get(tier, 0) + 1
        self.on_time += state == "done_on_time"
        self.utility += float(record.get("utility") or 0.0)
        self.cost += cost
        self.cost_by_tier[tier] = self.cost_by_tier.get(tier, 0.0) + cost

    def merged(self, other: "TaskCounts") -> "TaskCounts":
        """The sum of this tally and ``other`` (a new object)."""
        out = TaskCounts(self.tasks + other.tasks, dict(self.states), dict(self.tiers), self.on_time + other.on_time,
                         self.utility + other.utility, self.cost + other.cost, dict(self.cost_by_tier))
        for mine, theirs in ((out.states, other.states), (out.tiers, other.tiers),
                             (out.cost_by_tier, other.cost_by_tier)):
            for k, v in theirs.items():
                mine[k] = mine.get(k, 0) + v
        return out

    def as_dict(self) -> dict[str, Any]:
        """The JSON form (``/run/accounting`` ``tasks.<scheduler>``)."""
        return {"tasks": self.tasks, "states": dict(sorted(self.states.items())),
                "tiers": dict(sorted(self.tiers.items())), "on_time": self.on_time, "utility": self.utility,
                "cost": self.cost, "cost_by_tier": dict(sorted(self.cost_by_tier.items()))}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TaskCounts":
        """The tally from its JSON form (:meth:`as_dict`). Raises TypeError / ValueError for a malformed one."""
        return cls(int(d.get("tasks", 0)), {str(k): int(v) for k, v in (d.get("states") or {}).items()},
                   {str(k): int(v) for k, v in (d.get("tiers") or {}).items()}, int(d.get("on_time", 0)),
                   float(d.get("utility", 0.0)), float(d.get("cost", 0.0)),
                   {str(k): float(v) for k, v in (d.get("cost_by_tier") or {}).items()})


class TaskTally:
    """Task records per scheduler (:class:`TaskCounts`); a record without a scheduler's name counts under ``"?"``.
    Not thread-safe: the recorder's writer thread adds, the recorder reads it once that thread has ended."""

    def __init__(self) -> None:
        self.per: dict[str, TaskCounts] = {}

    def add(self, record: dict[str, Any]) -> None:
        """Count one task record (see :meth:`TaskCounts.add`)."""
        self.per.setdefault(str(record.get("scheduler") or "?"), TaskCounts()).add(record)

    def add_all(self, records: Iterable[dict[str, Any]]) -> "TaskTally":
        """Count every record of ``records``; returns self."""
        for r in records:
            if isinstance(r, dict):
                self.add(r)
        return self

    def merged(self, other: "TaskTally") -> "TaskTally":
        """The sum of this tally and ``other`` (a new object)."""
        out = TaskTally()
        for name in {*self.per, *other.per}:
            out.per[name] = self.per.get(name, TaskCounts()).merged(other.per.get(name, TaskCounts()))
        return out

    def as_dict(self) -> dict[str, dict[str, Any]]:
        """``{scheduler: TaskCounts.as_dict()}`` (``/run/accounting`` ``tasks``)."""
        return {name: c.as_dict() for name, c in sorted(self.per.items())}

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> "TaskTally":
        """The tally from its JSON form (None: empty). Raises TypeError / ValueError for a malformed one."""
        out = cls()
        for name, c in (d or {}).items():
            out.per[str(name)] = TaskCounts.from_dict(c)
        return out


def tally_recordings(paths: Iterable[str | os.PathLike]) -> TaskTally:
    """The task records in the recordings ``paths`` (segments of a run; finished or not), tallied. A file that
    cannot be read (gone, not an MCAP file, cut inside a record) adds what was read of it before the error."""
    from aerodaas.recording.reader import summarize_mcap  # lazy: heavy mcap

    tally = TaskTally()
    for p in paths:
        try:
            tally_recording(tally, p, summarize_mcap(p)["channels"])
        except Exception:  # noqa: BLE001 - unreadable: its records are not there to count
            continue
    return tally


def tally_recording(tally: TaskTally, path: str | os.PathLike, channels: list[dict[str, Any]]) -> TaskTally:
    """Add the task records of the recording ``path`` to ``tally``, reading only its task topics; ``channels`` is
    its channel list as :func:`aerodaas.recording.reader.summarize_mcap` gives it (``topic``, ``schema``), so that
    a caller that summarized the file already does not read it twice. Returns ``tally``. Raises what
    :func:`aerodaas.recording.reader.read_messages` raises for an unreadable file (the records read before the
    error stay counted)."""
    from aerodaas.recording.reader import read_messages  # lazy: heavy mcap

    topics = [c["topic"] for c in channels if c["schema"] == TASK_SCHEMA]
    if topics:
        for _topic, schema, _t, msg in read_messages(path, topics=topics):
            if schema == TASK_SCHEMA and isinstance(msg, dict):
                tally.add(msg)
    return tally
