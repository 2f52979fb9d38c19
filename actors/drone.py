"""DroneActor: one robot — its backend (the embedded simulator), flight control, navigation executor, and its
odometry and stat-stream sensors (co-located in this actor because their data is the vehicle state itself).

The simulation loop runs in a thread of this (threaded) actor so that pause/resume/end and status calls are
served while it flies. Simulated time advances ``speedup`` x wall time, or, in lock-step mode, frame by
frame after the analytics have consumed each frame.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any

import ray

from aerodaas.config import RobotConfig, SimulationConfig
from aerodaas.fsm import MissionFSM, MissionState as S
from aerodaas.models import ActionCommand, VelocityCommand, Waypoint
from aerodaas.safety import SafetyGate, SafetyViolation
from aerodaas.sim.vehicle import SimVehicle

from .streams import Outlet, wait_tree


@ray.remote(num_cpus=0, max_concurrency=8)
class DroneActor:
    def __init__(self, robot_cfg: dict, sim_cfg: dict, scheduler: Any, recorder: Any, epoch_ns: int) -> None:
        self.cfg = RobotConfig.model_validate(robot_cfg)
        self.sim = SimulationConfig.model_validate(sim_cfg)
        self.vehicle = SimVehicle(self.cfg.id, self.cfg.home, self.cfg.limits, self.cfg.battery, self.cfg.noise)
        self.gate = SafetyGate(self.cfg.safety, self.cfg.limits, self.cfg.home)
        self.rejected: list[dict] = []
        self.preplanned_left = 0
        self.idle_since: float | None = None
        self.flew_something = False
        self.scheduler = scheduler
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.fsm = MissionFSM(self._on_transition)
        self.cameras: list[dict] = []  # {"actor", "fps", "outlet", "next_t", "seq"}
        self.odom_outlets: list[Outlet] = []
        self.state_outlets: list[Outlet] = []
        self.visited: list[dict] = []
        self.events: list[dict] = []
        self.active_wp: str | None = None
        self.hold_until: float | None = None
        self.last_cmd_kind: str | None = None
        self._paused_from: S | None = None
        self._pause_req = threading.Event()
        self._resume_req = threading.Event()
        self._end_req: str | None = None
        self.outcome: str | None = None
        self.error: str | None = None
        self.missed_ticks = 0
        self.ticks = 0
        self.preplanned_total = 0

    # ------------------------------------------------------------------ wiring
    def connect(self, cameras: list[tuple[Any, float]], odom_subs: list[tuple], state_subs: list[tuple],
                preplanned_total: int) -> bool:
        ls = self.sim.lockstep
        self.cameras = [{"actor": a, "fps": fps, "outlet": Outlet(a, "capture", "capture", 1, ls), "next_t": 0.0,
                         "seq": 0} for a, fps in cameras]
        self.odom_outlets = [Outlet(a, m, p, b, ls) for a, m, p, b in odom_subs]
        self.state_outlets = [Outlet(a, m, p, b, False) for a, m, p, b in state_subs]
        self.preplanned_total = preplanned_total
        return True

    # ------------------------------------------------------------------ recording helpers
    def _t_ns(self, t: float) -> int:
        return self.epoch_ns + int(t * 1e9)

    def _event(self, kind: str, **kw: Any) -> None:
        ev = {"robot": self.cfg.id, "t": self.vehicle.t, "event": kind, **kw}
        self.events.append(ev)
        if self.recorder is not None:
            self.recorder.json.remote(f"/{self.cfg.id}/events", self._t_ns(self.vehicle.t), ev, "aerodaas.MissionEvent")

    def _on_transition(self, old: S, new: S, t: float) -> None:
        msg = {"robot": self.cfg.id, "state": new.value, "previous": old.value, "t": t}
        if self.recorder is not None:
            self.recorder.json.remote("/mission/state", self._t_ns(t), msg, "aerodaas.MissionState")
        env = {"kind": "value", "data": msg, "meta": None, "sim_t": t, "trace": {}}
        for o in self.state_outlets:
            o.send(env)

    # ------------------------------------------------------------------ control API (served concurrently)
    def pause_mission(self) -> bool:
        self._pause_req.set()
        return True

    def resume_mission(self) -> bool:
        self._resume_req.set()
        return True

    def end_mission(self, reason: str = "aborted") -> bool:
        self._end_req = reason
        return True

    def status(self) -> dict:
        s = self.vehicle.state
        cam_drop = sum(c["outlet"].dropped for c in self.cameras)
        return {"robot": self.cfg.id, "t": self.vehicle.t, "state": self.fsm.state.value,
                "position": [float(v) for v in s.position], "battery_pct": self.vehicle.battery_pct,
                "visited": len(self.visited), "preplanned_total": self.preplanned_total,
                "frames": sum(c["seq"] for c in self.cameras), "frames_dropped_at_camera": cam_drop,
                "outcome": self.outcome, "missed_ticks": self.missed_ticks, "ticks": self.ticks}

    def report(self) -> dict:
        return {**self.status(), "visited_waypoints": self.visited, "events": self.events, "error": self.error,
                "rejected": self.rejected, "safety": self.gate.stats(),
                "state_history": [(t, s.value) for t, s in self.fsm.history]}

    # ------------------------------------------------------------------ main loop
    def run(self, timeout_s: float | None = None) -> dict:
        """Fly the mission to its end; returns :meth:`report`. ``timeout_s`` is wall-clock seconds."""
        try:
            self._run(timeout_s)
        except Exception as e:  # never lose the report: record the failure and land the sim vehicle
            import traceback

            self.error = f"{type(e).__name__}: {e}"
            self.outcome = "failed"
            self._event("error", message=self.error, traceback=traceback.format_exc())
        if self.recorder is not None:
            self.recorder.json.remote("/mission/result", self._t_ns(self.vehicle.t),
                                      {"robot": self.cfg.id, "outcome": self.outcome, "visited": len(self.visited),
                                       "preplanned_total": self.preplanned_total, "t": self.vehicle.t,
                                       "error": self.error}, "aerodaas.MissionResult")
        return self.report()

    def _run(self, timeout_s: float | None) -> None:
        v, fsm = self.vehicle, self.fsm
        dt = 1.0 / self.sim.physics_hz
        ctrl_every = max(1, round(self.sim.physics_hz / self.cfg.control_rate_hz))
        odom_rate = 10.0
        for s in self.cfg.sensors:
            if s.type == "odometry":
                odom_rate = float(s.properties.get("rate_hz", 10.0))
        odom_every = max(1, round(self.sim.physics_hz / odom_rate))
        fsm.transition(S.PREFLIGHT, v.t)
        fsm.transition(S.ARMED, v.t)
        v.arm()
        fsm.transition(S.TAKING_OFF, v.t)
        v.takeoff(self.cfg.takeoff_altitude)
        self._event("takeoff", altitude=self.cfg.takeoff_altitude)
        wall0 = time.monotonic()
        step = 0
        while True:
            step += 1
            v.step(dt)
            if step % odom_every == 0:
                self._publish_odometry()
            for cam in self.cameras:
                if v.t + 1e-9 >= cam["next_t"]:
                    cam["next_t"] += 1.0 / cam["fps"]
                    cam["seq"] += 1
                    ref = cam["outlet"].send(tuple(float(c) for c in v.state.position), v.state.yaw, v.t, cam["seq"])
                    if self.sim.lockstep and ref is not None:
                        wait_tree([ref])
            if step % ctrl_every == 0:
                self.ticks += 1
                if self._control():
                    break
            if self._end_req is not None:
                self.outcome = self._end_req
                self._event("end_requested", reason=self._end_req)
                break
            if timeout_s is not None and time.monotonic() - wall0 > timeout_s:
                self.outcome = "timeout"
                self._event("timeout", wall_s=timeout_s)
                break
            if not self.sim.lockstep:
                lag = wall0 + v.t / self.sim.speedup - time.monotonic()
                if lag > 0:
                    time.sleep(lag)
                elif step % ctrl_every == 0 and lag < -0.25:
                    self.missed_ticks += 1
        self._publish_odometry()

    def _publish_odometry(self) -> None:
        odom = self.vehicle.odometry().model_dump(mode="json")
        t_ns = self._t_ns(self.vehicle.t)
        if self.recorder is not None:
            self.recorder.odometry.remote(self.cfg.id, t_ns, odom)
        env = {"kind": "odometry", "data": odom, "meta": None, "sim_t": self.vehicle.t, "trace": {}}
        for o in self.odom_outlets:
            ref = o.send(env)
            if self.sim.lockstep and ref is not None:
                wait_tree([ref])
        self.last_odom = odom

    def _control(self) -> bool:
        """One control tick; returns True when the mission is over."""
        v, fsm = self.vehicle, self.fsm
        t, st = v.t, fsm.state
        pos = tuple(float(c) for c in v.state.position)
        if st == S.LANDING:
            if not v.state.in_air:
                fsm.transition(S.LANDED, t)
                v.disarm()
                self._event("landed")
                if self.outcome is None:
                    self.outcome = "success" if self.preplanned_left == 0 else "incomplete"
                return True
            return False
        if st == S.EMERGENCY:
            v.land()
            fsm.transition(S.LANDING, t)
            return False
        safety = self.cfg.safety
        if v.battery_pct < safety.critical_battery_pct and v.state.in_air:
            self._event("battery_critical", battery_pct=v.battery_pct)
            self.outcome = "failed"
            fsm.transition(S.EMERGENCY, t)
            return False
        if st == S.RETURNING:
            if math.hypot(pos[0], pos[1]) <= 0.5:
                v.land()
                fsm.transition(S.LANDING, t)
                self._event("landing", reason="return to launch")
            return False
        if v.battery_pct < safety.low_battery_rtl_pct and v.state.in_air:
            self._event("failsafe_rtl", battery_pct=v.battery_pct, threshold_pct=safety.low_battery_rtl_pct)
            self.outcome = "failsafe_rtl"
            self._return_to_launch(t, pos)
            return False
        if self._pause_req.is_set():
            self._pause_req.clear()
            if st != S.PAUSED and fsm.can(S.PAUSED):
                self._paused_from = st
                v.hold()
                fsm.transition(S.PAUSED, t)
                self._event("paused")
            return False
        if st == S.PAUSED:
            if not self._resume_req.is_set():
                return False
            self._resume_req.clear()
            back = self._paused_from or S.HOVERING
            fsm.transition(back if back != S.WAYPOINT_HOLD else S.NAVIGATING, t)
            self._event("resumed")
            if back == S.TAKING_OFF:
                v.takeoff(self.cfg.takeoff_altitude)
            self.active_wp = None
            self.hold_until = None
            return False
        if st == S.TAKING_OFF:
            if abs(v.state.position[2] - self.cfg.takeoff_altitude) < 0.1:
                fsm.transition(S.HOVERING, t)
                v.hold()
            return False
        res = ray.get(self.scheduler.tick.remote(t, pos))
        item = res["item"]
        self.preplanned_left = res["preplanned_left"]
        if item is not None:
            self.idle_since = None
            self.flew_something = True
        if isinstance(item, (Waypoint, VelocityCommand)) and not (isinstance(item, Waypoint) and self.active_wp == item.id):
            try:  # the choke point: nothing outside the safety limits reaches the backend
                item = self.gate.check_item(item, pos)
            except SafetyViolation as e:
                self._reject(t, item, e)
                return False
        if isinstance(item, ActionCommand):
            self._event("action", action=item.action, reason=item.reason, priority=res["priority"])
            if st == S.TRACKING:
                self._event("tracking_ended")
            ray.get(self.scheduler.discard.remote(item.id, "executed"))
            self.preplanned_left = ray.get(self.scheduler.pending.remote())
            if item.action == "land":
                v.land()
                fsm.transition(S.LANDING, t)
                self._event("landing", reason=item.reason or "land command")
            else:
                self._return_to_launch(t, pos)
            return False
        if isinstance(item, VelocityCommand):
            if st != S.TRACKING:
                fsm.transition(S.TRACKING, t)
                self._event("tracking_started", priority=res["priority"], mission=res["mission"],
                            preempted=self.active_wp)
            v.set_velocity((item.vx, item.vy, item.vz), item.yaw_rate)
            self.active_wp, self.hold_until = None, None
            self.last_cmd_kind = "velocity"
            return False
        if isinstance(item, Waypoint):
            target = item.to_local(self.cfg.home)
            if self.active_wp != item.id:
                if st == S.TRACKING:
                    self._event("tracking_ended")
                self.active_wp, self.hold_until = item.id, None
                v.goto(target, item.speed)
                fsm.transition(S.NAVIGATING, t)
                self._event("navigate", waypoint=item.id, target=list(target), priority=res["priority"],
                            mission=res["mission"])
                if self.recorder is not None:
                    self.recorder.json.remote(f"/{self.cfg.id}/nav/command", self._t_ns(t),
                                              {"kind": "waypoint", "waypoint": item.model_dump(), "local": list(target),
                                               "priority": res["priority"]}, "aerodaas.NavCommand")
                return False
            dist = math.dist(pos, target)
            if st == S.NAVIGATING and dist <= item.acceptance_radius:
                fsm.transition(S.WAYPOINT_HOLD, t)
                v.goto(target)  # keep station on the exact waypoint
                self.hold_until = t + item.hover_duration
                self._event("waypoint_reached", waypoint=item.id, error_m=dist)
            if st == S.WAYPOINT_HOLD and self.hold_until is not None and t + 1e-9 >= self.hold_until:
                ray.get(self.scheduler.complete.remote(item.id))
                self.visited.append({"id": item.id, "t": t, "position": list(pos), "target": list(target),
                                     "error_m": dist})
                self._event("waypoint_done", waypoint=item.id)
                self.active_wp, self.hold_until = None, None
            return False
        # nothing queued
        if st == S.TRACKING:
            self._event("tracking_ended")
        if self.idle_since is None:
            self.idle_since = t
        done_plan = self.preplanned_total > 0 and res["preplanned_left"] == 0 and len(self.visited) > 0
        had_mission = self.flew_something or self.preplanned_total > 0
        idle_too_long = had_mission and t - self.idle_since >= self.cfg.idle_land_s
        if done_plan or idle_too_long:
            v.land()
            fsm.transition(S.LANDING, t)
            self._event("landing", reason="mission complete" if done_plan else
                        f"nothing to do for {self.cfg.idle_land_s:g} s")
            return False
        if st != S.HOVERING:
            fsm.transition(S.HOVERING, t)
            v.hold()
        return False

    def _return_to_launch(self, t: float, pos: tuple) -> None:
        """RTL: fly home at the current altitude (at least the take-off altitude), then land (see _control)."""
        self.vehicle.goto((0.0, 0.0, max(pos[2], self.cfg.takeoff_altitude)))
        self.active_wp, self.hold_until = None, None
        if self.fsm.state == S.TRACKING:
            self._event("tracking_ended")
        self.fsm.transition(S.RETURNING, t)
        self._event("returning", home=[0.0, 0.0])

    def _reject(self, t: float, item: Any, err: SafetyViolation) -> None:
        """A command outside the safety limits: never sent to the backend; dropped from the queue and recorded."""
        rec = {"id": getattr(item, "id", "?"), "t": t, "field": err.field, "value": err.value, "reason": err.reason}
        self.rejected.append(rec)
        self._event("command_rejected", **rec)
        ray.get(self.scheduler.discard.remote(rec["id"], f"rejected: {err.reason}"))
        if self.fsm.state == S.TRACKING:
            self._event("tracking_ended")
        if self.fsm.state in (S.TRACKING, S.NAVIGATING, S.WAYPOINT_HOLD):
            self.fsm.transition(S.HOVERING, t)
        self.vehicle.hold()
        self.active_wp, self.hold_until = None, None
