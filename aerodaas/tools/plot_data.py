"""What ``aerodaas plot`` draws, read from a recording: per robot the planned waypoints (from ``/{robot}/mission/plan``
or rebuilt from the commands flown), the flown path, altitude, battery and mission states over time, per-frame
latency records, and the moving targets' ground truth (:func:`load_plot_data`, :func:`planned_and_flown`,
:func:`tracking_segments`). Positions are local ENU metres, times seconds since the recording's first message."""
from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aerodaas.recording.reader import (_TRUNCATION_ERRORS, MISSION_RESULT_TOPIC, MISSION_STATE_TOPIC, read_messages,
                        summarize_mcap)


TARGETS_TOPIC = "/world/targets"


# --------------------------------------------------------------------------------------------------------------
# data extraction
# --------------------------------------------------------------------------------------------------------------
@dataclass
class PlannedWaypoint:
    """One planned waypoint: ``local`` = (x east, y north, z up) metres from the robot's home; ``order`` = 1-based
    position in the order waypoints were first commanded (``None``: never commanded); ``reached`` = a
    ``waypoint_reached`` event was recorded for it."""

    id: str
    local: tuple[float, float, float]
    order: int | None = None
    reached: bool = False
    mission: str | None = None
    priority: int | None = None


@dataclass
class TargetTrack:
    """Ground truth of one moving target: ``t`` s since the recording start, ``xy`` (N, 2) ENU metres with NaN
    rows where the target was not present in the world."""

    id: str
    class_name: str
    t: np.ndarray
    xy: np.ndarray


@dataclass
class RobotRun:
    """What the figures need about one robot. Times are seconds since the first message of the recording;
    positions ENU metres from home; battery percent (0-100); latencies milliseconds per frame."""

    robot: str
    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    position: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    battery_pct: np.ndarray = field(default_factory=lambda: np.zeros(0))
    states: list[tuple[float, str]] = field(default_factory=list)  # (t, state entered), time-sorted
    planned: list[PlannedWaypoint] = field(default_factory=list)  # in visiting order (see module doc)
    plan_source: str = "none"  # "plan" (/{robot}/mission/plan), "commands" (nav/command + events) or "none"
    latency: dict[str, np.ndarray] = field(default_factory=dict)  # e2e_ms, inference_ms, post_ms, overhead_ms
    events: list[tuple[float, dict]] = field(default_factory=list)
    outcome: str | None = None

    def state_at(self, t: np.ndarray) -> np.ndarray:
        """Mission state (str array) in force at each time of ``t`` (s); ``""`` before the first transition."""
        if not self.states:
            return np.full(len(t), "", dtype=object)
        st_t = np.array([s[0] for s in self.states])
        names = np.array([""] + [s[1] for s in self.states], dtype=object)
        return names[np.searchsorted(st_t, np.asarray(t), side="right")]


@dataclass
class RunData:
    """A recording reduced to plain arrays: ``robots`` by id, ``targets`` by target id, ``t0_ns`` the log time
    (ns) that is t = 0 s, ``finished`` False for a crashed recording, ``notes`` things worth telling the user."""

    path: Path
    finished: bool
    t0_ns: int | None
    robots: dict[str, RobotRun]
    targets: dict[str, TargetTrack]
    notes: list[str] = field(default_factory=list)


_ROBOT_TOPIC = re.compile(r"^/(?P<robot>.+)/(?P<kind>odometry|latency|events|nav/command|mission/plan)$")


def _vec3(v: Any) -> tuple[float, float, float] | None:
    try:
        x, y, z = (float(c) for c in v)
    except (TypeError, ValueError):
        return None
    return (x, y, z) if all(math.isfinite(c) for c in (x, y, z)) else None


def _num(v: Any, default: float = math.nan) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return default


