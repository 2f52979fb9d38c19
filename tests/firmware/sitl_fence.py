"""Real-firmware scenarios of the autopilot's own geofence (``tests/firmware/test_sitl_fence.py``).

Everything the tests judge is read from the firmware with raw pymavlink on the firmware's *second* link
(:func:`tests.firmware.sitl.monitor_connection`, system id 253, MAVLink 2), never through AeroDaaS:

* ``read-fence``: the fence items (MISSION_REQUEST_LIST with ``mission_type`` FENCE, MISSION_REQUEST_INT per item)
  and the fence parameters (PARAM_REQUEST_READ), written as JSON.
* ``read-params``: every parameter of the vehicle; ``mission-flight``: follow a mission someone else started until the
  vehicle disarms, then every parameter.
* ``clear-union``: a second ground station sets ArduPilot's FENCE_OPTIONS back to 0 once the vehicle holds at a
  point (:func:`clear_union`); ``px4-intersects``: how PX4 reads two overlapping inclusion circles, asked with
  DO_REPOSITION (:func:`px4_intersects`).
* ``kill-and-push``: wait until the vehicle flies the app's mission (armed, GUIDED/OFFBOARD, above 1 m), SIGKILL the
  ``aerodaas run`` process tree (the driver, Ray and its workers: our gate is gone), read the fence as above, then
  act as a runaway client would (a companion computer stuck on its last command, a second ground station): stream a
  velocity target (SET_POSITION_TARGET_LOCAL_NED, velocity only) straight out of the fence, until the firmware
  leaves GUIDED by itself or ``push_s`` wall seconds pass; then, if the firmware took its fence action, follow the
  vehicle until it has disarmed (or the timeout), else 2 s more (it hovers where its fence held it). Records every GLOBAL_POSITION_INT (the firmware's ``time_boot_ms``), the mode of every HEARTBEAT,
  FENCE_STATUS and STATUSTEXT.
"""
from __future__ import annotations

import json
import math
import os
import signal
import sys
import time
from pathlib import Path

os.environ["MAVLINK20"] = "1"  # fence items need MAVLink 2 (mission_type is an extension field)

from pymavlink import mavutil  # noqa: E402

from aerodaas.model.types import GeoPoint  # noqa: E402
from aerodaas.model.geo import geodetic_to_enu  # noqa: E402

FENCE_PARAMS = {"ardupilot": ["FENCE_ENABLE", "FENCE_TYPE", "FENCE_ALT_MAX", "FENCE_ACTION", "FENCE_MARGIN",
                              "FENCE_RADIUS", "FENCE_OPTIONS"],
                "px4": ["GF_ACTION", "GF_MAX_VER_DIST", "GF_MAX_HOR_DIST", "RTL_RETURN_ALT", "RTL_DESCEND_ALT"]}
MAV_MISSION_TYPE_FENCE = 1


