"""Component health: how often each sensor and analytics failed, and whether that degrades the run.

A component counts every attempt (a sensor's sample, an analytics' item) and every failure (an exception, an output
that breaks the declared contract) in a :class:`FailureLog`. The first :data:`FIRST_EVENTS` failures are recorded one
by one as ``sensor_error`` / ``analytics_error`` events of the robot (``/<robot>/events``); after that, one
``sensor_error_summary`` / ``analytics_error_summary`` event for every :data:`SUMMARY_EVERY` further failures, or
once :data:`SUMMARY_PERIOD_S` seconds of vehicle time passed since the last event with failures unrecorded, and a
last one when the component closes. Every event carries ``failures`` and ``attempts``: how many of each since the
component's previous event (an individual event: ``failures`` 1), so that the sum over the recording is the
component's total — also across restarts of its actor, whose own counters begin at 0 again (the recording's
``count`` of its component's failures is what :func:`tally_failures` sums). ``count`` is the component's own total
since its actor (re)started, ``error`` (individual) / ``last_error`` (summary) the exception's text.

:func:`assess` takes each component's own counts and the recording's tally and returns the components whose failures
exceed their limit, ``max_failure_fraction`` of their attempts (default :data:`DEFAULT_MAX_FAILURE_FRACTION`; a
sensor's in ``environment.json``, an analytics' as its attribute): the run's outcome is then ``degraded``.
"""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Iterable

__all__ = ["DEFAULT_MAX_FAILURE_FRACTION", "FIRST_EVENTS", "SUMMARY_EVERY", "SUMMARY_PERIOD_S", "ComponentKind",
           "FailureCount", "FailureLog", "assess", "tally_failures"]

#: default limit: a component whose failures exceed this fraction of its attempts degrades the run
DEFAULT_MAX_FAILURE_FRACTION = 0.2
#: failures recorded one event each before summaries take over
FIRST_EVENTS = 5
#: failures per summary event after the first ones
SUMMARY_EVERY = 100
#: vehicle seconds after which failures not yet recorded get a summary event (at the next failure)
SUMMARY_PERIOD_S = 10.0


class ComponentKind(str, Enum):
    """What failed: the event names and the key that names the component in them."""

    SENSOR = "sensor"
    ANALYTICS = "analytics"

    @property
    def event(self) -> str:
        """The individual failure event (``sensor_error``)."""
        return f"{self.value}_error"

    @property
    def summary_event(self) -> str:
        """The summary event (``sensor_error_summary``)."""
        return f"{self.value}_error_summary"


@dataclass
class FailureCount:
    """One component's failures: ``kind``, ``robot`` (a sensor's robot; None for an analytics, which may serve
    several robots and counts as one across them), ``name`` (sensor id / analytics name), ``attempts`` and
    ``failures`` (counts), the ``first_error`` and ``last_error`` texts, and its ``limit`` (max_failure_fraction)."""

    kind: ComponentKind
    robot: str | None
    name: str
    attempts: int = 0
    failures: int = 0
    first_error: str | None = None
    last_error: str | None = None
    limit: float = DEFAULT_MAX_FAILURE_FRACTION

    @property
    def key(self) -> tuple[str, str | None, str]:
        return (self.kind.value, self.robot, self.name)

    @property
    def label(self) -> str:
        """``sensor flaky of d1`` / ``analytics bad``: how the summary names it."""
        return f"{self.kind.value} {self.name}" + (f" of {self.robot}" if self.robot else "")

    @property
    def over_limit(self) -> bool:
        """More failures than ``limit`` × attempts (and at least one)."""
        return self.failures > 0 and self.failures > self.limit * max(self.attempts, self.failures)

    def as_dict(self) -> dict[str, Any]:
        """The JSON form (a component's ``stats()["health"]``)."""
        return {"kind": self.kind.value, "robot": self.robot, "name": self.name, "attempts": self.attempts,
                "failures": self.failures, "first_error": self.first_error, "last_error": self.last_error,
                "limit": self.limit}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "FailureCount":
        """From :meth:`as_dict`. Raises KeyError / ValueError for a malformed one."""
        return cls(ComponentKind(d["kind"]), d.get("robot"), str(d["name"]), int(d.get("attempts", 0)),
                   int(d.get("failures", 0)), d.get("first_error"), d.get("last_error"),
                   float(d.get("limit", DEFAULT_MAX_FAILURE_FRACTION)))


