"""ActorAssembly: builds an actor's components (cameras, analytics, trajectory schedulers, drones) from its spec,
runs the drones' clock and checkpoints, and answers the driver's calls.

Components hand each other typed messages (:mod:`aerodaas.protocol.messages`): a camera publishes :class:`FrameMsg` (a
read-only (H, W, 3) uint8 BGR ``ndarray``, shared by every reader of the actor, never copied there), a drone
:class:`OdometryMsg` and :class:`StatMsg`, an analytics :class:`DetectionsMsg`, :class:`NavigationMsg` or
:class:`ValueMsg`; each carries its robot, simulated time, the FrameMeta of its frame and the frame's latency
trace (``capture_wall``: ``time.time()`` when the frame was ready, ``inference_ms``, ``post_ms``), and in
lock-step its :class:`~aerodaas.actors.data.plane.Cascade`.
"""
from __future__ import annotations

import math
import os
import time
from typing import Any

import cv2

from aerodaas.actors.drone.checkpoint import CheckpointNumbers, QueueBases
from aerodaas.actors.drone.component import DroneComponent
from aerodaas.actors.sensors.plugin_sensor import PluginSensorComponent
from aerodaas.actors.recording.remote_recorder import RemoteRecorder
from aerodaas.backends.base import CredentialsRefused, RobotsNotConnected
from aerodaas.config import RobotConfig, SimulationConfig, WorldConfig
from aerodaas.plugins.frames import frame_source_class
from aerodaas.plugins.registry import adopt
from aerodaas.protocol.ids import is_drone
from aerodaas.protocol.messages import SealedCheckpoint
from aerodaas.protocol.specs import ActorSpec

from aerodaas.actors.data.plane import Cascade, DataPlane, percentiles as _percentiles
from aerodaas.actors.sensors.camera import CameraComponent
from aerodaas.sim.world import World


#: the actor's clock sheds its cameras' due frames while it is more than this many control periods behind the wall
#: clock (outside lock-step): control before sensing. A node that cannot keep up (40 drone actors with 640x480
#: cameras at 15 FPS on two cores, docs/results/fleet.md "When the node is full") then renders fewer, fresher
#: frames instead of letting the renders take the CPU from the control ticks the clock is catching up on
SHED_LATE_TICKS = 0.5


#: at most this many physics steps in one wake of an actor's clock outside lock-step (:func:`_quiet_steps`)
MAX_QUIET_STEPS = 10


def _quiet_steps(drones: list, dt: float) -> int:
    """How many physics steps of ``dt`` (s) an actor's clock computes in one wake outside lock-step: up to and
    including the first step at which a drone of ``drones`` has something due — a control tick, a camera's frame,
    an odometry or plug-in sensor sample — at most :data:`MAX_QUIET_STEPS`. The clock sleeps until that step's
    wall time, then computes the steps before it in order, each at its own simulated time, so nothing is computed
    before its wall time and whatever is due happens at its own; a call reading a drone's state between two wakes
    (``status``) sees it as of the last wake. 1 (a wake per step) while a drone's vehicle is not the simulator, a
    camera reads a video stream (both are polled every step), or its mission has ended or its end is requested."""
    n = MAX_QUIET_STEPS
    for d in drones:
        b = d.backend
        if d.done or d.end_requested is not None or b.clock != "sim" or b.telemetry.sample_key is not None or any(
                c["comp"].stream is not None for c in d.cameras):
            return 1
        due = min([d.next_tick, d.next_odom] + [c["next_t"] for c in d.cameras]
                  + [ps.next_t for ps in d.plugin_sensors])
        # the first step j after which b.t + 1e-9 >= due; rounded down when in doubt: one wake more, never late
        n = min(n, max(1, math.ceil((due - b.t - 1e-9) / dt - 1e-6)))
    return n


def _sleep_until(wall: float) -> float:
    """Sleep until monotonic time ``wall`` (s); returns how far past it the clock already was (s, 0 when on time)."""
    lag = wall - time.monotonic()
    if lag > 0:
        time.sleep(lag)
        return 0.0
    return -lag


