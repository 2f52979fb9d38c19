"""Per-node accounting of ``aerodaas bench fleet --edge-nodes N``: what each node of a local
multi-node cluster carried and what it cost, over a window of the flight.

The window (:class:`FlightWindow`) opens ``settle_s`` after the drones' start hooks ran (the driver runs them just
before the flight: :func:`aerodaas.runtime.driver._supervise`) and closes ``window_s`` later, inside the flight, so
neither the actors' start (imports, the ground cache) nor their close is in it. At each end it reads, per node, the
CPU time (``psutil``: user + system, proc(5) ``utime``/``stime``) of every process of that node's raylet tree —
the node's system processes (``ray._private.node.Node.all_processes``) and all their descendants, so the node's
workers — and the driver's (counted on the head, node 0, where it connects); at the close also each process's PSS
(``/proc/<pid>/smaps_rollup`` via ``psutil.Process.memory_full_info``) and every actor Ray's GCS knows
(``ray._private.state.actors()``, the state the ``ray list actors`` command reads: name, class, node id, state).

Roles (:class:`Role`) split a node's cost into what grows with its drones (drone actors, its recorder actor) and
what a node costs whatever it carries (raylet, Ray's agents and log monitor, idle workers; on the head also the
GCS and the driver). Rates are per simulated second: ``cpu_s / (window_s * speedup)``; the benchmark flies at
speedup 1.
"""
from __future__ import annotations

import enum
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import psutil

__all__ = ["Role", "ProcSample", "NodeWindow", "FlightWindow", "role_of", "snapshot", "gcs_actors",
           "recorder_throughput", "drones_in_actor", "ClusterLayout", "node_report"]


class Role(enum.Enum):
    """What a process is to the cost model; the value is its key in the JSON report."""

    DRONE = "drone_actors"
    RECORDER = "recorder_actors"
    RAYLET = "raylet"
    GCS = "gcs"
    DRIVER = "driver"
    OTHER = "ray_other"  # Ray's dashboard/runtime-env agents, log monitor, idle workers, other actors


def role_of(title: str, is_driver: bool = False) -> Role:
    """The role of a process from its title (``ray::DroneActor.run``, ``raylet``, ``gcs_server``...)."""
    if is_driver:
        return Role.DRIVER
    for key, role in (("DroneActor", Role.DRONE), ("RecorderActor", Role.RECORDER), ("raylet", Role.RAYLET),
                      ("gcs_server", Role.GCS)):
        if key in title:
            return role
    return Role.OTHER


@dataclass(frozen=True)
class ProcSample:
    """One process at one end of the window: its node (index into the cluster's edge nodes), role, CPU seconds
    so far, PSS in MiB (None when not read)."""

    node: int
    role: Role
    cpu_s: float
    pss_mb: float | None


def _tree(node: Any) -> list[psutil.Process]:
    """The system processes of a ``ray._private.node.Node`` and all their descendants (its workers)."""
    out: dict[int, psutil.Process] = {}
    for info in (i for infos in node.all_processes.values() for i in infos):
        try:
            p = psutil.Process(info.process.pid)
            out[p.pid] = p
            out.update({c.pid: c for c in p.children(recursive=True)})
        except psutil.NoSuchProcess:
            continue
    return list(out.values())


def snapshot(nodes: list[Any], with_pss: bool) -> dict[int, ProcSample]:
    """pid -> :class:`ProcSample` of every process of ``nodes`` (their order gives the node index) and of this
    driver (node 0). Processes that exit while being read are left out."""
    me = psutil.Process()
    found: list[tuple[int, psutil.Process]] = [(0, me)]
    for j, node in enumerate(nodes):
        found.extend((j, p) for p in _tree(node) if p.pid != me.pid)
    out: dict[int, ProcSample] = {}
    for j, p in found:
        try:
            t = p.cpu_times()
            title = " ".join(p.cmdline()[:1]) + " " + p.name()
            pss = getattr(p.memory_full_info(), "pss", None) if with_pss else None
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        out[p.pid] = ProcSample(j, role_of(title, p.pid == me.pid), t.user + t.system,
                                None if pss is None else pss / 2**20)
    return out