class Watcher:
    """A raw pymavlink link to the vehicle that keeps what the tests judge (see the module docstring)."""

    def __init__(self, conn: str, home: GeoPoint) -> None:
        self.m = mavutil.mavlink_connection(conn, source_system=253, source_component=190)
        self.home = home
        self.sysid = self.compid = None
        self.autopilot = None
        self.samples: list[list] = []  # [t_boot s, e, n, rel alt, mode]
        self.modes: list[list] = []  # [t_boot s, mode] at every change
        self.texts: list[str] = []
        self.fence_status: list[dict] = []
        self.armed = self.was_armed = False
        self.mode = ""
        self.t_boot = 0.0
        self._next_hb = 0.0

    def _hb(self) -> None:
        if time.monotonic() >= self._next_hb:
            self.m.mav.heartbeat_send(6, 8, 0, 0, 4)
            self._next_hb = time.monotonic() + 1.0

    def pump(self, timeout: float = 0.2, want: tuple[str, ...] = ()):
        """Read one message (keeping state); returns it when its type is in ``want``."""
        self._hb()
        msg = self.m.recv_match(blocking=True, timeout=timeout)
        if msg is None:
            return None
        t = msg.get_type()
        if t == "HEARTBEAT":
            if msg.autopilot == 8 or msg.type == 6:
                return None
            if self.sysid is None:
                self.sysid, self.compid = msg.get_srcSystem(), msg.get_srcComponent()
                self.autopilot = "px4" if msg.autopilot == 12 else "ardupilot"
                for mid, hz in ((33, 10.0), (162, 2.0)):  # GLOBAL_POSITION_INT, FENCE_STATUS
                    self.m.mav.command_long_send(self.sysid, self.compid, 511, 0, mid, 1e6 / hz, 0, 0, 0, 0, 0)
            self.armed = bool(msg.base_mode & 128)
            self.was_armed = self.was_armed or self.armed
            mode = mavutil.mode_string_v10(msg)
            if mode != self.mode:
                self.mode = mode
                self.modes.append([self.t_boot, mode])
        elif t == "GLOBAL_POSITION_INT" and (msg.lat or msg.lon):
            self.t_boot = msg.time_boot_ms / 1000.0
            e, n, _ = geodetic_to_enu(msg.lat / 1e7, msg.lon / 1e7, self.home.alt, self.home)
            self.samples.append([self.t_boot, float(e), float(n), msg.relative_alt / 1000.0, self.mode])
        elif t == "FENCE_STATUS":
            self.fence_status.append({"t": self.t_boot, "breach_status": msg.breach_status,
                                      "breach_count": msg.breach_count, "breach_type": msg.breach_type})
        elif t == "STATUSTEXT":
            self.texts.append(msg.text)
        return msg if t in want else None

    def wait_vehicle(self, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        while self.sysid is None and time.monotonic() < end:
            self.pump()
        if self.sysid is None:
            raise SystemExit("no autopilot HEARTBEAT on the monitor link")

    def _ask(self, send, match, timeout_s: float = 20.0, every_s: float = 1.0):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            send()
            again = time.monotonic() + every_s
            while time.monotonic() < again:
                msg = self.pump(0.1, want=("MISSION_COUNT", "MISSION_ITEM_INT", "PARAM_VALUE", "MISSION_ACK"))
                if msg is not None and match(msg):
                    return msg
        raise SystemExit("no answer from the vehicle")

    def read_fence(self) -> dict:
        """The vehicle's fence items ``[[command, frame, param1, x, y], ...]`` and fence parameters."""
        s, c = self.sysid, self.compid
        count = self._ask(lambda: self.m.mav.mission_request_list_send(s, c, MAV_MISSION_TYPE_FENCE),
                          lambda m: m.get_type() == "MISSION_COUNT" and m.mission_type == MAV_MISSION_TYPE_FENCE).count
        items = []
        for seq in range(count):
            it = self._ask(lambda: self.m.mav.mission_request_int_send(s, c, seq, MAV_MISSION_TYPE_FENCE),
                           lambda m, seq=seq: m.get_type() == "MISSION_ITEM_INT" and m.seq == seq
                           and m.mission_type == MAV_MISSION_TYPE_FENCE)
            items.append([it.command, it.frame, it.param1, it.x, it.y])
        self.m.mav.mission_ack_send(s, c, 0, MAV_MISSION_TYPE_FENCE)
        params = {}
        for name in FENCE_PARAMS[self.autopilot]:
            try:
                pv = self._ask(lambda name=name: self.m.mav.param_request_read_send(s, c, name.encode(), -1),
                               lambda m, name=name: m.get_type() == "PARAM_VALUE" and m.param_id == name,
                               timeout_s=5.0)
            except SystemExit:
                continue
            v = pv.param_value
            if self.autopilot == "px4" and pv.param_type in (1, 2, 3, 4, 5, 6):  # bytewise integers
                import struct
                v = struct.unpack("<i", struct.pack("<f", v))[0]
            params[name] = float(v)
        return {"items": items, "params": params}

    def read_all_params(self, timeout_s: float = 60.0) -> dict[str, float]:
        """Every parameter of the vehicle (PARAM_REQUEST_LIST, then PARAM_REQUEST_READ by index for those a lossy
        link dropped), as floats in the firmware's units (PX4's integers decoded from their bytes)."""
        import struct

        s, c = self.sysid, self.compid
        got: dict[int, tuple[str, float]] = {}
        total = None
        end = time.monotonic() + timeout_s
        self.m.mav.param_request_list_send(s, c)
        quiet = time.monotonic() + 3.0
        while time.monotonic() < end and (total is None or len(got) < total):
            msg = self.pump(0.1, want=("PARAM_VALUE",))
            if msg is not None and msg.param_index != 65535:
                total = msg.param_count
                v = msg.param_value
                if self.autopilot == "px4" and msg.param_type in (1, 2, 3, 4, 5, 6):
                    v = struct.unpack("<i", struct.pack("<f", v))[0]
                got[msg.param_index] = (msg.param_id, float(v))
                quiet = time.monotonic() + 1.0
            elif time.monotonic() > quiet and total is not None:  # the list ended with gaps: ask for each
                for i in [i for i in range(total) if i not in got][:20]:
                    self.m.mav.param_request_read_send(s, c, b"", i)
                quiet = time.monotonic() + 1.0
        return {name: v for name, v in got.values()}

    def upload_mission(self, points: list[tuple[float, float, float]]) -> bool:
        """A plain mission (ArduPilot: home placeholder at 0, then NAV_WAYPOINTs at ``(lat, lon, alt above home)``),
        MISSION_ITEM_INT answers to each request; True on MISSION_ACK accepted."""
        s, c = self.sysid, self.compid
        items = [(0, 16, self.home.lat, self.home.lon, 0.0)] + [(3, 16, la, lo, z) for la, lo, z in points]
        self.m.mav.mission_count_send(s, c, len(items), 0)
        end = time.monotonic() + 20
        while time.monotonic() < end:
            msg = self.pump(0.2, want=("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"))
            if msg is None or getattr(msg, "mission_type", 0) != 0:
                continue
            if msg.get_type() == "MISSION_ACK":
                return msg.type == 0
            frame, cmd, la, lo, z = items[msg.seq]
            self.m.mav.mission_item_int_send(s, c, msg.seq, frame, cmd, 0, 1, 0, 0, 0, 0,
                                             int(round(la * 1e7)), int(round(lo * 1e7)), z, 0)
        return False

    def set_mode(self, custom_mode: int) -> None:
        """MAV_CMD_DO_SET_MODE (custom mode: ArduCopter AUTO 3, GUIDED 4)."""
        self.m.mav.command_long_send(self.sysid, self.compid, 176, 0, 1, custom_mode, 0, 0, 0, 0, 0)

    def push(self, ve: float, vn: float) -> None:
        """One velocity-only target in MAV_FRAME_LOCAL_NED (north, east m/s), as a runaway client sends it."""
        self.m.mav.set_position_target_local_ned_send(0, self.sysid, self.compid, 1, 0b110111000111,
                                                      0, 0, 0, vn, ve, 0, 0, 0, 0, 0, 0)


def kill_tree(pid: int) -> list[int]:
    """SIGSTOP ``pid`` and all its descendants (re-scanned until no new one appears: nothing can fork any more),
    then SIGKILL them all. Returns the pids killed."""
    import psutil

    seen: dict[int, psutil.Process] = {}
    try:
        root = psutil.Process(pid)
    except psutil.NoSuchProcess:
        return []
    todo = [root]
    while todo:
        p = todo.pop()
        if p.pid in seen:
            continue
        seen[p.pid] = p
        try:
            p.send_signal(signal.SIGSTOP)
            todo.extend(p.children(recursive=True))
        except psutil.NoSuchProcess:
            pass
    for p in seen.values():
        try:
            p.send_signal(signal.SIGKILL)
        except psutil.NoSuchProcess:
            pass
    psutil.wait_procs(list(seen.values()), timeout=10)
    return sorted(seen)


def kill_and_push(conn: str, run_pid: int, out: str, home: GeoPoint, fly_s: float = 4.0, push_speed: float = 2.5,
                  push_s: float = 25.0, timeout_s: float = 400.0) -> int:
    w = Watcher(conn, home)
    w.wait_vehicle(120)
    end = time.monotonic() + timeout_s
    flying_since = None
    while time.monotonic() < end:  # the app flies its mission
        w.pump()
        # ArduCopter arms and takes off in GUIDED (so: above 1 m); PX4 enters OFFBOARD only once in the air
        flying = w.armed and w.samples and (w.mode == "OFFBOARD" or (w.mode == "GUIDED" and w.samples[-1][3] > 1.0))
        flying_since = (flying_since or time.monotonic()) if flying else None
        if flying_since is not None and time.monotonic() - flying_since >= fly_s:
            break
    else:
        Path(out).write_text(json.dumps({"error": "never saw the vehicle fly the mission", "modes": w.modes,
                                         "texts": w.texts, "samples": w.samples[-200:]}))
        return 1
    killed = kill_tree(run_pid)
    alive = [p for p in killed if _alive(p)]
    t_kill = w.t_boot
    fence = w.read_fence()
    e, n = w.samples[-1][1], w.samples[-1][2]
    d = math.hypot(e, n) or 1.0
    ve, vn = push_speed * (e / d if d > 0.5 else 1.0), push_speed * (n / d if d > 0.5 else 0.0)
    if w.autopilot == "px4":  # PX4 left OFFBOARD when our setpoint stream stopped: stream first, then OFFBOARD
        for _ in range(10):
            w.push(ve, vn)
            stop = time.monotonic() + 0.1
            while time.monotonic() < stop:
                w.pump(0.05)
        w.m.mav.command_long_send(w.sysid, w.compid, 176, 0, 1, 6, 0, 0, 0, 0, 0)  # custom main mode 6: OFFBOARD
    push_end = time.monotonic() + push_s
    entering = time.monotonic() + 5.0
    pushed, reentered = 0, 0
    t_push = w.t_boot
    texts_before = len(w.texts)
    next_offboard = time.monotonic() + 1.0

    def fence_acted() -> bool:
        return any("geofence" in t.lower() for t in w.texts[texts_before:])

    # 20 Hz: PX4's offboard-loss timeout (COM_OF_LOSS_T, 1 s of firmware time) is 0.2 wall seconds at speed-up 5
    while time.monotonic() < push_end and (w.mode in ("GUIDED", "OFFBOARD") or time.monotonic() < entering
                                           or (w.autopilot == "px4" and not fence_acted())):
        w.push(ve, vn)
        pushed += 1
        if w.autopilot == "px4" and w.mode != "OFFBOARD" and not fence_acted() \
                and time.monotonic() >= next_offboard:
            # the push stalled (a loaded machine) and PX4's offboard-loss failsafe took over before the fence
            # acted: a runaway client takes OFFBOARD back, as it did after the kill
            w.m.mav.command_long_send(w.sysid, w.compid, 176, 0, 1, 6, 0, 0, 0, 0, 0)
            reentered += 1
            next_offboard = time.monotonic() + 1.0
        stop = time.monotonic() + 0.05
        while time.monotonic() < stop:
            w.pump(0.02)
    t_push_end = w.t_boot
    t_auto = None
    uploaded = False
    if w.mode in ("GUIDED", "OFFBOARD") and w.autopilot == "ardupilot":
        # held by fence avoidance (GUIDED velocity control): now a mission waypoint 35 m from home (out of a 20 m fence), flown
        # in AUTO, where ArduCopter applies no fence avoidance: the fence itself must act (breach -> FENCE_ACTION)
        from aerodaas.model.geo import enu_to_geodetic

        g = enu_to_geodetic(35.0 * ve / push_speed, 35.0 * vn / push_speed, 0.0, home)  # 35 m out, the push's way
        uploaded = w.upload_mission([(g.lat, g.lon, 1.5)])
        t_auto = w.t_boot
        for _ in range(5):
            w.set_mode(3)
            stop = time.monotonic() + 1.0
            while time.monotonic() < stop:
                w.pump(0.05)
            if w.mode != "GUIDED":
                break
    if w.autopilot == "px4" and w.mode == "OFFBOARD":
        # the push ended while PX4 was still taking its geofence action (on a loaded machine SIH runs behind the wall
        # clock): no setpoints now, so it leaves OFFBOARD by itself (the fence's return or the offboard-loss failsafe)
        stop = time.monotonic() + 60.0
        while time.monotonic() < stop and w.mode == "OFFBOARD":
            w.pump()
    if w.mode not in ("GUIDED", "OFFBOARD"):  # AUTO, then the firmware's fence action: follow it to the ground
        while time.monotonic() < end and w.armed:
            w.pump()
    else:  # still held in GUIDED: a few more samples, then leave it hovering
        stop = time.monotonic() + 2.0
        while time.monotonic() < stop:
            w.pump()
    Path(out).write_text(json.dumps({
        "killed": killed, "alive_after_kill": alive, "t_kill": t_kill, "t_push": t_push, "t_push_end": t_push_end,
        "push": [ve, vn], "pushed": pushed, "reentered": reentered, "t_auto": t_auto, "mission_uploaded": uploaded, "fence": fence, "samples": w.samples, "modes": w.modes,
        "fence_status": w.fence_status, "texts": w.texts, "armed_at_end": w.armed}))
    return 0


def clear_union(conn: str, out: str, home: GeoPoint, x: float, y: float, timeout_s: float = 300.0) -> int:
    """A second ground station changes the vehicle's fence rule under the run: once the vehicle holds at ENU
    (``x``, ``y``) (within 0.6 m, above 1 m, armed) with FENCE_OPTIONS 2 (the union our backend set), set
    FENCE_OPTIONS 0 (ArduPilot's default: inclusion zones intersect), then follow the vehicle until it disarms."""
    w = Watcher(conn, home)
    w.wait_vehicle(120)
    s, c = w.sysid, w.compid
    end = time.monotonic() + timeout_s
    cleared = None
    while time.monotonic() < end and not (w.was_armed and not w.armed):
        w.pump()
        if cleared is None and w.armed and w.samples and w.samples[-1][3] > 1.0 \
                and math.hypot(w.samples[-1][1] - x, w.samples[-1][2] - y) < 0.6:
            before = w._ask(lambda: w.m.mav.param_request_read_send(s, c, b"FENCE_OPTIONS", -1),
                            lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "FENCE_OPTIONS").param_value
            if before != 2:
                continue  # our backend has not set it (yet)
            after = w._ask(lambda: w.m.mav.param_set_send(s, c, b"FENCE_OPTIONS", 0.0, 2),
                           lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "FENCE_OPTIONS").param_value
            cleared = {"t": w.t_boot, "before": before, "after": after, "at": w.samples[-1]}
    Path(out).write_text(json.dumps({"cleared": cleared, "samples": w.samples, "modes": w.modes,
                                     "fence_status": w.fence_status, "texts": w.texts, "armed_at_end": w.armed}))
    return 0


def read_params(conn: str, out: str, home: GeoPoint) -> int:
    w = Watcher(conn, home)
    w.wait_vehicle(120)
    Path(out).write_text(json.dumps(w.read_all_params()))
    return 0


def mission_flight(conn: str, out: str, home: GeoPoint, timeout_s: float = 400.0) -> int:
    """Follow a mission someone else started (``aerodaas mission upload --start``) until the vehicle has landed and
    disarmed, then read every parameter: positions (the firmware's GLOBAL_POSITION_INT), modes, texts, params."""
    w = Watcher(conn, home)
    w.wait_vehicle(120)
    end = time.monotonic() + timeout_s
    arming = time.monotonic() + 60.0  # a mission that was not started: no arming to wait for
    while time.monotonic() < end and not (w.was_armed and not w.armed) and (w.was_armed or time.monotonic() < arming):
        w.pump()
    params = w.read_all_params()
    Path(out).write_text(json.dumps({"samples": w.samples, "modes": w.modes, "texts": w.texts,
                                     "was_armed": w.was_armed, "armed_at_end": w.armed, "params": params}))
    return 0


#: the overlapping inclusion circles of the fence tests: (east, north, radius) metres from home; home is in both
OVERLAP_CIRCLES = [(-6.0, 0.0, 10.0), (6.0, 0.0, 10.0)]


def px4_intersects(conn: str, out: str, home: GeoPoint, timeout_s: float = 300.0) -> int:
    """How PX4 reads two overlapping inclusion circles (:data:`OVERLAP_CIRCLES`), asked as a ground station would:
    upload them as its fence, GF_ACTION 2 (Hold), arm, take off, then DO_REPOSITION to (2, 0) (inside both), then to
    (-12, 0) (inside the first only), 10 s of the firmware's time each. Records the times of the commands and every
    position."""
    import struct

    from aerodaas.model.geo import enu_to_geodetic

    w = Watcher(conn, home)
    w.wait_vehicle(120)
    s, c = w.sysid, w.compid
    f = struct.unpack("<f", struct.pack("<i", 2))[0]  # GF_ACTION is INT32, bytewise in the float field
    w._ask(lambda: w.m.mav.param_set_send(s, c, b"GF_ACTION", f, 6),
           lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "GF_ACTION")
    items = []
    for e, n, r in OVERLAP_CIRCLES:
        g = enu_to_geodetic(e, n, 0.0, home)
        items.append((5003, r, int(round(g.lat * 1e7)), int(round(g.lon * 1e7))))
    w.m.mav.mission_count_send(s, c, len(items), MAV_MISSION_TYPE_FENCE)
    acked = None
    end = time.monotonic() + 30
    while acked is None and time.monotonic() < end:
        msg = w.pump(0.2, want=("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"))
        if msg is None or msg.mission_type != MAV_MISSION_TYPE_FENCE:
            continue
        if msg.get_type() == "MISSION_ACK":
            acked = msg.type
            break
        cmd, r, xi, yi = items[msg.seq]
        w.m.mav.mission_item_int_send(s, c, msg.seq, 0, cmd, 0, 1, r, 0, 0, 0, xi, yi, 0, MAV_MISSION_TYPE_FENCE)
    end = time.monotonic() + timeout_s
    while time.monotonic() < end and not (w.armed and w.samples and w.samples[-1][3] > 2.0):
        if not w.armed:
            w.m.mav.command_long_send(s, c, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # arm
        elif w.mode != "TAKEOFF":
            w.m.mav.command_long_send(s, c, 22, 0, 0, 0, 0, math.nan, math.nan, math.nan, home.alt + 5.0)
        stop = time.monotonic() + 1.0
        while time.monotonic() < stop:
            w.pump()
    commands = []
    for e, n in ((2.0, 0.0), (-12.0, 0.0)):
        g = enu_to_geodetic(e, n, 0.0, home)
        w.m.mav.command_long_send(s, c, 192, 0, -1, 1, 0, math.nan, g.lat, g.lon, home.alt + 5.0)  # DO_REPOSITION
        t0 = w.t_boot
        commands.append({"target": [e, n], "t": t0})
        while time.monotonic() < end and w.t_boot < t0 + 10.0:
            w.pump()
    w.m.mav.command_long_send(s, c, 21, 0, 0, 0, 0, 0, 0, 0, 0)  # land where it is
    Path(out).write_text(json.dumps({"fence_ack": acked, "commands": commands, "samples": w.samples,
                                     "modes": w.modes, "texts": w.texts}))
    return 0


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        return True
    except OSError:
        return False


def read_fence(conn: str, out: str, home: GeoPoint) -> int:
    w = Watcher(conn, home)
    w.wait_vehicle(120)
    Path(out).write_text(json.dumps(w.read_fence()))
    return 0


if __name__ == "__main__":
    from tests.firmware.sitl import FARM_HOME

    h = GeoPoint(**FARM_HOME)
    if sys.argv[1] == "read-fence":
        sys.exit(read_fence(sys.argv[2], sys.argv[3], h))
    if sys.argv[1] == "read-params":
        sys.exit(read_params(sys.argv[2], sys.argv[3], h))
    if sys.argv[1] == "mission-flight":
        sys.exit(mission_flight(sys.argv[2], sys.argv[3], h))
    if sys.argv[1] == "clear-union":
        sys.exit(clear_union(sys.argv[2], sys.argv[3], h, float(sys.argv[4]), float(sys.argv[5])))
    if sys.argv[1] == "px4-intersects":
        sys.exit(px4_intersects(sys.argv[2], sys.argv[3], h))
    if sys.argv[1] == "kill-and-push":
        # optional 5th argument: the push's wall seconds (default 25; tests/firmware/test_sitl_fence.py PUSH_FIRMWARE_S)
        sys.exit(kill_and_push(sys.argv[2], int(sys.argv[3]), sys.argv[4], h,
                               **({"push_s": float(sys.argv[5])} if len(sys.argv) > 5 else {})))
    raise SystemExit(f"unknown command {sys.argv[1]!r}")