def _capture_due(d: Any, tok: Any, clock_late: bool = False) -> None:
    """Drone ``d``'s cameras whose next frame is due at its vehicle time capture (in lock-step, as part of the
    cascade ``tok``); after a jump of the vehicle clock the next frame is one period on, not a burst. ``clock_late``:
    the actor's clock is behind the wall clock (see :data:`SHED_LATE_TICKS`): a pulled camera's due frame is not
    rendered (:meth:`~aerodaas.actors.sensors.camera.CameraComponent.try_capture`)."""
    b = d.backend
    for cam in d.cameras:
        if b.t + 1e-9 >= cam["next_t"]:
            cam["next_t"] += 1.0 / cam["fps"]
            if b.t > cam["next_t"] + 1.0 / cam["fps"]:  # vehicle clock jumped: do not burst
                cam["next_t"] = b.t + 1.0 / cam["fps"]
            cam["comp"].try_capture(b.telemetry.pose_sample(), b.t, tok, clock_late)


def _halt_cameras(d: Any) -> None:
    """Drone ``d``'s mission is over: its cameras capture no more (a stream camera's arrivals included)."""
    for cam in d.cameras:
        cam["comp"].halt()


#: the keys of :meth:`ActorAssembly.cpu_accounts` for what the user brings, in :meth:`ActorAssembly._user_cpu`'s
#: order: the cameras' frame making, the analytics' ``process`` calls, the recorded frames' JPEG encodes (CPU s)
USER_CPU_PARTS = ("render_cpu_s", "analytics_cpu_s", "encode_cpu_s")


class _ClockHold:
    """The wall time this actor's clock spent waiting for its recorder (``recorder.hold.held_s``,
    :class:`~aerodaas.actors.recording.remote_recorder.FrameHold`): :meth:`taken` returns what was waited since the last call; a wait that
    is over becomes a ``clock_held`` event (``held_s``: wall s) of every drone in ``drones``."""

    def __init__(self, recorder: Any, drones: list) -> None:
        self.recorder, self.drones = recorder, drones
        self.seen = self._held()
        self.total_s = 0.0
        self.open_s = 0.0  # the wait in progress (over several captures)

    def _held(self) -> float:
        return 0.0 if self.recorder is None else self.recorder.hold.held_s

    def taken(self) -> float:
        now = self._held()
        dt, self.seen = now - self.seen, now
        if dt > 0:
            self.open_s += dt
            self.total_s += dt
        elif self.open_s:
            self.end()
        return dt

    def end(self) -> None:
        """Record the wait in progress, if any."""
        if self.open_s:
            for d in self.drones:
                d.record_event("clock_held", held_s=round(self.open_s, 3), cause="recorder behind")
            self.open_s = 0.0


class _Checkpointer:
    """Sends each drone's checkpoint (:mod:`aerodaas.actors.drone.checkpoint`) to the run's recorder actor about every ``period_s``
    wall seconds and whenever a waypoint was completed, without waiting for the reply (fire and forget: a lost
    checkpoint only means resuming from the one before). Does nothing on an actor without the recorder peer.

    The drones' periodic checkpoints are spread over the period (an actor of ten drones does not take and send ten
    at one tick), and each carries its drone's waypoint queue only when it changed otherwise than by flying
    (:class:`~aerodaas.actors.drone.checkpoint.QueueBases`); when the recorder answers that it lacks the queue a
    checkpoint goes with (it restarted), the next one carries the queue again."""

    def __init__(self, plane: DataPlane, drones: list, numbers: CheckpointNumbers, period_s: float = 2.0) -> None:
        self.plane, self.period_s, self.numbers = plane, period_s, numbers
        self.on = "recorder" in (getattr(plane, "peers", None) or {}) and bool(drones)
        now = time.monotonic()
        self.due = {id(d): now + period_s * (i + 1) / len(drones) for i, d in enumerate(drones)}
        self.visited = {id(d): len(d.visited) for d in drones}
        self.queues = QueueBases()

    def maybe(self, active: list) -> None:
        if not self.on:
            return
        now = time.monotonic()
        for d in active:
            due = now >= self.due[id(d)]
            if due or len(d.visited) != self.visited.get(id(d)):
                self.visited[id(d)] = len(d.visited)
                if due:
                    self.due[id(d)] = now + self.period_s
                # taken here (consistent with the control step), serialised and sent on the pool: the clock
                # thread never pays for pickling
                self.plane.submit(self._send, d.cfg.id, self.numbers.take(d))

    def _send(self, robot_id: str, cp: dict) -> None:
        try:
            state, queue, qid = self.queues.split(cp)
            ref = self.plane.peer("recorder").checkpoint.remote(robot_id, SealedCheckpoint.seal(state, queue, qid))
            if queue is None:  # the recorder may lack the queue this one goes with: then it answers False
                ref.future().add_done_callback(lambda f: self._answered(f, robot_id, qid))
        except Exception as e:  # noqa: BLE001 - a missing checkpoint must never stop the flight
            self.plane.report_error("checkpoint", e)
            self.on = False

    def _answered(self, reply: Any, robot_id: str, qid: int) -> None:
        """The recorder's reply ``reply`` (a future) to a checkpoint going with queue ``qid``."""
        if not reply.cancelled() and reply.exception() is None and reply.result() is False:
            self.queues.forget(robot_id, qid)