def load_plot_data(path: str | Path) -> RunData:
    """Read the JSON channels the figures need from an MCAP recording (odometry, mission state, events, navigation
    commands, mission plan, per-frame latency, target ground truth, mission result).

    Works on unfinished (crashed) recordings: what is readable up to the last complete chunk is used, and reading
    stops quietly at a corrupt record (a note is added). Raises ``FileNotFoundError`` / ``OSError`` if the file
    cannot be opened and ``ValueError`` if it is not an MCAP file.
    """
    path = Path(path)
    summary = summarize_mcap(path)
    notes: list[str] = []
    if not summary["finished"]:
        notes.append(f"{path} is unfinished (the recorder did not close it); plotting what was readable")
    by_topic = _read_by_topic(path, summary, notes)
    times = [m[0][0] for m in by_topic.values() if m]
    t0_ns = summary["start_ns"] if summary["start_ns"] is not None else (min(times) if times else None)
    if times and t0_ns is not None:
        t0_ns = min(t0_ns, min(times))

    def sec(t_ns: int) -> float:
        return (t_ns - t0_ns) / 1e9 if t0_ns is not None else 0.0

    robots: dict[str, RobotRun] = {}

    def robot(name: str) -> RobotRun:
        if name not in robots:
            robots[name] = RobotRun(name)
        return robots[name]

    per_robot: dict[tuple[str, str], list[tuple[int, dict]]] = {}
    for topic, msgs in by_topic.items():
        m = _ROBOT_TOPIC.match(topic)
        if m:
            per_robot[(m["robot"], m["kind"])] = msgs
            robot(m["robot"])
    state_msgs = by_topic.get(MISSION_STATE_TOPIC, [])
    result_msgs = by_topic.get(MISSION_RESULT_TOPIC, [])
    for _t, msg in state_msgs + result_msgs:
        if isinstance(msg.get("robot"), str):
            robot(msg["robot"])

    for name, r in robots.items():
        _fill_robot(r, name, per_robot, state_msgs, result_msgs, sec)
    targets = _target_tracks(by_topic.get(TARGETS_TOPIC, []), sec)
    return RunData(path, bool(summary["finished"]), t0_ns, dict(sorted(robots.items())), targets, notes)


def _read_by_topic(path: Path, summary: dict, notes: list[str]) -> dict[str, list[tuple[int, Any]]]:
    """The JSON messages of the robot channels and the mission state, result and target channels, per topic in
    time order (ns); reading stops at a corrupt record, with a note."""
    topics = sorted({c["topic"] for c in summary["channels"]
                     if c["encoding"] == "json" and (_ROBOT_TOPIC.match(c["topic"]) or c["topic"] in
                                                      (MISSION_STATE_TOPIC, MISSION_RESULT_TOPIC, TARGETS_TOPIC))})
    by_topic: dict[str, list[tuple[int, Any]]] = {}
    if topics:
        try:
            for topic, _schema, t_ns, msg in read_messages(path, topics=topics):
                if isinstance(msg, dict):
                    by_topic.setdefault(topic, []).append((t_ns, msg))
        except _TRUNCATION_ERRORS as e:
            notes.append(f"stopped reading at a corrupt record ({type(e).__name__}: {e}); plotting what was read")
    for msgs in by_topic.values():  # unfinished files are read in write order
        msgs.sort(key=lambda m: m[0])
    return by_topic


def _fill_robot(r: RobotRun, name: str, per_robot: dict, state_msgs: list, result_msgs: list, sec: Any) -> None:
    """Robot ``name``'s odometry, states, outcome, events, per-frame latency and planned waypoints (times in
    seconds from the recording's start: ``sec(t_ns)``)."""
    odo = [(sec(t), msg) for t, msg in per_robot.get((name, "odometry"), [])
           if _vec3(msg.get("position")) is not None]
    if odo:
        r.t = np.array([t for t, _ in odo])
        r.position = np.array([_vec3(msg["position"]) for _, msg in odo])
        r.battery_pct = np.array([_num(msg.get("battery_pct")) for _, msg in odo])
    r.states = [(sec(t), str(msg["state"])) for t, msg in state_msgs
                if "state" in msg and msg.get("robot", name) == name]
    results = [msg for _t, msg in result_msgs if msg.get("robot", name) == name]
    r.outcome = results[-1].get("outcome") if results else None
    r.events = [(sec(t), msg) for t, msg in per_robot.get((name, "events"), [])]
    lat = [msg for _t, msg in per_robot.get((name, "latency"), [])]
    if lat:
        e2e = np.array([_num(m.get("e2e_ms")) for m in lat])
        inf = np.array([_num(m.get("inference_ms"), 0.0) for m in lat])
        post = np.array([_num(m.get("post_ms"), 0.0) for m in lat])
        ovh = np.array([_num(m.get("overhead_ms"), max(0.0, _num(m.get("e2e_ms"), 0.0) - _num(
            m.get("inference_ms"), 0.0) - _num(m.get("post_ms"), 0.0))) for m in lat])
        r.latency = {"e2e_ms": e2e, "inference_ms": inf, "post_ms": post, "overhead_ms": ovh}
    _planned_waypoints(r, per_robot.get((name, "mission/plan"), []), per_robot.get((name, "nav/command"), []),
                       sec)