def gcs_actors() -> list[dict]:
    """Every actor Ray's GCS knows (``ray._private.state.actors()``): name, class, node id (hex), state."""
    from ray._private import state  # lazy: heavy ray, and only once the driver is connected

    return [{"name": a.get("Name") or "", "class": a.get("ActorClassName"), "state": a.get("State"),
             "node_id": (a.get("Address") or {}).get("NodeID")} for a in state.actors().values()]


@dataclass
class NodeWindow:
    """One node over the window: CPU seconds and PSS (MiB) by role, process counts by role."""

    cpu_s: dict[Role, float] = field(default_factory=dict)
    pss_mb: dict[Role, float] = field(default_factory=dict)
    processes: dict[Role, int] = field(default_factory=dict)
    drone_actor_pss_mb: list[float] = field(default_factory=list)


@dataclass
class FlightWindow:
    """Measures ``nodes`` over a window of the flight in a background thread: :meth:`begin` is the drones' start
    hook (``Robot.on_mission_start``; only its first call counts), :meth:`stop` ends it early (the run ended
    first: then ``complete`` stays False). After :meth:`stop`: ``nodes`` (one :class:`NodeWindow` per node),
    ``window_s`` and ``actors`` (:func:`gcs_actors` at the close), or ``error``."""

    cluster_nodes: list[Any]
    settle_s: float
    window_s: float
    nodes: list[NodeWindow] = field(default_factory=list)
    actors: list[dict] = field(default_factory=list)
    measured_s: float = 0.0
    complete: bool = False
    error: str | None = None
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def begin(self, _robot: Any = None) -> None:
        """Open the window (``settle_s`` from now) in a background thread; later calls do nothing."""
        with self._lock:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="bench-fleet-window", daemon=True)
                self._thread.start()

    def stop(self) -> None:
        """End the window now if still open and wait for the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(60)

    def _run(self) -> None:
        try:
            self._measure()
        except Exception as e:  # noqa: BLE001 - reported in the benchmark's JSON, never fatal to the run
            self.error = f"{type(e).__name__}: {e}"

    def _measure(self) -> None:
        if self._stop.wait(self.settle_s):
            self.error = "the run ended before the window opened"
            return
        a, t0 = snapshot(self.cluster_nodes, with_pss=False), time.monotonic()
        self.complete = not self._stop.wait(self.window_s)
        self.actors = gcs_actors()
        b, self.measured_s = snapshot(self.cluster_nodes, with_pss=True), time.monotonic() - t0
        self.nodes = [NodeWindow() for _ in self.cluster_nodes]
        for pid, s in b.items():
            w = self.nodes[s.node]
            before = a.get(pid)
            w.cpu_s[s.role] = w.cpu_s.get(s.role, 0.0) + s.cpu_s - (before.cpu_s if before is not None else 0.0)
            w.pss_mb[s.role] = w.pss_mb.get(s.role, 0.0) + (s.pss_mb or 0.0)
            w.processes[s.role] = w.processes.get(s.role, 0) + 1
            if s.role is Role.DRONE and s.pss_mb is not None:
                w.drone_actor_pss_mb.append(s.pss_mb)


def drones_in_actor(host_id: str) -> int:
    """Drones a drone actor carries from its host id: ``drone/<robot>`` -> 1, ``drones/<first>+<m>`` -> m + 1
    (:func:`aerodaas.runtime.dataflow` names grouped actors so)."""
    if host_id.startswith("drones/") and "+" in host_id:
        return int(host_id.rsplit("+", 1)[1]) + 1
    return 1


def recorder_throughput(paths: list[Path], seconds: float) -> dict[str, float]:
    """Messages and bytes of the MCAP files ``paths`` (their summary's statistics, read with the ``mcap`` library;
    size on disk) over ``seconds``: ``messages``, ``bytes``, ``messages_per_s``, ``mb_per_s`` (MiB/s). Raises
    OSError / mcap's errors for an unreadable file."""
    from mcap.reader import make_reader  # lazy: only at the end of a recorded run

    messages, size = 0, 0
    for path in paths:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        messages += int(summary.statistics.message_count) if summary and summary.statistics else 0
        size += os.path.getsize(path)
    per = max(seconds, 1e-9)
    return {"messages": messages, "bytes": size, "messages_per_s": round(messages / per, 1),
            "mb_per_s": round(size / 2**20 / per, 3)}


