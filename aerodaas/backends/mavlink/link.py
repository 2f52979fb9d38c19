"""Link and heartbeat (MAVLink heartbeat/connection protocol): opening the pymavlink connection, finding and identifying the
autopilot, the I/O thread (receive, de-duplicate, dispatch; our GCS HEARTBEAT at 1 Hz; link-loss watch), the vehicle clock
from ``time_boot_ms`` and the telemetry stream requests (MAV_CMD_SET_MESSAGE_INTERVAL, else REQUEST_DATA_STREAM)."""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable

from pymavlink import mavutil

from aerodaas.backends.base import BackendError, CommandRefused, LinkLost
from aerodaas.backends.mavlink.shared_link import open_link
from aerodaas.backends.mavlink._common import FAILSAFE_MODES, M, _enum_name, _log_level, log, _ESTIMATOR_STREAM, _LEGACY_STREAMS, _MULTIROTORS, _NOT_VEHICLES, _TELEMETRY

#: the most wall time (seconds) one round of the I/O loop spends reading a backlog before its periodic sends
_DRAIN_S = 0.25


#: wall seconds between two reports of a :class:`ReportedCount`
REPORT_EVERY_S = 5.0


class ReportedCount:
    """A growing count (messages dropped, messages lost) reported at most every :data:`REPORT_EVERY_S` wall seconds:
    ``base`` is what the counter held when this connection began, :attr:`reported` what has been reported since."""

    __slots__ = ("base", "reported", "_next")

    def __init__(self, base: int = 0) -> None:
        self.base, self.reported, self._next = int(base), 0, 0.0

    def due(self, counter: int, now: float) -> int:
        """How many of ``counter`` (the counter's value now) are new since the last report, when a report is due at
        ``now`` (time.monotonic() seconds), and mark them reported; 0 when nothing new or not yet due."""
        new = counter - self.base - self.reported
        if new <= 0 or now < self._next:
            return 0
        self.reported += new
        self._next = now + REPORT_EVERY_S
        return new