def _target_tracks(msgs: list[tuple[int, dict]], sec: Any) -> dict[str, TargetTrack]:
    """Each target's ground-truth track (x, y ENU m; NaN while absent) from the ``/world/targets`` messages."""
    targets: dict[str, TargetTrack] = {}
    samples: dict[str, dict[float, tuple[float, float]]] = {}
    classes: dict[str, str] = {}
    for t_ns, msg in msgs:
        for tg in msg.get("targets") or []:
            if not isinstance(tg, dict) or "id" not in tg:
                continue
            tid = str(tg["id"])
            classes.setdefault(tid, str(tg.get("class_name", "")))
            present = bool(tg.get("present", True))
            xy = (_num(tg.get("x")), _num(tg.get("y"))) if present else (math.nan, math.nan)
            samples.setdefault(tid, {})[sec(t_ns)] = xy  # dedupes the same instant seen by several cameras
    for tid, s in samples.items():
        ts = np.array(sorted(s))
        targets[tid] = TargetTrack(tid, classes[tid], ts, np.array([s[t] for t in ts], dtype=float).reshape(-1, 2))
    return targets


def _planned_waypoints(r: RobotRun, plan_msgs: list[tuple[int, dict]], cmd_msgs: list[tuple[int, dict]],
                       sec: Callable[[int], float]) -> None:
    """Fill ``r.planned`` / ``r.plan_source`` (see the module docstring for the rules)."""
    commanded: dict[str, tuple[float, tuple[float, float, float] | None, dict]] = {}  # id -> (t, local, extra)
    for t_ns, msg in cmd_msgs:
        wp = msg.get("waypoint") if isinstance(msg.get("waypoint"), dict) else {}
        wid = wp.get("id") if wp else msg.get("waypoint")
        if wid is None or str(wid) in commanded:
            continue
        commanded[str(wid)] = (sec(t_ns), _vec3(msg.get("local")), {"priority": msg.get("priority")})
    for t, ev in r.events:
        if ev.get("event") == "navigate" and ev.get("waypoint") is not None:
            wid = str(ev["waypoint"])
            if wid not in commanded or commanded[wid][0] > t:
                prev = commanded.get(wid)
                local = _vec3(ev.get("target")) or (prev[1] if prev else None)
                commanded[wid] = (t, local, {"priority": ev.get("priority"), "mission": ev.get("mission")})
    reached = {str(ev.get("waypoint")) for _t, ev in r.events if ev.get("event") == "waypoint_reached"}

    planned: dict[str, PlannedWaypoint] = {}
    for _t_ns, msg in plan_msgs:
        for mission in msg.get("missions") or []:
            if not isinstance(mission, dict):
                continue
            for item in mission.get("items") or []:
                if not isinstance(item, dict) or item.get("id") is None:
                    continue
                local = _vec3(item.get("local"))
                wid = str(item["id"])
                if local is None or wid in planned:  # velocity commands (tracking) have no waypoint
                    continue
                prio = mission.get("priority")
                planned[wid] = PlannedWaypoint(wid, local, mission=mission.get("name"),
                                               priority=int(prio) if isinstance(prio, (int, float)) else None)
    r.plan_source = "plan" if planned else "none"
    for wid, (_t, local, extra) in commanded.items():  # commanded but absent from the plan (or no plan channel)
        if wid not in planned and local is not None:
            planned[wid] = PlannedWaypoint(wid, local, mission=extra.get("mission"), priority=extra.get("priority"))
            if r.plan_source == "none":
                r.plan_source = "commands"
    order = sorted((commanded[w][0], w) for w in planned if w in commanded)
    for i, (_t, wid) in enumerate(order, start=1):
        planned[wid].order = i
    rest = [w for w in planned if w not in commanded]  # never commanded: plan order
    for wid in planned:
        planned[wid].reached = wid in reached
    r.planned = [planned[w] for _t, w in order] + [planned[w] for w in rest]


def planned_and_flown(run: RunData | str | Path, robot: str | None = None
                      ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """``(waypoint ids, planned (K, 3), flown (N, 3))`` for ``robot`` (default: the first robot): planned waypoint
    positions in visiting order and the odometry positions, ENU metres from home."""
    data = run if isinstance(run, RunData) else load_plot_data(run)
    if not data.robots:
        raise ValueError(f"{data.path} has no robot channels")
    r = data.robots[robot] if robot is not None else next(iter(data.robots.values()))
    planned = np.array([w.local for w in r.planned], dtype=float).reshape(-1, 3)
    return [w.id for w in r.planned], planned, r.position


def tracking_segments(r: RobotRun) -> np.ndarray:
    """Boolean per odometry segment (length N-1): True where the segment starts while the mission state is
    ``TRACKING``."""
    if len(r.t) < 2:
        return np.zeros(0, dtype=bool)
    return r.state_at(r.t[:-1]) == "TRACKING"