class ActorAssembly:
    """Builds an actor's components from its :class:`~aerodaas.protocol.specs.ActorSpec` and runs them: the
    recorder (a file of its own with ``spec.record``, else the run's recorder actor with ``spec.record_remote``),
    the analytics instances (``spec.analytics``), and per robot (``spec.robots``) its trajectory scheduler, drone
    and cameras (simulated ones render ``spec.world``). Drones connect to their vehicles here, so an unreachable
    vehicle fails the run before take-off (:class:`~aerodaas.backends.base.RobotsNotConnected`)."""

    def __init__(self, plane: DataPlane, spec: ActorSpec) -> None:
        self.plane = plane
        if spec.role in ("drone", "analytics") and spec.opencv_threads is not None:
            cv2.setNumThreads(spec.opencv_threads)  # the process's OpenCV pool (ActorSpec.opencv_threads)
        self.sim = SimulationConfig.model_validate(spec.sim)
        #: the numbers of this actor's checkpoints (its runs and its ``checkpoint`` call)
        self.checkpoint_numbers = CheckpointNumbers()
        self.recorder = self._make_recorder(plane, spec)
        plane.recorder = self.recorder
        self.comps: dict[str, Any] = {}
        #: this actor's analytics components (:meth:`_add_analytics`)
        self.analytics: list[Any] = []
        self.scheduling = self._make_scheduling(plane, spec)
        self._add_analytics(plane, spec)
        self.drones: list[DroneComponent] = []
        #: the last :meth:`run`'s span (its simulated seconds, the process's CPU seconds over it, its drones); None
        #: before a run
        self.flight_cpu: dict | None = None
        world = None
        for r in spec.robots:
            world = self._add_robot(plane, spec, r, world)
        # real cameras are not synchronised: spread the fleet's capture phases over one frame period
        for c in self.analytics:  # on_error=abort: end every mission of the run, wherever the drones are
            c.abort = self._abort_all
        if self.recorder is not None:  # a failing disk becomes an event of every drone (and the run's report)
            self.recorder.on_failure.append(
                lambda info, drones=tuple(self.drones): [d.record_event("recording_failed", **info) for d in drones])
        cams = [c for d in self.drones for c in d.cameras]
        for i, c in enumerate(cams):
            c["next_t"] = i / (len(cams) * c["fps"])
        self._connect_all()

    @staticmethod
    def _make_recorder(plane: DataPlane, spec: ActorSpec) -> Any:
        """A file of its own (and/or the live view) with ``spec.record``, the run's recorder actor with
        ``spec.record_remote``, else None."""
        rec = spec.record
        if rec is not None:  # an actor with the file and/or the live view
            # only here: an unrecorded run's actors never import the writer and the live view (0.08-0.10 s of CPU
            # per fresh worker, measured at load 40)
            from aerodaas.actors.recording.recorder import RecorderService  # lazy: heavy mcap, protobuf, websockets

            return RecorderService(rec.path, rec.meta, copies=plane.copies, live=rec.live, homes=rec.homes,
                                   declare=rec.declare, hold_s=float(spec.sim.get("recorder_hold_s", 0.0)),
                                   json_schemas=rec.schemas)  # plug-in sensors' message schemas
        if spec.record_remote:  # an actor of a recorded run: its messages go to the run's recorder actor
            return RemoteRecorder(plane, spec.record_remote, hold_s=float(spec.sim.get("recorder_hold_s", 0.0)))
        return None

    @staticmethod
    def _make_scheduling(plane: DataPlane, spec: ActorSpec) -> Any:
        """The analytics scheduler's service of a dispatcher actor (``spec.analytics_scheduler``), else None."""
        if spec.analytics_scheduler is None:
            return None
        # only here: a drone actor never imports the dispatcher's schedulers (0.05 s of CPU per worker)
        from aerodaas.actors.dispatch.scheduling import AnalyticsSchedulingService  # lazy: start-up cost

        return AnalyticsSchedulingService(plane, spec.analytics_scheduler)

    def _add_analytics(self, plane: DataPlane, spec: ActorSpec) -> None:
        """The analytics instances; those the analytics scheduler places go to its service (started here). Raises
        ValueError for a scheduled analytics in an actor without an analytics scheduler."""
        # imported only here: an actor without analytics (a drone actor whose analytics run elsewhere) never
        # imports their hosting and its tracks, nor one without a scheduler the dispatcher's (0.05 s of CPU each)
        for a in spec.analytics:
            if a.scheduled:
                if self.scheduling is None:
                    raise ValueError(f"analytics {a.cid!r} is placed by the analytics scheduler, but actor "
                                     f"{plane.actor_id!r} has no analytics_scheduler spec")
                from aerodaas.actors.dispatch.scheduling import ScheduledAnalyticsComponent  # lazy: start-up cost

                comp = ScheduledAnalyticsComponent(plane, a.cid, a.name, a.obj, self.recorder, plane.epoch_ns,
                                                   self.scheduling)
                self.scheduling.add(comp)
            else:
                from aerodaas.actors.analytics.component import AnalyticsComponent  # lazy: start-up cost

                comp = AnalyticsComponent(plane, a.cid, a.name, a.obj, self.recorder, plane.epoch_ns, a.buffer)
            self.comps[a.cid] = plane.add(comp)
            self.analytics.append(comp)
        if self.scheduling is not None:
            self.scheduling.start()

    def _add_robot(self, plane: DataPlane, spec: ActorSpec, r: Any, world: Any) -> Any:
        """Robot ``r``'s drone (with its navigation inbox), cameras and plug-in sensors. ``world``: the simulated
        world its cameras render, made on the first simulated camera of this actor; returns it."""
        if r.plugins:  # plug-in classes carried in the spec: known here before the config is checked

            adopt(r.plugins)
        cfg = RobotConfig.model_validate(r.robot)
        # the drone owns its waypoint queue and its navigation inbox (registered as <robot>/scheduler)
        drone = DroneComponent(r.drone_cid, r.robot, plane, r.scheduler, self.recorder, plane.epoch_ns,
                               r.preplanned, r.odom_cids, r.stat_cids, inbox_cid=r.scheduler_cid,
                               gimbal_commands=r.gimbal)
        inbox = plane.add(drone.inbox)
        for c in r.cameras:
            source = c.source if c.source is not None else frame_source_class(c.props.get("source", "sim"))
            if source.needs_world and world is None:
                w = WorldConfig.model_validate(spec.world)
                world = World(w.ground, w.targets)  # one texture for every camera of this actor
            cam = CameraComponent(plane, c.cid, cfg.id, c.sensor, c.props, world, drone.backend,
                                  self.recorder, plane.epoch_ns, source)
            cam.on_event = drone.record_event
            drone.cameras.append({"comp": cam, "fps": cam.fps, "next_t": 0.0})
            self.comps[c.cid] = cam
        for ps in r.plugin_sensors:
            comp = PluginSensorComponent(plane, ps, cfg.id, self.recorder, plane.epoch_ns)
            drone.plugin_sensors.append(comp)
            self.comps[ps["cid"]] = comp
        self.comps[r.drone_cid] = drone
        self.comps[r.scheduler_cid] = inbox
        self.drones.append(drone)
        return world

    def _connect_all(self) -> None:
        """Connect every drone to its vehicle. Robots that claim a fixed vehicle identity (a configured MAVLink
        system id) connect before the ones that take the lowest unclaimed one on a shared link
        (VehicleBackend.connects_first). Raises RobotsNotConnected naming each robot's error (the connected
        vehicles are handed back untouched)."""
        errors: dict[str, str] = {}
        refused: list[str] = []  # robots whose vehicle refused our credentials (CredentialsRefused)
        for d in sorted(self.drones, key=lambda d: not d.backend.connects_first):
            try:
                d.connect()
                for c in d.cameras:  # a camera reading the stream the vehicle announces (source "mavlink")
                    c["comp"].on_vehicle_connected()
            except Exception as e:  # noqa: BLE001 - every robot gets its own error (RobotsNotConnected)
                errors[d.cfg.id] = f"{type(e).__name__}: {e}"
                if isinstance(e, CredentialsRefused):
                    refused.append(d.cfg.id)
                try:  # idempotent: a vehicle connected before its camera failed is handed back too
                    d.backend.close()
                except Exception:  # noqa: BLE001
                    pass
        if errors:
            for d in self.drones:  # the run will not start: hand the connected vehicles back untouched
                if d.cfg.id not in errors:
                    try:
                        d.backend.close()
                    except Exception:  # noqa: BLE001
                        pass
            raise RobotsNotConnected(errors, tuple(refused))

    def describe(self) -> dict:
        live = getattr(self.recorder, "live", None)
        return {"host": self.plane.actor_id, "tier": self.plane.tier, "components": sorted(self.comps),
                "pid": os.getpid(), "threads": self.plane.workers, "opencv_threads": cv2.getNumThreads(),
                "live_url": live.url if live is not None else None}

    def lookup(self, cid: str) -> Any:
        try:
            return self.comps[cid]
        except KeyError:
            raise KeyError(f"actor {self.plane.actor_id!r} has no component {cid!r}; it has {sorted(self.comps)}") from None

    # ------------------------------------------------------------------ the clock
    def run(self, timeout_s: float | None = None, resume: bool = False) -> dict[str, dict]:
        """Fly every drone of this actor to the end of its mission; returns robot id -> report. ``resume``: the
        drones were restored from checkpoints (a restarted actor): no arming, no take-off, the mission goes on.

        One clock for the fleet: every ``1/physics_hz`` simulated seconds each backend steps (simulator) or is
        polled (real vehicles), odometry is published at its rate, due cameras capture, and each drone's control
        tick runs at ``control_rate_hz``. Time runs at ``speedup`` x wall time (lock-step: as fast as the
        analytics allow); outside lock-step the clock wakes for the steps with something due (:func:`_quiet_steps`)
        and computes the steps before each on waking. A control tick that runs later than one control period after
        its due wall time (the period divided by ``speedup``) is counted as missed. A drone whose mission has ended
        keeps stepping, with odometry only, until its recorded odometry shows the end state
        (:meth:`DroneComponent.settled`).

        A simulated run's clock waits for a recorder that falls behind (``simulation.recorder_hold_s``): the wall
        time a capture spent waiting for the recorder is taken off the pacing, so no tick runs late for it; each
        wait is a ``clock_held`` event of every drone here, and the total is each drone's ``clock_held_s``."""
        sim, drones = self.sim, self.drones
        dt = 1.0 / sim.physics_hz
        lock = sim.lockstep
        for d in drones:
            if resume and getattr(d, "restored_from", None) is not None:
                continue
            d.start()
        wall0 = time.monotonic()
        cpu0, user0 = time.process_time(), self._user_cpu()
        step = 0
        active = [d for d in drones if not d.done]
        checkpoints = _Checkpointer(self.plane, drones, self.checkpoint_numbers)
        held = _ClockHold(self.recorder, drones)
        self.tick_lateness: list[float] = []
        behind_s = 0.0  # how far the clock is behind the wall clock at this wake (wall s)
        wake_to = 0  # the last step of this wake (outside lock-step)
        try:
            while active:
                step += 1
                if not lock and step > wake_to:  # simulated time is computed when wall time reaches it, never early:
                    wake_to = step - 1 + _quiet_steps(active, dt)  # one wake to the next step with something due
                    behind_s = _sleep_until(wall0 + wake_to * dt / sim.speedup)
                tok = Cascade() if lock else None
                for d in active:
                    d.step(dt, tok)
                for d in active:
                    if not d.done:  # settling: odometry only (:meth:`DroneComponent.settled`)
                        _capture_due(d, tok, behind_s > SHED_LATE_TICKS * d.tick_period / sim.speedup)
                    else:  # no more ticks: a stream camera stops capturing its arrivals too
                        _halt_cameras(d)
                wall0 += held.taken()  # simulated time waited for the recorder: not late for it
                if tok is not None:  # a frame for a consumer that Ray restarts waits up to restart_hold_s for it
                    tok.wait(max(120.0, self.plane.restart_hold_s + 60.0))
                now = time.monotonic()
                finished = [d for d in active if self._control_due(d, now, wall0)]
                for d in finished:
                    _halt_cameras(d)  # (a drone may end and settle in one tick)
                    d.finish()
                    active.remove(d)
                checkpoints.maybe([d for d in active if not d.done])  # a settling drone's mission is over
                if timeout_s is not None and (lock or step >= wake_to) and time.monotonic() - wall0 > timeout_s:
                    for d in active:
                        if not d.done:  # one still settling has ended its mission already
                            d.outcome = "timeout"
                            d.record_event("timeout", wall_s=timeout_s)
                        _halt_cameras(d)
                        d.finish()
                    active = []
        finally:
            self.flight_cpu = self._flight_account(step * dt, len(drones), cpu0, user0)
            held.end()
            for d in drones:
                _halt_cameras(d)
                d.close()
            if self.scheduling is not None:
                try:
                    self.scheduling.finish()
                except Exception as e:  # reported; the drones' reports must still come back
                    self.plane.report_error("analytics_scheduler", e)
        return {d.cfg.id: {**d.report(), "plugin_sensors": {ps.sensor_id: ps.stats() for ps in d.plugin_sensors},
                           "clock_held_s": round(held.total_s, 3), "clock_hold_budget_s": sim.recorder_hold_s}
                for d in drones}

    def _control_due(self, d: Any, now: float, wall0: float) -> bool:
        """Drone ``d``'s control tick when due (or its end requested) at wall time ``now`` (monotonic s; the run's
        clock began at ``wall0``), its lateness counted outside lock-step. True when its mission ended and its
        recorded odometry shows the vehicle's end state (then it is finished)."""
        sim = self.sim
        if d.done:  # the mission ended; its odometry waits for the vehicle's end state (below)
            pass
        elif d.backend.t + 1e-9 >= d.next_tick:
            due = d.next_tick
            d.next_tick += d.tick_period
            if not sim.lockstep:
                late = now - (wall0 + due / sim.speedup) if d.backend.clock == "sim" else 0.0
                self.tick_lateness.append(late)
                if late > d.tick_period / sim.speedup:
                    d.missed_ticks += 1
            d.control_tick()
        elif d.end_requested is not None:
            d.control_tick()
        return d.done and d.settled()

    def _abort_all(self, reason: str) -> None:
        """End every drone's mission as failed with ``reason``: this actor's drones directly, the others through
        their actor (an analytics on the cloud tier aborting drones on the edge)."""
        for d in self.drones:
            d.error = reason
            d.end_mission("failed")
        peers = getattr(self.plane, "peers", {}) or {}

        for cid, hid in getattr(self.plane, "location", {}).items():
            if is_drone(cid) and hid in peers and not any(d.cid == cid for d in self.drones):
                self.plane.peer(hid).call.remote(cid, DroneComponent.end_mission, "failed")

    # ------------------------------------------------------------------ end
    def drain(self) -> bool:
        """The drones are done: let the analytics scheduler (a dispatcher actor) finish its tasks in flight, so that
        its report counts every task in a terminal state. Returns True when there was one."""
        if self.scheduling is None:
            return False
        try:
            self.scheduling.finish()
        except Exception as e:  # reported; the report must still come back
            self.plane.report_error("analytics_scheduler", e)
        return True

    def stats(self) -> dict:
        out = {cid: c.stats() for cid, c in self.comps.items() if c.kind in ("camera", "analytics", "scheduler")}
        gcp = self.plane.gc_pauses_ms
        out["_host"] = {"errors": self.plane.errors[-10:], "error_count": len(self.plane.errors),
                        "gc_pauses": {"count": len(gcp), "max_ms": max(gcp, default=0.0)},
                        "first_processed_wall": self.plane.first_processed_wall,
                        "frame_copies": self.plane.copies.snapshot(),
                        "lost_consumers": self.plane.lost_consumers(),
                        "tick_lateness_ms": _percentiles([x * 1e3 for x in getattr(self, "tick_lateness", [])]),
                        "cpu": self.cpu_accounts(),
                        # an actor without the recorder (cloud): messages it could not hand to the edge recorder
                        "record_send_errors": list(getattr(self.recorder, "send_errors", []))[-5:]}
        if self.scheduling is not None:
            out["_analytics_scheduler"] = self.scheduling.report()
        return out

    def _user_cpu(self) -> tuple[float, float, float]:
        """CPU seconds so far of what the user brings, each on the threads that ran it (``time.thread_time``): this
        actor's cameras' frame making, its analytics' ``process`` calls, the JPEG encodes of its recorded frames
        (sent to the run's recorder actor)."""
        rec = self.recorder
        return (sum(c.render_cpu_s for c in self.comps.values() if isinstance(c, CameraComponent)),
                sum(a.process_cpu_s for a in self.analytics),
                rec.encode_cpu_s if isinstance(rec, RemoteRecorder) else 0.0)

    def _flight_account(self, sim_s: float, drones: int, cpu0: float, user0: tuple) -> dict:
        """A run's CPU account (:meth:`cpu_accounts`) from its start's ``time.process_time()`` (``cpu0``) and
        :meth:`_user_cpu` (``user0``), taken at its end."""
        cpu, user1 = time.process_time() - cpu0, self._user_cpu()
        return {"flight_sim_s": round(sim_s, 6), "drones": drones, "flight_cpu_s": round(cpu, 6),
                **{k: round(u1 - u0, 6) for k, u0, u1 in zip(USER_CPU_PARTS, user0, user1)}}

    def cpu_accounts(self) -> dict:
        """Where this actor's CPU went, exactly (no sampling), in CPU seconds. After a :meth:`run`, over that run:
        ``flight_sim_s`` (simulated s), ``drones``, ``flight_cpu_s`` (every thread of the process,
        ``time.process_time``) and, of it, what the user brings: its cameras' frame making (``render_cpu_s``), its
        analytics' ``process`` calls (``analytics_cpu_s``), the JPEG encodes of recorded frames (``encode_cpu_s``);
        the framework's own part is ``flight_cpu_s`` minus those three. An actor that flew no run: the three over
        its life so far. Counted as the framework's, though the user brought them: plug-in sensors' sampling, a video
        stream's decoding, OpenCV's own pool threads (``actor_opencv_threads`` above 1), the encodes of a recorder
        inside this actor (``RecorderService``), analytics run by an analytics scheduler's dispatcher."""
        if self.flight_cpu is not None:
            return dict(self.flight_cpu)
        return {k: round(u, 6) for k, u in zip(USER_CPU_PARTS, self._user_cpu())}

    def close(self) -> dict:
        if self.scheduling is not None:
            try:
                self.scheduling.finish()
            except Exception as e:  # reported, never blocks closing the recording
                self.plane.report_error("analytics_scheduler", e)
        self.plane.close()
        for d in self.drones:
            for cam in d.cameras:
                cam["comp"].close()
        analytics = {id(c) for c in self.analytics}
        for c in self.comps.values():
            if id(c) in analytics:  # its failures not yet in an event: one summary
                c.finish_failures()
            close = getattr(c.obj, "close", None) if hasattr(c, "obj") else None
            if callable(close):
                try:
                    close()
                except Exception:
                    pass
        return self.recorder.close() if self.recorder is not None else {}

    def recording_report(self) -> dict:
        """The recorder's :meth:`~aerodaas.actors.recording.recorder.RecorderService.report` (failure, lost messages), {} without one."""
        return self.recorder.report() if self.recorder is not None else {}