@dataclass
class FailureLog:
    """A component's attempts and failures since its actor (re)started, and what of them to record: see the
    module. ``count`` holds the totals; ``unrecorded_*`` what no event carried yet; ``last_event_t`` the vehicle
    time (s) of the component's last event."""

    count: FailureCount
    first_events: int = FIRST_EVENTS
    every: int = SUMMARY_EVERY
    period_s: float = SUMMARY_PERIOD_S
    unrecorded_failures: int = 0
    unrecorded_attempts: int = 0
    last_event_t: float | None = None
    _events: int = field(default=0, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def attempt(self) -> None:
        """One more attempt (call before :meth:`failed` for a failing one)."""
        with self._lock:
            self.count.attempts += 1
            self.unrecorded_attempts += 1

    def failed(self, t: float, error: str) -> dict[str, Any] | None:
        """The attempt at vehicle time ``t`` (s) failed with ``error`` (text): counted. Returns the fields of the
        event to record now (``event``, the component's key field, ``error`` or ``last_error``, ``failures``,
        ``attempts``, ``count``), or None when this failure goes into a later summary."""
        with self._lock:
            c = self.count
            c.failures += 1
            c.first_error = c.first_error or error
            c.last_error = error
            self.unrecorded_failures += 1
            if self._events < self.first_events:
                return self._event(t, {"event": c.kind.event, "error": error})
            if (self.unrecorded_failures >= self.every
                    or (self.last_event_t is not None and t - self.last_event_t >= self.period_s)):
                return self._summary(t)
            return None

    def summary(self, t: float) -> dict[str, Any] | None:
        """A summary event of what no event carried yet (None when no failure is unrecorded): at the end of the
        component."""
        with self._lock:
            return self._summary(t)

    def _summary(self, t: float) -> dict[str, Any] | None:
        if not self.unrecorded_failures:
            return None
        return self._event(t, {"event": self.count.kind.summary_event, "last_error": self.count.last_error})

    def _event(self, t: float, ev: dict[str, Any]) -> dict[str, Any]:
        c = self.count
        ev.update({c.kind.value: c.name, "failures": self.unrecorded_failures, "attempts": self.unrecorded_attempts,
                   "count": c.failures})
        self.unrecorded_failures = self.unrecorded_attempts = 0
        self.last_event_t = t
        self._events += 1
        return ev

    def state(self) -> dict[str, Any]:
        """For a checkpoint (a restarted drone actor's sensors go on counting): :meth:`restore` takes it."""
        with self._lock:
            return {"count": self.count.as_dict(), "unrecorded": [self.unrecorded_failures,
                                                                  self.unrecorded_attempts],
                    "last_event_t": self.last_event_t, "events": self._events}

    def restore(self, st: dict[str, Any]) -> None:
        """Put a :meth:`state` back (the limit stays this log's own)."""
        limit = self.count.limit
        self.count = FailureCount.from_dict(st["count"])
        self.count.limit = limit
        self.unrecorded_failures, self.unrecorded_attempts = (int(x) for x in st["unrecorded"])
        self.last_event_t = st.get("last_event_t")
        self._events = int(st.get("events", 0))


def _from_event(robot: str | None, ev: dict[str, Any]) -> FailureCount | None:
    """The failures one recorded event carries (None: not a failure event). An event recorded before events
    carried ``failures`` counts as one failure."""
    name = ev.get("event")
    for kind in ComponentKind:
        if name in (kind.event, kind.summary_event) and ev.get(kind.value) is not None:
            error = ev.get("error") if name == kind.event else ev.get("last_error")
            return FailureCount(kind, robot if kind is ComponentKind.SENSOR else None, str(ev[kind.value]),
                                int(ev.get("attempts") or 0), int(ev.get("failures") or 1),
                                error if name == kind.event else None, error)
    return None


def tally_failures(paths: Iterable[str | os.PathLike]) -> dict[tuple, FailureCount]:
    """The failures recorded in a run's recording ``paths`` (its segments in order): per component key
    (:attr:`FailureCount.key`) the sum of its events' ``failures`` and ``attempts``, the first individual event's
    error and the last error. A segment that cannot be read adds what was read of it before the error."""
    from aerodaas.recording.reader import read_messages, summarize_mcap  # lazy: heavy mcap

    out: dict[tuple, FailureCount] = {}
    for p in paths:
        try:
            topics = [c["topic"] for c in summarize_mcap(p)["channels"] if c["topic"].endswith("/events")]
            for topic, _schema, _t, ev in read_messages(p, topics=topics):
                got = _from_event(topic.split("/")[1], ev) if isinstance(ev, dict) else None
                if got is None:
                    continue
                have = out.setdefault(got.key, FailureCount(got.kind, got.robot, got.name))
                have.attempts += got.attempts
                have.failures += got.failures
                have.first_error = have.first_error or got.first_error
                have.last_error = got.last_error or have.last_error
        except Exception:  # noqa: BLE001 - unreadable: its events are not there to count
            continue
    return out


def assess(own: Iterable[FailureCount], recorded: dict[tuple, FailureCount] | None) -> list[FailureCount]:
    """The components over their limit (:attr:`FailureCount.over_limit`), each with the larger of its own counts
    (``own``: what its actor counted since it last started; several entries of one key, e.g. replicas of an
    analytics, are summed) and the recording's (``recorded``: :func:`tally_failures`, None without a recording),
    so that neither a restarted actor (own counts reset) nor an unrecorded tail (the failures after a
    component's last event) hides failures. Sorted by kind, robot, name."""
    merged: dict[tuple, FailureCount] = {}
    for c in own:
        have = merged.get(c.key)
        if have is None:
            merged[c.key] = FailureCount(c.kind, c.robot, c.name, c.attempts, c.failures, c.first_error,
                                         c.last_error, c.limit)
        else:
            have.attempts += c.attempts
            have.failures += c.failures
            have.first_error = have.first_error or c.first_error
            have.last_error = c.last_error or have.last_error
            have.limit = min(have.limit, c.limit)
    for key, r in (recorded or {}).items():
        have = merged.setdefault(key, FailureCount(r.kind, r.robot, r.name))
        have.attempts = max(have.attempts, r.attempts)
        have.failures = max(have.failures, r.failures)
        have.first_error = r.first_error or have.first_error
        have.last_error = have.last_error or r.last_error
    return sorted((c for c in merged.values() if c.over_limit), key=lambda c: (c.kind.value, c.robot or "", c.name))
