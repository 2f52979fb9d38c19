"""The built-in "follow" navigable analytics (:class:`FollowAnalytics`): detections in, ENU velocity commands out
(a PID controller on the target's ground position), with one :class:`FollowTrack` per drone."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable

import numpy as np

from aerodaas.analytics.base import NavigableAnalytics
from aerodaas.analytics.motion import MovingTarget, TrackMotion
from aerodaas.model.camera import pixel_to_ground
from aerodaas.model.types import AeroNavigation, Detection, FrameMeta, NavigationType, SchedulingType, VelocityCommand
from aerodaas.perception.track_records import TrackRecords, track_rows
from aerodaas.perception.tracking import ByteTracker

__all__ = ["FollowTrack", "FollowAnalytics"]


@dataclass
class FollowTrack:
    """One drone's follow state (:class:`FollowAnalytics` keeps one per drone): the target's ground position
    ``track`` (ENU metres, None: no track) and velocity ``track_v`` (m/s) at sim time ``track_t`` (s), the
    detections ``hits`` that fed it, the PID integral (metre-seconds) and previous error (metres) at ``prev_t``,
    the standoff direction ``away`` (unit ENU vector), the ``commands`` issued to this drone, and the smoothed
    interval ``frame_interval_s`` (s, capture time) between the frames that reached the follow at ``last_frame_t``."""

    track: np.ndarray | None = None
    track_v: np.ndarray = field(default_factory=lambda: np.zeros(2))
    track_t: float = 0.0
    hits: int = 0
    integral: np.ndarray = field(default_factory=lambda: np.zeros(2))
    prev_err: np.ndarray | None = None
    prev_t: float | None = None
    away: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.0]))
    commands: int = 0
    frame_interval_s: float | None = None
    last_frame_t: float | None = None
    tracker: Any = None  # this drone's ByteTracker (FollowAnalytics(tracker=...)), None: gated nearest detection
    target_id: int | None = None  # the track id followed (with a tracker)
    motion: TrackMotion | None = None  # the tracks' recent ground fixes (FollowAnalytics(moving=...))

    def saw_frame(self, t: float, longest_gap_s: float) -> None:
        """Note a frame captured at sim time ``t`` (s): ``frame_interval_s`` follows the gaps between frames with
        an exponential average (weight 0.3 on the newest gap), each gap cut to ``longest_gap_s`` (a pause, such as
        a detector restarting, is not the detector's pace); a frame older than the newest seen is not a gap."""
        if self.last_frame_t is not None:
            if t <= self.last_frame_t:
                return
            gap = min(t - self.last_frame_t, longest_gap_s)
            self.frame_interval_s = gap if self.frame_interval_s is None else 0.7 * self.frame_interval_s + 0.3 * gap
        self.last_frame_t = t

    def drop(self) -> None:
        """Lose the target: clear the track and the controller memory (``away``, ``commands`` and the frame
        interval stay)."""
        self.track, self.track_v, self.track_t, self.hits = None, np.zeros(2), 0.0, 0
        self.target_id = None
        self.integral, self.prev_err, self.prev_t = np.zeros(2), None, None


class FollowAnalytics(NavigableAnalytics):
    """Follow a detected target: turns its pixel box into ENU velocity commands with a PID controller.

    The box centre is back-projected through the frame's camera pose onto the ground plane
    (:func:`aerodaas.model.camera.pixel_to_ground`), giving the target's ground position; a simple gated track
    (nearest detection to the predicted position) keeps it locked. The command is
    ``v = kp·e + ki·∫e dt + kd·de/dt + v_target`` where ``e`` is the horizontal ground error in metres
    (target minus drone), ``kp`` in 1/s, ``ki`` in 1/s², ``kd`` dimensionless, and ``v_target`` the
    target's estimated velocity (feed-forward), clipped to ``max_speed`` m/s. Each command lasts
    ``command_duration`` s from its frame's capture time, stretched by twice the interval between the frames
    that reach the follow for this drone (to at most ``lost_after`` and 4 x ``command_duration``): with a
    detector slower than the camera the frames that get analysed arrive late and far apart (80 ms of inference
    on a 2-core machine is 0.32 s of vehicle time at 4x real time), and a command that expired before the next
    one arrived handed the drone back to the preempted mission between every two detections (TRACKING and
    NAVIGATING alternated every 0.1-0.4 s). The track must be confirmed by ``confirm_hits`` detections; after
    ``lost_after`` seconds without a detection it is dropped and no more commands are issued (the preempted
    mission resumes once the last command runs out).
    ``standoff_m`` > 0 keeps the drone that many metres (horizontally) behind the target along its heading
    (e.g. 2 m for following a person), instead of directly above it.

    Shared by several drones, it keeps one :class:`FollowTrack` per drone (keyed by the frame's
    ``FrameMeta.robot_id``): each drone follows what its own camera sees, with its own PID memory.

    ``tracker``: a :class:`aerodaas.perception.tracking.ByteTrackConfig` makes it follow a **track id**:
    each drone runs its own ByteTracker on the target-class detections; the followed id is kept while that track
    is seen, whatever other boxes come near, and ByteTrack re-acquires it under the same id after a short occlusion
    (``track_buffer`` frames); when the id is gone for good, the track nearest the predicted ground position within
    ``gate_m`` is adopted. ``None`` (default): the gated nearest detection of each frame, as before. With a tracker
    the drone's tracks are also recorded in a run (:mod:`aerodaas.perception.track_records`, under
    ``/{robot}/{name}/tracks``: image annotations with the track ids, a 3-D scene and the tracks' ``LocationFixes``).

    ``moving``: a :class:`aerodaas.analytics.motion.MovingTarget` (needs ``tracker``) adopts only a track whose
    ground speed over the rule's window is at least its ``min_speed_mps`` (0.5 m/s by default): an aerial detector
    also sees the parked cars, and without it the first confident parked car was followed. A track too
    new to have a speed is not adopted yet; the adopted one is kept while it is seen, even when it stops.
    ValueError for ``moving`` without ``tracker`` or with a bad threshold (naming the field and the value).
    """

    name = "follow"
    consumes, produces = ("detections",), ("navigation",)

    def __init__(self, target_classes: Iterable[str] = ("car", "truck", "bus"), kp: float = 0.8, ki: float = 0.02,
                 kd: float = 0.1, max_speed: float = 4.0, command_duration: float = 0.5, gate_m: float = 4.0,
                 confirm_hits: int = 2, lost_after: float = 2.0, standoff_m: float = 0.0,
                 name: str | None = None, tracker: Any = None, moving: MovingTarget | None = None) -> None:
        super().__init__(name)
        if tracker is not None:
            tracker.check()
        if moving is not None:
            if tracker is None:
                raise ValueError("FollowAnalytics.moving needs tracker=ByteTrackConfig(...): a track's speed comes "
                                 "from its geo-located fixes under one track id")
            moving.check()
        self.moving = moving
        self.tracker = tracker
        #: the tracks the runtime records (aerodaas.perception.track_records), None without a tracker
        self.track_records = TrackRecords() if tracker is not None else None
        self.standoff_m = float(standoff_m)
        self.target_classes = set(target_classes)
        self.kp, self.ki, self.kd = kp, ki, kd
        self.max_speed, self.command_duration = max_speed, command_duration
        self.gate_m, self.confirm_hits, self.lost_after = gate_m, confirm_hits, lost_after


    def track_of(self, robot_id: str) -> FollowTrack | None:
        """The follow state of drone ``robot_id`` (None before its first frame)."""
        return self.drone_states().get(robot_id)

    @property
    def commands(self) -> int:
        """Velocity commands issued, all drones together."""
        return sum(st.commands for st in self.drone_states().values())

    def generate_navigation(self, dets: list[Detection], meta: FrameMeta | None) -> AeroNavigation | None:
        if meta is None:
            return None
        st = self.drone_state(dets, meta, FollowTrack)
        t = meta.capture_time
        st.saw_frame(t, self._longest_command_s())
        drone = np.array(meta.pose.position[:2])
        cands = []
        ids: list[int | None] = []
        if self.tracker is not None and self.track_records is not None:
            if st.tracker is None:
                st.tracker = ByteTracker(self.tracker)
            active = st.tracker.update([d for d in dets if d.class_name in self.target_classes])
            self.track_records.keep(meta, track_rows(active, meta))  # recorded by the runtime (track_records)
            seen = [(tr.detection, tr.track_id) for tr in active]
        else:
            seen = [(d, None) for d in dets if d.class_name in self.target_classes]
        for d, tid in seen:
            g = pixel_to_ground(*d.center, meta.pose, meta.intrinsics)
            if g is not None:
                cands.append((d, np.array(g)))
                ids.append(tid)
        if self.moving is not None:
            self._note_motion(st, cands, ids, meta)
        best = self._choose(st, cands, ids, t)
        if best is not None:
            if self.tracker is not None:
                st.target_id = ids[next(i for i, c in enumerate(cands) if c is best)]
            p = best[1]
            if st.track is not None and t > st.track_t:
                v_new = (p - st.track) / (t - st.track_t)
                st.track_v = 0.7 * st.track_v + 0.3 * v_new if st.hits > 1 else v_new * 0.0
            st.track, st.track_t = p, t
            st.hits += 1
        elif st.track is None or t - st.track_t > self.lost_after:
            if st.track is not None:
                st.drop()
            return None
        if st.hits < self.confirm_hits:
            return None
        target = st.track + st.track_v * (t - st.track_t)
        if self.standoff_m > 0:  # stay standoff_m behind the target (along its heading), or where we are if it stops
            sp = float(np.hypot(*st.track_v))
            if sp > 0.2:
                st.away = -st.track_v / sp
            elif np.hypot(*(drone - target)) > 0.3:
                st.away = (drone - target) / np.hypot(*(drone - target))
            target = target + st.away * self.standoff_m
        err = target - drone
        dt = (t - st.prev_t) if st.prev_t is not None else 0.0
        if dt > 0:
            st.integral = np.clip(st.integral + err * dt, -5.0, 5.0)
        deriv = (err - st.prev_err) / dt if (st.prev_err is not None and dt > 0) else np.zeros(2)
        st.prev_err, st.prev_t = err, t
        v = self.kp * err + self.ki * st.integral + self.kd * deriv + st.track_v
        n = float(np.hypot(*v))
        if n > self.max_speed:
            v *= self.max_speed / n
        st.commands += 1
        cmd = VelocityCommand(id=f"follow-{meta.seq}", vx=float(v[0]), vy=float(v[1]), vz=0.0,
                              duration=self.duration_for(st), issued_at=t)
        return AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [cmd], SchedulingType.ORDERED, name="follow")

    def _choose(self, st: FollowTrack, cands: list, ids: list, t: float):
        """This frame's target among ``cands`` ((detection, ENU xy) by track id ``ids``; ids None without a
        tracker) at capture time ``t`` (s), or None: the followed track id while it is seen; nothing while it coasts
        in ByteTrack's buffer; otherwise, among the candidates :attr:`moving` allows (all without it), the most
        confident when nothing was followed, else the nearest to the predicted position within ``gate_m``."""
        if st.target_id is not None and st.target_id in ids:  # the followed track is seen: keep it
            return cands[ids.index(st.target_id)]
        if st.target_id is not None and any(tr.track_id == st.target_id for tr in st.tracker.tracks):
            return None  # hidden but still alive in ByteTrack (lost, within its buffer): adopt no other object
        eligible = cands if self.moving is None else [c for c, tid in zip(cands, ids) if st.motion.is_moving(tid)]
        if not eligible:
            return None
        if st.track is None:
            return max(eligible, key=lambda c: c[0].score)
        pred = st.track + st.track_v * (t - st.track_t)
        c = min(eligible, key=lambda c: float(np.linalg.norm(c[1] - pred)))
        return c if np.linalg.norm(c[1] - pred) <= self.gate_m else None

    def _note_motion(self, st: FollowTrack, cands: list, ids: list, meta: FrameMeta) -> None:
        """Add this frame's ground fixes (``cands``: (detection, ENU xy) by track id ``ids``) to the drone's
        :class:`TrackMotion`, leaving out boxes within the rule's ``border_px`` of the image edge (cut boxes slide
        with the drone), and forget the tracks its tracker no longer holds."""
        if st.motion is None:
            st.motion = TrackMotion(self.moving)
        w, h, m = meta.intrinsics.width, meta.intrinsics.height, self.moving.border_px
        for (d, g), tid in zip(cands, ids):
            x0, y0, x1, y1 = d.box
            if x0 > m and y0 > m and x1 < w - m and y1 < h - m:
                st.motion.add(tid, meta.capture_time, g)
        st.motion.forget_except({tr.track_id for tr in st.tracker.tracks})

    def _longest_command_s(self) -> float:
        """The most a command is stretched to (s): ``lost_after``, and at most 4 x ``command_duration``."""
        return max(self.command_duration, min(self.lost_after, 4.0 * self.command_duration))

    def duration_for(self, st: FollowTrack) -> float:
        """A command's lifetime (s) for the drone whose state is ``st``: ``command_duration`` + twice its frame
        interval (it must outlive the wait for the next analysed frame plus that frame's latency, which is about
        one interval when the detector is the bottleneck), within [``command_duration``, ``lost_after``] and at
        most 4 x ``command_duration``."""
        d = self.command_duration
        if st.frame_interval_s is not None:
            d = min(d + 2.0 * st.frame_interval_s, self._longest_command_s())
        return float(min(d, 3600.0))

    def stats(self) -> dict:
        """``commands`` (all drones) and ``commands_by_drone`` (robot id -> velocity commands issued)."""
        by = {rid: st.commands for rid, st in self.drone_states().items()}
        return {"commands": sum(by.values()), "commands_by_drone": by}