def _robot_counts(res: Any, robots: list[str]) -> dict[str, float]:
    """Control ticks and frames of ``robots`` in the run's result ``res`` (a MissionResult): ticks, missed ticks,
    camera ticks, frames the colocated analytics processed, frames the recorder refused (its queue full: the
    cameras' ``recorder_dropped``, as the recorder counts them), and the two percentages."""
    ticks = sum(res.robots.get(r, {}).get("ticks", 0) for r in robots)
    missed = sum(res.robots.get(r, {}).get("missed_ticks", 0) for r in robots)
    cams = sum(c.get("ticks", 0) for r in robots for c in (res.stats.get(r) or {}).get("cameras", {}).values())
    analysed = sum((a or {}).get("processed", 0) for r in robots for a in (res.stats.get(r) or {}).get("analytics", []))
    refused = sum(c.get("recorder_dropped", 0) for r in robots
                  for c in (res.stats.get(r) or {}).get("cameras", {}).values())
    return {"ticks": ticks, "missed_ticks": missed, "missed_ticks_pct": 100.0 * missed / max(ticks, 1),
            "camera_ticks": cams, "frames_analysed": analysed, "frames_refused_by_recorder": refused,
            "dropped_frames_pct": 100.0 * (cams - analysed) / max(cams, 1)}


@dataclass(frozen=True)
class ClusterLayout:
    """What the benchmark placed where: the edge nodes' Ray node ids (hex, in order: node 0 is the head), the run's
    id (actor names are ``aerodaas/<run>/<host id>``), each robot's node index by its compute (robot -> j), and
    the MCAP files of each node's recorder (j -> paths; empty without a recording)."""

    node_ids: list[str]
    run_id: str
    robot_node: dict[str, int]
    recordings: dict[int, list[Path]]


def node_report(window: FlightWindow, layout: ClusterLayout, res: Any, mission_s: float) -> list[dict]:
    """The ``nodes`` list of a fleet row: per edge node its id, the drone actors Ray's GCS placed on it and the
    drones they carry, the robots flying from its compute with their missed ticks and dropped frames, CPU-seconds
    per simulated second by :class:`Role` over the window (and per drone: the drone actors' CPU / drones), PSS by
    role (MiB) and per drone actor, the GCS actors on it, and its recorder's messages/s and MiB/s over
    ``mission_s``."""
    prefix = f"aerodaas/{layout.run_id}/"
    out = []
    for j, nid in enumerate(layout.node_ids):
        w = window.nodes[j] if j < len(window.nodes) else NodeWindow()
        alive = [a for a in window.actors if a["node_id"] == nid and a["state"] == "ALIVE"]
        drone_actors = sorted(a["name"] for a in alive if a["class"] == "DroneActor")
        drones = sum(drones_in_actor(n[len(prefix):]) for n in drone_actors if n.startswith(prefix))
        robots = sorted(r for r, k in layout.robot_node.items() if k == j)
        sim_s = max(window.measured_s, 1e-9)  # speedup 1: a wall second is a simulated second
        cpu = {r.value: round(v / sim_s, 4) for r, v in sorted(w.cpu_s.items(), key=lambda kv: kv[0].value)}
        rec = recorder_throughput(layout.recordings.get(j, []), mission_s) if layout.recordings.get(j) else None
        out.append({
            "node": j, "node_id": nid, "head": j == 0, "drone_actors": drone_actors, "drones": drones,
            "robots": robots, **_robot_counts(res, robots),
            "window_s": round(window.measured_s, 2), "cpu_s_per_sim_s": cpu,
            "cpu_s_per_sim_s_total": round(sum(w.cpu_s.values()) / sim_s, 4),
            "cpu_s_per_drone_per_sim_s": (round(w.cpu_s.get(Role.DRONE, 0.0) / sim_s / drones, 4) if drones
                                          else None),
            "pss_mb": {r.value: round(v, 1) for r, v in sorted(w.pss_mb.items(), key=lambda kv: kv[0].value)},
            "pss_mb_total": round(sum(w.pss_mb.values()), 1),
            "pss_mb_per_drone_actor": (round(sum(w.drone_actor_pss_mb) / len(w.drone_actor_pss_mb), 1)
                                       if w.drone_actor_pss_mb else None),
            "processes": {r.value: n for r, n in sorted(w.processes.items(), key=lambda kv: kv[0].value)},
            "gcs_actors": len(alive), "recorder": rec})
    return out
