"""LAPLAN's arrival predictors, learned online from the tasks that have arrived (never from anything later).

* :class:`ArrivalPredictor` — periodic frames: per drone, the period is the last frame gap (or the median of the
  last ``gap_window``); the frames of the next ``horizon_ms`` are predicted at ``last + k * period``.
* :class:`BurstArrivalPredictor` — bursty video: per drone, the frame gaps seen decide between
  a *regular* drone (most gaps near their median) and an *irregular* one (heavy-tailed gaps), and a regular
  drone's gaps are split into burst gaps and idle gaps (longer than ``idle_factor`` x the median; a drone is
  regular when most of its non-idle gaps are within ``regular_band`` of the median):

  - regular: the next frames are predicted on the drone's phase grid, ``anchor + k * b`` with ``b`` the median
    gap — the burst's gap, not the silence before the burst (on/off video) — and ``anchor`` the drone's last frame
    made on time. A frame that repeats a model within ``same_frame_ms`` is a stalled link's flush (the buffered
    frames delivered a few ms apart): it is not an anchor, so the frames after a flush are predicted where they
    are made, on the old grid. When the drone's completed bursts have had the same number of frames (within
    one; at least two bursts seen), the burst is predicted to end after that many frames: after them the drone is
    predicted idle (no frames) until it sends again.
  - irregular: one next frame at the ``quantile`` of the gap *conditioned on the time already waited*: among
    the gaps seen (pooled over drones once there are ``min_pooled``), those longer than ``now - last``; its gain
    in the plan is weighted by ``quantile`` (the chance it has come by then). For heavy-tailed (Pareto) gaps the
    hazard falls with the wait, so the predicted frame moves later the longer a drone is silent.

Non-anticipation: both predictors change only in :meth:`observe` (a task that has arrived) and read the clock
only through the ``now_ms`` given to :meth:`predict`.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from aerodaas.schedulers.analytics_base import AnalyticsTask

__all__ = ["ArrivalPredictor", "BurstArrivalPredictor", "Prediction"]

#: ``(arrival_ms, drone, model, wake_ms, frame_ms, weight)`` of one predicted task (see :meth:`ArrivalPredictor.predict`)
Prediction = tuple[float, str, str, float, float, float]


class ArrivalPredictor:
    """Per-drone periodic arrival model learned from the tasks seen (see the module docstring).

    ``overdue``: fraction of the period after which a missing frame stops the drone's predictions; ``same_frame_ms``:
    tasks of one drone this close in arrival time belong to one frame; ``frame_grace_ms``: how long the rest of a
    frame whose first tasks have arrived is still expected (its tasks are submitted one by one); ``gap_window``: the
    period is the median of the drone's last ``gap_window`` frame gaps (1: the last gap). Raises ValueError for a
    ``gap_window`` that is not an integer >= 1."""

    def __init__(self, overdue: float = 0.1, same_frame_ms: float = 50.0, frame_grace_ms: float = 20.0,
                 gap_window: int = 1) -> None:
        self.overdue, self.same_frame_ms, self.frame_grace_ms = overdue, same_frame_ms, frame_grace_ms
        if not (isinstance(gap_window, int) and gap_window >= 1):
            raise ValueError(f"gap_window must be an integer >= 1, got {gap_window!r}")
        self.gap_window = gap_window
        #: drone -> [current frame arrival ms, period ms or None, models seen in it, models of the frame before]
        self.drones: dict[str, list] = {}
        #: drone -> its last ``gap_window`` frame gaps (ms)
        self._gaps: dict[str, deque] = {}

    def observe(self, task: AnalyticsTask) -> None:
        """Learn from an arrived task: a task within ``same_frame_ms`` of its drone's current frame joins it; a
        later one starts the next frame and sets the drone's period to the gap between the two frames."""
        st = self.drones.get(task.drone)
        if st is None:
            self.drones[task.drone] = [task.arrival_ms, None, [task.model], []]
            self._new_drone(task)
        elif abs(task.arrival_ms - st[0]) < self.same_frame_ms:  # same frame
            if task.model not in st[2]:
                st[2].append(task.model)
            else:
                self._repeated_model(task)
        elif task.arrival_ms > st[0]:
            gap = task.arrival_ms - st[0]
            self._new_frame(task, gap)
            if self.gap_window == 1:
                st[1] = gap
            else:  # the median of the last gaps: a burst's gap, not the silence before it or a flush's 2 ms
                gaps = self._gaps.setdefault(task.drone, deque(maxlen=self.gap_window))
                gaps.append(gap)
                srt = sorted(gaps)
                st[1] = srt[len(srt) // 2]
            st[0], st[2], st[3] = task.arrival_ms, [task.model], st[2]

    # hooks for subclasses (called before the drone's record is updated)
    def _new_drone(self, task: AnalyticsTask) -> None:
        pass

    def _repeated_model(self, task: AnalyticsTask) -> None:
        pass

    def _new_frame(self, task: AnalyticsTask, gap_ms: float) -> None:
        pass

    def _rest_of_frame(self, now_ms: float, drone: str, last: float, seen: list, before: list) -> list[Prediction]:
        if now_ms < last + self.frame_grace_ms:
            return [(now_ms, drone, m, last + self.frame_grace_ms, last, 1.0) for m in before if m not in seen]
        return []

    def _frames(self, now_ms: float, drone: str, t: float, period: float, until: float, models: list,
                count: float = math.inf) -> list[Prediction]:
        """Up to ``count`` frames from ``t`` every ``period`` until ``until`` (ms), each with its ``models``."""
        out: list[Prediction] = []
        while t <= until and count > 0:
            wake = t if t > now_ms else t + self.overdue * period
            out += [(max(t, now_ms), drone, m, wake, t, 1.0) for m in models]
            t += period
            count -= 1
        return out

    def predict(self, now_ms: float, horizon_ms: float) -> list[Prediction]:
        """``(arrival_ms, drone, model, wake_ms, frame_ms, weight)`` of the tasks still expected: the rest of a frame
        being submitted (the previous frame's models not seen yet, within ``frame_grace_ms``) and each drone's next
        frames within ``horizon_ms`` of its next frame (so the set changes only when a task arrives or a frame goes
        missing). An overdue frame within its grace is predicted at ``now_ms`` and ``wake_ms`` (when to re-plan if
        it has not come) is the end of its grace; otherwise ``wake_ms`` is its predicted arrival. ``frame_ms``: the
        frame's own (predicted) time, which identifies it; ``weight``: the factor on its gain in the plan (1 here)."""
        out: list[Prediction] = []
        for drone, (last, period, seen, before) in self.drones.items():
            out += self._rest_of_frame(now_ms, drone, last, seen, before)
            if not period or period <= 0:
                continue
            t = last + period
            if t + self.overdue * period <= now_ms:
                continue  # a frame is missing: do not wait for this drone
            models = seen if len(seen) >= len(before) else before
            out += self._frames(now_ms, drone, t, period, t + horizon_ms, models)
        return out


@dataclass
class _Bursts:
    """One drone's burst/idle state (:class:`BurstArrivalPredictor`)."""

    gaps: deque                        # its last frame gaps (ms)
    anchor: float                      # its last frame made on time (ms): the phase grid's origin
    prev_anchor: float                 # the anchor before the current frame (restored if that frame is a flush)
    flushed: bool = False              # the current frame repeated a model: a stalled link's flush
    run: int = 1                       # frames in the current burst
    complete: bool = False             # the current burst began after an idle gap (its length counts)
    runs: deque = field(default_factory=lambda: deque(maxlen=3))  # frames in its last completed bursts


class BurstArrivalPredictor(ArrivalPredictor):
    """Burst/idle-aware arrival model (see the module docstring). Options: ``window`` (frame gaps kept per drone,
    default 16), ``idle_factor`` (a gap this many times the median gap is idle, default 2), ``regular_band`` and
    ``regular_share`` (a drone is regular when at least ``regular_share`` of its non-idle gaps are within
    ``regular_band`` x the median of it; defaults 0.25, 0.75: uniform +-20 % jitter is regular, Pareto gaps of
    shape 1.5 are not, about half of them being within the band), ``quantile`` (an irregular drone's next frame: this quantile of the gap
    given the wait, also its gain's weight; default 0.5), ``pooled_window`` / ``min_pooled`` (the pooled gaps for
    irregular drones: the last 200, used from 20), and :class:`ArrivalPredictor`'s ``overdue``, ``same_frame_ms``,
    ``frame_grace_ms``. Raises ValueError naming an option out of range."""

    def __init__(self, *, window: int = 16, idle_factor: float = 2.0, regular_band: float = 0.25,
                 regular_share: float = 0.75, quantile: float = 0.5, pooled_window: int = 200, min_pooled: int = 20,
                 **kw) -> None:
        super().__init__(**kw)
        for name, v, ok in (("window", window, isinstance(window, int) and window >= 3),
                            ("idle_factor", idle_factor, idle_factor > 1),
                            ("regular_band", regular_band, 0 < regular_band < 1),
                            ("regular_share", regular_share, 0 < regular_share <= 1),
                            ("quantile", quantile, 0 < quantile < 1),
                            ("pooled_window", pooled_window, isinstance(pooled_window, int) and pooled_window >= 1),
                            ("min_pooled", min_pooled, isinstance(min_pooled, int) and min_pooled >= 1)):
            if not ok:
                raise ValueError(f"burst predictor: {name} out of range: {v!r}")
        self.window, self.idle_factor, self.quantile = window, float(idle_factor), float(quantile)
        self.regular_band, self.regular_share, self.min_pooled = float(regular_band), float(regular_share), min_pooled
        self.bursts: dict[str, _Bursts] = {}
        self._pooled: deque[float] = deque(maxlen=pooled_window)
        self._pooled_sorted: list[float] | None = None

    def _new_drone(self, task: AnalyticsTask) -> None:
        self.bursts[task.drone] = _Bursts(deque(maxlen=self.window), task.arrival_ms, task.arrival_ms)

    def _repeated_model(self, task: AnalyticsTask) -> None:
        s = self.bursts[task.drone]
        if not s.flushed:  # a flush: the frame arrived late, so it does not set the phase
            s.flushed, s.anchor = True, s.prev_anchor

    def _new_frame(self, task: AnalyticsTask, gap_ms: float) -> None:
        s = self.bursts[task.drone]
        b = self.burst_gap(task.drone)
        if b is not None and gap_ms > self.idle_factor * b:  # an idle gap ends the burst
            if s.complete:
                s.runs.append(s.run)
            s.run, s.complete = 1, True
        else:
            s.run += 1
        s.gaps.append(gap_ms)
        self._pooled.append(gap_ms)
        self._pooled_sorted = None
        s.prev_anchor, s.anchor, s.flushed = s.anchor, task.arrival_ms, False

    def burst_gap(self, drone: str) -> float | None:
        """The median of ``drone``'s frame gaps seen (ms), None before its second frame."""
        s = self.bursts.get(drone)
        if s is None or not s.gaps:
            return None
        srt = sorted(s.gaps)
        return srt[len(srt) // 2]

    def regular(self, drone: str) -> bool:
        """Whether ``drone``'s gaps are regular: at least ``regular_share`` of its non-idle gaps (idle: over
        ``idle_factor`` x the median) within ``regular_band`` x the median of it; True while fewer than 4 are known."""
        s, b = self.bursts[drone], self.burst_gap(drone)
        if b is None or len(s.gaps) < 4:
            return True
        busy = [g for g in s.gaps if g <= self.idle_factor * b]
        near = sum(abs(g - b) <= self.regular_band * b for g in busy)
        return near >= self.regular_share * len(busy)

    def frames_left(self, drone: str) -> float:
        """Frames still expected in ``drone``'s current burst: inf unless its last completed bursts (>= 2) agree on
        their length within one frame; then that length (their least) less the frames seen, at least 0."""
        s = self.bursts[drone]
        if len(s.runs) < 2 or max(s.runs) - min(s.runs) > 1:
            return math.inf
        return max(0, min(s.runs) - s.run)

    def _gap_given_wait(self, drone: str, waited_ms: float) -> float | None:
        """The ``quantile`` of the drone's gap given it is longer than ``waited_ms``, from the pooled gaps once
        there are ``min_pooled`` of them (else the drone's own); None when no gap seen was that long."""
        if len(self._pooled) >= self.min_pooled:
            if self._pooled_sorted is None:
                self._pooled_sorted = sorted(self._pooled)
            srt = self._pooled_sorted
        else:
            srt = sorted(self.bursts[drone].gaps)
        lo = next((i for i, g in enumerate(srt) if g > waited_ms), None)
        if lo is None:
            return None
        tail = srt[lo:]
        return tail[min(len(tail) - 1, int(self.quantile * len(tail)))]

    def predict(self, now_ms: float, horizon_ms: float) -> list[Prediction]:
        """As :meth:`ArrivalPredictor.predict`, with the burst/idle rules of the module docstring."""
        out: list[Prediction] = []
        for drone, (last, _, seen, before) in self.drones.items():
            out += self._rest_of_frame(now_ms, drone, last, seen, before)
            b = self.burst_gap(drone)
            if not b or b <= 0:
                continue
            models = seen if len(seen) >= len(before) else before
            if not self.regular(drone):
                gap = self._gap_given_wait(drone, now_ms - last)
                if gap is not None and last + gap <= now_ms + horizon_ms:
                    t = last + gap
                    out += [(t, drone, m, t, t, self.quantile) for m in models]
                continue
            left = self.frames_left(drone)
            if left <= 0:
                continue  # the burst is over: predicted idle until the drone sends again
            anchor = self.bursts[drone].anchor
            k = max(1, math.ceil((last + self.same_frame_ms - anchor) / b))
            t = anchor + k * b
            if t + self.overdue * b <= now_ms:
                continue  # a frame is missing: do not wait for this drone
            out += self._frames(now_ms, drone, t, b, t + horizon_ms, models, left)
        return out