class LinkMixin:
    """Part of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (see its docstring for the shared state)."""

    # ------------------------------------------------------------------ lifecycle
    def connect(self, timeout_s: float | None = None) -> None:
        """Open ``mavlink.connection``, wait for the autopilot's HEARTBEAT (GCS and peripheral heartbeats are
        ignored), identify it, start the I/O thread, request the telemetry streams and HOME_POSITION, and wait
        for the first SYS_STATUS. Raises :class:`BackendError` after ``timeout_s`` (default
        ``connect_timeout_s``) seconds, naming the connection string; ValueError for a vehicle that is not a
        multirotor or an autopilot that cannot be identified."""
        timeout = self.cfg.connect_timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        where = f"robot {self.robot_id!r}: mavlink connection {self.cfg.connection!r}"
        # one socket per endpoint in this process, shared by every robot that names it (shared_link.py)
        port = open_link(self.cfg, self.robot_id, deadline)
        self._conn = port
        self._send_lock = port.send_lock
        next_hb = [0.0]

        def tick() -> None:  # udpout: the vehicle learns our address from what we send
            if time.monotonic() >= next_hb[0]:
                self._send_gcs_heartbeat()
                next_hb[0] = time.monotonic() + 1.0

        try:
            hb = port.claim(self.cfg.target_system, deadline, tick)
        except TimeoutError as e:
            self.close()
            which = ("" if self.cfg.target_system in (None, "auto")
                     else f" from system id {self.cfg.target_system}")
            raise BackendError(f"{where}: no autopilot HEARTBEAT{which} within {timeout:g} s ({e})") from None
        except BaseException:
            self.close()
            raise
        # counted from this connection on (the shared link may have counted this system id for an earlier one)
        self._drops_report, self._lost_report = ReportedCount(), ReportedCount(port.lost)
        self._received_base = port.received
        self._identify(hb)
        self._on_heartbeat(hb, time.monotonic())
        self._stop.clear()
        self._io = threading.Thread(target=self._io_loop, name=f"mavlink-{self.robot_id}", daemon=True)
        self._io.start()
        self._request_streams()
        self._request_home()
        while True:
            with self._lock:
                ready = self.telemetry.sys_status_seen
            if ready:
                break
            if time.monotonic() > deadline:
                self.close()
                raise BackendError(f"{where}: the autopilot sent HEARTBEAT but no SYS_STATUS within {timeout:g} s "
                                   "(telemetry streams not configured?)")
            time.sleep(0.01)
        with self._lock:
            self.clock.start()
            self.telemetry.clear_odometry()  # stamped on the clock before the connection's zero
        if self.autopilot == "px4":  # how long PX4 waits for our setpoints before its failsafe (offboard.py)
            got = self.read_parameters(["COM_OF_LOSS_T"]).get("COM_OF_LOSS_T")
            if got is not None and math.isfinite(got) and got > 0:
                self.offboard.loss_timeout_s = float(got)
            else:  # PX4's default 1 s, scaled as PX4 SITL's rcS scales it by its speed factor (never stricter)
                self.offboard.loss_timeout_s = max(1.0, self.clock.ratio)
            self._event("offboard_loss_timeout", seconds=self.offboard.loss_timeout_s, read=got is not None)
        if self.cfg.set_speed_limits:
            try:
                self.apply_speed_limits()
            except BaseException:
                self.close(safe_end=False)
                raise
        if self.cfg.fence.upload and not self.safety.geofence.is_empty:
            try:  # the autopilot's own fence, the second line behind our gate (fence.py)
                self.apply_fence()
            except BaseException:
                self.close(safe_end=False)
                raise

    def close(self, safe_end: bool = True) -> None:
        """Close the link (idempotent, never raises). With ``safe_end`` (default) a vehicle still armed is first
        brought down (:meth:`safe_end`), and parameters changed by :meth:`apply_speed_limits` are restored when
        ``restore_params`` says so and the vehicle is disarmed (never in flight: it would speed up). ``safe_end=False``
        hands the vehicle over as it is (``aerodaas mission upload --start``: the autopilot flies on)."""
        worker = self.speed_limits.worker  # a limit being lowered (params.py): finished before restoring parameters
        if worker is not None and worker is not threading.current_thread():
            worker.join(timeout=5.0)
        if self._conn is not None and self._io is not None and not self._stop.is_set():
            if safe_end:
                try:
                    self.safe_end()
                except Exception as e:  # noqa: BLE001 - closing must go on
                    self._event("safe_end_failed", error=str(e))
                    log.warning("%s: safe end failed: %s", self.robot_id, e)
            if self.cfg.fence.restore_on_close and self.fence.has_saved:
                if self._link_ok and not self._armed:
                    self.restore_fence()
                else:
                    self._event("fence_not_restored", reason="link lost" if not self._link_ok else "still armed")
            if self.cfg.restore_params and self.parameters.changed:
                if worker is not None and worker.is_alive():  # its PARAM_SET echoes and ours would be mixed up
                    self._event("params_not_restored", reason="speed limit write in progress",
                                names=self.parameters.changed)
                elif self._link_ok and not self._armed:
                    self.restore_parameters()
                else:
                    self._event("params_not_restored", reason="link lost" if not self._link_ok else "still armed",
                                names=self.parameters.changed)
        self._stop.set()
        if self._io is not None and self._io is not threading.current_thread():
            self._io.join(timeout=2)
        self._io = None
        if self._conn is not None:
            try:
                self._conn.close()
            except Exception:  # noqa: BLE001
                pass
            self._conn = None

    def _is_autopilot_heartbeat(self, msg: Any) -> bool:
        if msg.get_srcSystem() == self.cfg.source_system and msg.get_srcComponent() == self.cfg.source_component:
            return False
        if msg.autopilot == M.MAV_AUTOPILOT_INVALID or msg.type in _NOT_VEHICLES:
            return False
        return not self._sysid or msg.get_srcSystem() == self._sysid

    def _identify(self, hb: Any) -> None:
        found = {M.MAV_AUTOPILOT_ARDUPILOTMEGA: "ardupilot", M.MAV_AUTOPILOT_PX4: "px4"}.get(hb.autopilot)
        flavour = found if self.cfg.autopilot == "auto" else self.cfg.autopilot
        self.vehicle_type = _enum_name("MAV_TYPE", hb.type)
        if flavour is None:
            self.close()
            raise ValueError(f"robot {self.robot_id!r}: mavlink.autopilot is 'auto' but the HEARTBEAT says "
                             f"{_enum_name('MAV_AUTOPILOT', hb.autopilot)}; set mavlink.autopilot to 'ardupilot' "
                             "or 'px4'")
        if hb.type not in _MULTIROTORS:
            self.close()
            raise ValueError(f"robot {self.robot_id!r}: the vehicle is a {self.vehicle_type}; the MAVLink backend "
                             "flies multirotors only (mode numbers and guidance differ for planes and rovers)")
        if found is not None and found != flavour:
            self._event("autopilot_mismatch", configured=flavour, heartbeat=found)
        self.autopilot = flavour
        self._sysid, self._compid = hb.get_srcSystem(), hb.get_srcComponent()
        if flavour == "ardupilot":
            self._ap_modes = mavutil.mode_mapping_byname(hb.type) or dict(
                (v, k) for k, v in mavutil.mode_mapping_acm.items())
        self._event("connected", autopilot=flavour, vehicle_type=self.vehicle_type, system=self._sysid,
                    component=self._compid)

    def _mode_params(self, name: str) -> tuple[float, ...]:
        """MAV_CMD_DO_SET_MODE's custom mode params (after MAV_MODE_FLAG_CUSTOM_MODE_ENABLED) for flight mode ``name``
        on the identified autopilot: PX4's main and sub mode (pymavlink's ``px4_map``), ArduPilot's custom mode (the
        mode table of its vehicle type, learned in :meth:`_identify`). Raises ValueError for an unknown name."""
        if self.autopilot == "px4":
            if name not in mavutil.px4_map:
                raise ValueError(f"mode {name!r} is not a PX4 mode; choose from {sorted(mavutil.px4_map)}")
            _, main, sub = mavutil.px4_map[name]
            return main, sub
        if name not in self._ap_modes:
            raise ValueError(f"mode {name!r} is not an ArduPilot {self.vehicle_type} mode; choose from "
                             f"{sorted(self._ap_modes)}")
        return (self._ap_modes[name],)

    # ------------------------------------------------------------------ I/O thread
    def _io_loop(self) -> None:
        """Receive everything waiting (at most :data:`_DRAIN_S` wall seconds of work), then the periodic sends. A
        backlog is read before anything is sent: after a stall of this process (a loaded machine, a debugger, a
        SIGSTOP) the vehicle's messages of the stall are still queued, and a setpoint sent before reading them would
        act on a vehicle state that is gone (PX4 takes a setpoint stream that comes back as the end of its
        offboard-loss failsafe and returns to OFFBOARD: failsafe.cpp ``checkModeFallback``; seen on PX4 SITL)."""
        conn = self._conn
        while not self._stop.is_set():
            got, start = 0, time.monotonic()
            # at most a quarter of PX4's offboard-loss timeout (wall seconds at the vehicle's speed-up) between sends
            budget = min(_DRAIN_S, 0.25 * self.offboard.loss_timeout_s / max(self.clock.ratio, 1.0))
            while True:
                try:
                    msg = conn.recv_msg()
                except Exception:  # noqa: BLE001 - a broken packet or a socket hiccup: keep going
                    time.sleep(0.01)
                    break
                if msg is None:
                    break
                got += 1
                try:
                    self._dispatch(msg, time.monotonic())
                except Exception as e:  # noqa: BLE001 - a malformed message must never stop telemetry
                    self._event("receive_error", message=msg.get_type(), error=str(e))
                if time.monotonic() - start > budget:
                    break
            now = time.monotonic()
            try:
                self._periodic(now)
            except Exception as e:  # noqa: BLE001
                self._io_error = e
            if not got:
                try:
                    conn.select(0.005)
                except Exception:  # noqa: BLE001
                    time.sleep(0.005)

    def _dispatch(self, msg: Any, now: float) -> None:
        mtype = msg.get_type()
        self.messages_received += 1
        if mtype == "BAD_DATA" or mtype.startswith("UNKNOWN_"):
            return
        key = (msg.get_srcSystem(), msg.get_srcComponent(), msg.get_seq(), msg.get_msgId(), getattr(msg, "_crc", 0))
        if key in self._recent:
            return  # the same packet again (captured on two links)
        self._recent.append(key)
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        if self._sysid and src_sys != self._sysid:
            return
        self._cameras.on_message(msg)  # cameras are components of their own: before the autopilot-only filter
        if mtype == "HEARTBEAT":
            if src_comp == self._compid and self._is_autopilot_heartbeat(msg):
                self._on_heartbeat(msg, now)
            return
        if mtype == "STATUSTEXT":
            self.status_texts.on_statustext(msg, now)
            return
        if self._compid and src_comp != self._compid:
            return
        if mtype == "COMMAND_ACK":
            if getattr(msg, "target_system", 0) in (0, self.cfg.source_system):
                self.commands.on_command_ack(now, msg)
            return
        if mtype in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_COUNT", "MISSION_ITEM_INT",
                     "MISSION_ITEM"):
            self.transfers.offer(msg)  # kept for the exchange under way, when it is for us (transfer.py)
            return
        handler = self._handlers.get(mtype)  # the backend's typed table (backend.py _message_handlers)
        if handler is not None:
            with self._lock:
                handler(msg)

    def _on_heartbeat(self, msg: Any, now: float) -> None:
        with self._lock:
            self._last_hb = now
            self._hb_boot_ms = self.clock.boot_ms
            if not self._link_ok:
                self._link_ok = True
                if self._ever_linked:
                    self._event("link_regained")
                    self._resume_streams = True
                self._ever_linked = True
            armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
            if armed != self._armed:
                self._armed = armed
                self._was_armed = self._was_armed or armed
                self._event("armed" if armed else "disarmed")
            mode = mavutil.mode_string_v10(msg)
            if mode != self._mode:
                previous = self._mode
                self._mode = mode
                self._mode_changes += 1
                self._event("mode", name=mode)
                self._check_failsafe(mode, previous, now)
            self._system_status = msg.system_status

    def _check_failsafe(self, mode: str, previous: str, now: float) -> None:
        """A failsafe mode (:data:`FAILSAFE_MODES`) entered while the vehicle is armed, and not the one we last
        asked for (set_mode): the autopilot's own failsafe (datalink, battery, geofence action, EKF) or a pilot's
        switch. Recorded as :attr:`failsafe` and an ``autopilot_failsafe`` event with the status texts of the last
        2 s (the autopilot says why). Caller holds ``_lock``."""
        asked = self.commands.mode_asked
        if not self._armed or mode not in FAILSAFE_MODES.get(self.autopilot or "", ()):
            return
        if asked is not None and asked[0] == mode:
            return
        texts = self.status_texts.recent(now, 2.0)
        self.failsafe = {"mode": mode, "previous": previous, "t": round(self.t, 3), "text": "; ".join(texts[-3:])}
        self.offboard.stop_quiet()
        self._failsafe_undelivered += 1
        self._event("autopilot_failsafe", **{k: v for k, v in self.failsafe.items() if k != "t"})

    def _report_link_drops(self, now: float) -> None:
        """A ``link_messages_dropped`` event (and a warning) when the shared link's queue for this robot dropped
        messages since the last report (:data:`~.shared_link.PORT_QUEUE`: this robot's I/O fell behind what its
        vehicle sends), at most every 5 wall seconds, with the count since the last report and in all; likewise
        ``link_messages_lost`` (``lost`` since the last report, ``total``, ``received``, ``lost_pct``) for the
        messages the vehicle's MAVLink sequence numbers say never reached this process (radio, router, kernel buffer;
        :meth:`~.shared_link.SharedLink._count`)."""
        rep = self._drops_report
        new = rep.due(int(getattr(self._conn, "dropped", 0) or 0), now)
        if new:
            self._event("link_messages_dropped", dropped=new, total=rep.reported)
            log.warning("%s: the shared link dropped %d messages of this vehicle (%d in all): its I/O fell behind",
                        self.robot_id, new, rep.reported)
        rep = self._lost_report
        new = rep.due(int(getattr(self._conn, "lost", 0) or 0), now)
        if new:
            lost, received = rep.reported, int(getattr(self._conn, "received", 0) or 0) - self._received_base
            self._event("link_messages_lost", lost=new, total=lost, received=received,
                        lost_pct=round(100.0 * lost / max(1, lost + received), 2))
            log.warning("%s: %d messages of this vehicle were lost on the way here (%d of %d in all, by their "
                        "MAVLink sequence numbers)", self.robot_id, new, lost, lost + received)

    def _periodic(self, now: float) -> None:
        self._report_link_drops(now)
        self.status_texts.flush_stale(now)
        if now >= self._hb_next:
            self._hb_next = now + 1.0 / max(1.0, min(self.clock.ratio, 20.0))
            self._send_gcs_heartbeat()
        with self._lock:
            # lost only once everything received until past the deadline has been read (LinkPort.live_since): after
            # a stall of this process the heartbeats of the stall may still wait in the socket
            # (and in any case after twice the timeout: a link whose socket is never empty, e.g. a noisy serial line)
            read_until, timeout = self._live_since(now), self.cfg.heartbeat_timeout_s
            if self._link_ok and now - self._last_hb > timeout and self.clock.heartbeats_missed(now, self._hb_boot_ms) \
                    and (read_until - self._last_hb > timeout or now - self._last_hb > 2.0 * timeout):
                self._link_ok = False
                self._event("link_lost", silent_s=round(now - self._last_hb, 3))
                self.clock.link_lost()
            resume = self._resume_streams
            self._resume_streams = False
            sp = self.offboard.setpoint if self._link_ok else None
        if resume:
            self._request_streams(wait=False)
        if sp is not None:
            self.offboard.send_due(sp, now)

    # ------------------------------------------------------------------ sending
    def _live_since(self, now: float) -> float:
        """Everything received until this wall time has been read (shared_link.py ``LinkPort.live_since``; ``now``
        without a connection)."""
        return getattr(self._conn, "live_since", now)

    def _send(self, fn: Callable[[Any], None]) -> None:
        conn = self._conn
        if conn is None:
            raise LinkLost(f"robot {self.robot_id!r}: not connected")
        with self._send_lock:
            try:
                fn(conn.mav)
            except OSError as e:
                raise LinkLost(f"robot {self.robot_id!r}: send failed: {e}") from None

    def _send_gcs_heartbeat(self) -> None:
        try:
            self._send(lambda mav: mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                                      M.MAV_STATE_ACTIVE))
        except (LinkLost, Exception):  # noqa: BLE001 - the link may be down; the heartbeat watch reports it
            pass

    def _check_link(self, command: str) -> None:
        if self._conn is None:
            raise BackendError(f"robot {self.robot_id!r}: {command}: not connected (call connect() first)")
        if self._io_error is not None:
            raise BackendError(f"robot {self.robot_id!r}: {command}: the MAVLink I/O thread failed: {self._io_error}")
        if not self._link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {command}: link lost (no HEARTBEAT for more than "
                           f"{self.cfg.heartbeat_timeout_s:g} s)")

    # ------------------------------------------------------------------ streams and home
    def _request_streams(self, wait: bool = True) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL for each telemetry message (rates in the vehicle's time); on UNSUPPORTED or
        no acknowledgement fall back to REQUEST_DATA_STREAM. ``wait=False`` (from the I/O thread, after the link
        returns) re-sends the method chosen at connect without waiting for acknowledgements."""
        rate = self.cfg.stream_rate_hz
        if not wait:
            for msg_id, hz in self._streams() if not self._stream_legacy else ():
                self._send(lambda mav, m=msg_id, h=hz: mav.command_long_send(
                    self._sysid, self._compid, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, m, 1e6 / (h or rate), 0, 0, 0, 0, 0))
            if self._stream_legacy:
                self._legacy_streams(rate)
            return
        for msg_id, hz in self._streams():
            name = f"SET_MESSAGE_INTERVAL for message {msg_id}"
            try:
                self.command_long(name, M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / (hz or rate), retries=1)
            except CommandRefused as e:
                if e.result == "MAV_RESULT_UNSUPPORTED":
                    self._stream_legacy = True
                    break
                self._streams_refused.add(msg_id)
                self._event("stream_refused", message_id=msg_id, result=e.result)
            except LinkLost:
                raise
            except BackendError:
                self._stream_legacy = True
                break
        if self._stream_legacy:
            self._event("stream_fallback", method="REQUEST_DATA_STREAM")
            self._legacy_streams(rate)

    def _streams(self) -> tuple:
        """(message id, Hz or None for ``stream_rate_hz``) of every telemetry message requested."""
        extra = _ESTIMATOR_STREAM.get(self.autopilot or "")
        return _TELEMETRY + ((extra,) if extra else ())

    def _legacy_streams(self, rate: float) -> None:
        for _ in range(3):  # no acknowledgement exists for REQUEST_DATA_STREAM
            for stream, hz in _LEGACY_STREAMS:
                self._send(lambda mav, s=stream, h=hz: mav.request_data_stream_send(
                    self._sysid, self._compid, s, max(1, int(round(h or rate))), 1))

    def _request_home(self) -> None:
        try:
            self.command_long("request HOME_POSITION", M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION,
                              retries=1)
        except CommandRefused as e:
            if e.result == "MAV_RESULT_UNSUPPORTED":
                try:
                    self.command_long("request HOME_POSITION", M.MAV_CMD_GET_HOME_POSITION, retries=1)
                except BackendError:
                    pass
            # FAILED / DENIED: no home yet; it is sent when it is set
        except LinkLost:
            raise
        except BackendError:
            pass

    # ------------------------------------------------------------------ VehicleBackend: state
    @property
    def armed(self) -> bool:
        """The armed flag of the autopilot's latest HEARTBEAT."""
        return self._armed

    @property
    def link_ok(self) -> bool:
        """HEARTBEATs keep coming (false before connect and after ``heartbeat_timeout_s`` without one)."""
        return self._link_ok

    @property
    def mode(self) -> str:
        """The flight mode from the latest HEARTBEAT, in pymavlink's names (``GUIDED``, ``OFFBOARD``, ``LOITER``...)."""
        return self._mode

    @property
    def clock_ratio(self) -> float:
        """Vehicle seconds per wall second, estimated from ``time_boot_ms`` (1 for a real vehicle;
        :attr:`VehicleClock.ratio`)."""
        return self.clock.ratio

    @property
    def t(self) -> float:
        """Vehicle seconds since :meth:`connect` (:attr:`VehicleClock.t`)."""
        return self.clock.t

    def step(self, dt: float) -> None:
        """Telemetry arrives on the I/O thread; this reports that thread's failure (BackendError) and lowers the
        vehicle's speed limit when its estimator needs more margin (params.py :meth:`SpeedLimits.update`, then
        :meth:`SpeedLimits.resend_speed`)."""
        if self._io_error is not None:
            raise BackendError(f"robot {self.robot_id!r}: the MAVLink I/O thread failed: {self._io_error}")
        self.speed_limits.update()
        self.speed_limits.resend_speed()

