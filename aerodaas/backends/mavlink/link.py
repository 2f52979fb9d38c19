"""Link and heartbeat (MAVLink heartbeat/connection protocol, mavlink.io/en/services/heartbeat.html): opening the
pymavlink connection, finding and identifying the autopilot, the I/O thread (receive, de-duplicate, dispatch; our GCS
HEARTBEAT at 1 Hz; link-loss watch) and the telemetry stream requests (MAV_CMD_SET_MESSAGE_INTERVAL, else
REQUEST_DATA_STREAM). A concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (:class:`MavlinkLink`);
the vehicle clock is :mod:`.clock`'s, the status texts :mod:`.statustext`'s."""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any, Callable, Literal

from pymavlink import mavutil

from aerodaas.backends.base import BackendError, CommandRefused, CredentialsRefused, LinkLost
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.routes import CommandRoute, ComponentRoute, MissionRoute, SetpointStream, StreamSource
from aerodaas.backends.mavlink.shared_link import LinkPort, PortLosses, open_link
from aerodaas.backends.mavlink.signing import LinkSigning, NoSigning
from aerodaas.backends.mavlink.statustext import StatusTexts
from aerodaas.backends.mavlink._common import FAILSAFE_MODES, M, _enum_name, log, _ESTIMATOR_STREAM, _LEGACY_STREAMS, _MULTIROTORS, _NOT_VEHICLES, _TELEMETRY

#: the most wall time (seconds) one round of the I/O loop spends reading a backlog before its periodic sends
_DRAIN_S = 0.25


class MavlinkLink:
    """The link to one autopilot (see the module docstring): the connection, the autopilot's identity and HEARTBEAT
    (:attr:`armed`, :attr:`mode`, :attr:`link_ok`, its own failsafes), the I/O thread that receives and dispatches
    every message, our GCS HEARTBEAT, sending, and the telemetry stream requests.

    It knows only what it is given: ``settings`` (:class:`~aerodaas.config.MavlinkConfig`), ``clock`` (the
    :class:`~aerodaas.backends.mavlink.clock.VehicleClock` the timestamped messages feed; the link registers itself
    with it as its :class:`~aerodaas.backends.mavlink.clock.LinkHealth`), ``texts`` (the
    :class:`~aerodaas.backends.mavlink.statustext.StatusTexts` STATUSTEXT feeds), ``signing`` (MAVLink 2 signing,
    :class:`~aerodaas.backends.mavlink.signing.LinkSigning`, or :class:`~aerodaas.backends.mavlink.signing.NoSigning`:
    every received message passes its check first, every sent one is signed), ``event`` (records a backend
    event), ``lock`` (the backend's lock: the I/O thread updates every concern's state under it). As in MAVSDK,
    where each plugin is handed the ``System`` and subscribes to its messages, the concerns made on this link
    register what they receive: :meth:`serve_commands` (:class:`CommandRoute`: COMMAND_ACK, the mode we last asked
    for, the command sender for stream requests), :meth:`serve_mission_protocol` (:class:`MissionRoute`),
    :meth:`serve_components` (:class:`ComponentRoute`: every message of the vehicle's system, cameras included),
    :meth:`serve_setpoints` (:class:`SetpointStream`: the guided target streamed by the I/O thread),
    :meth:`add_streams` (:class:`StreamSource`: more (message id, Hz) to request) and :meth:`handle` (the handler
    of one message type). Raises :class:`BackendError` / :class:`LinkLost` as :meth:`open`, :meth:`send` and
    :meth:`check_link` say."""

    def __init__(self, robot_id: str, settings: Any, *, clock: VehicleClock, texts: StatusTexts,
                 signing: LinkSigning | NoSigning, event: Callable[..., None], lock: threading.RLock) -> None:
        self.robot_id, self._settings, self._clock, self._texts = robot_id, settings, clock, texts
        self._signing = signing
        self._event, self._lock = event, lock
        self._commands: CommandRoute | None = None
        self._mission: MissionRoute | None = None
        self._components: list[ComponentRoute] = []
        self._setpoints: SetpointStream | None = None
        self._stream_sources: list[StreamSource] = []
        clock.watch(self)
        #: the handler of each other message type (registered with :meth:`handle`), called under ``lock``
        self.handlers: dict[str, Callable[[Any], None]] = {}
        #: the connection (shared_link.py ``LinkPort``), None when not connected
        self.port: Any = None
        #: ``"ardupilot"`` / ``"px4"`` once identified (``mavlink.autopilot``, else the HEARTBEAT's)
        self.autopilot: Literal["ardupilot", "px4"] | None = None
        #: the HEARTBEAT's MAV_TYPE name (``MAV_TYPE_QUADROTOR``...)
        self.vehicle_type: str = ""
        #: every message the receive path saw, unknown and malformed ones included
        self.messages_received = 0
        #: the autopilot's failsafe, when it entered one by itself: {"mode", "previous", "t", "text"}
        self.failsafe: dict[str, Any] | None = None
        self._sysid = self._compid = 0
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._io: threading.Thread | None = None
        self._io_error: BaseException | None = None
        self._recent: deque[tuple] = deque(maxlen=32)  # (sys, comp, seq, msgid, crc) for duplicate packets
        self._ap_modes: dict[str, int] = {}
        self._armed = False
        self._mode = ""
        self._system_status = 0
        self._was_armed = False  # armed once: the ENU origin (home) stays put until the next arm() (telemetry.py)
        self._link_ok = False
        self._last_hb = 0.0
        self._hb_boot_ms = 0  # the vehicle's time_boot_ms when its latest HEARTBEAT came (periodic)
        self._hb_next = 0.0
        self._failsafe_undelivered = 0  # autopilot_failsafe events not yet handed out by drain_events
        #: the messages of this vehicle the shared link dropped or lost, reported as events (shared_link.py)
        self.losses = PortLosses(robot_id, event)
        self._mode_changes = 0
        self._stream_legacy = False
        self._ever_linked = False
        self._resume_streams = False
        self._streams_refused: set[int] = set()  # message ids the vehicle would not stream

    # ------------------------------------------------------------------ what the concerns made on this link receive
    def serve_commands(self, commands: CommandRoute) -> None:
        """COMMAND_ACKs go to ``commands``; its :attr:`~CommandRoute.mode_asked` is no failsafe; stream and
        HOME_POSITION requests are sent with its ``command_long``."""
        self._commands = commands

    def serve_mission_protocol(self, transfers: MissionRoute) -> None:
        """The mission protocol's messages (MISSION_REQUEST(_INT), MISSION_ACK, MISSION_COUNT, MISSION_ITEM(_INT))
        go to ``transfers``."""
        self._mission = transfers

    def serve_components(self, receiver: ComponentRoute) -> None:
        """Every message of the vehicle's system (any component) goes to ``receiver`` too."""
        self._components.append(receiver)

    def serve_setpoints(self, stream: SetpointStream) -> None:
        """The I/O thread streams ``stream``'s active target and stops it on an autopilot failsafe."""
        self._setpoints = stream

    def add_streams(self, source: StreamSource) -> None:
        """The (message id, Hz) ``source`` asks for are requested with the telemetry streams."""
        self._stream_sources.append(source)

    def handle(self, message_type: str, handler: Callable[[Any], None]) -> None:
        """Messages of ``message_type`` (pymavlink's name, e.g. ``"PARAM_VALUE"``) go to ``handler`` under the lock.
        Raises ValueError when that type already has a handler."""
        if message_type in self.handlers:
            raise ValueError(f"robot {self.robot_id!r}: {message_type} already has a handler")
        self.handlers[message_type] = handler

    # ------------------------------------------------------------------ lifecycle
    def open(self, deadline: float, timeout: float) -> None:
        """Open ``mavlink.connection``, wait for the autopilot's HEARTBEAT (GCS and peripheral heartbeats are
        ignored) until ``deadline`` (time.monotonic()), identify it, start the I/O thread, request the telemetry
        streams and HOME_POSITION. Raises :class:`BackendError` without a HEARTBEAT (``timeout``: the seconds
        named), naming the connection string; ValueError for a vehicle that is not a multirotor or an autopilot
        that cannot be identified (closed again in both cases)."""
        where = f"robot {self.robot_id!r}: mavlink connection {self._settings.connection!r}"
        # one socket per endpoint in this process, shared by every robot that names it (shared_link.py)
        port = open_link(self._settings, self.robot_id, deadline)
        self.port = port
        self._send_lock = port.send_lock
        if self._signing.enabled:
            port.link.use_signing_encoder()  # before our first (signed) HEARTBEAT
            port.screen = self._signing.screen  # checked before queueing: rejected messages take no queue slot
        next_hb = [0.0]

        def tick() -> None:  # udpout: the vehicle learns our address from what we send
            if time.monotonic() >= next_hb[0]:
                self._send_gcs_heartbeat()
                next_hb[0] = time.monotonic() + 1.0

        try:
            hb = port.claim(self._settings.target_system, deadline, tick)
        except TimeoutError as e:
            self.close()
            which = ("" if self._settings.target_system in (None, "auto")
                     else f" from system id {self._settings.target_system}")
            raise BackendError(f"{where}: no autopilot HEARTBEAT{which} within {timeout:g} s ({e})") from None
        except BaseException:
            self.close()
            raise
        if self._signing.enabled:
            hb = self._signed_heartbeat(port, deadline, tick, timeout)
        self.losses.count_from(port)  # counted from this connection on
        self.identify(hb)
        self._signing.announce(self._settings.connection)  # an unsigned link said out loud (signing.py NoSigning)
        self.on_heartbeat(hb, time.monotonic())
        self._stop.clear()
        self._io = threading.Thread(target=self._io_loop, name=f"mavlink-{self.robot_id}", daemon=True)
        self._io.start()
        self.request_streams()
        self.request_home()

    def _signed_heartbeat(self, port: LinkPort, deadline: float, tick: Callable[[], None], timeout: float) -> Any:
        """The first correctly signed autopilot HEARTBEAT of the system ``port`` claimed, reading (and passing
        through the signature check, which counts what it drops) everything the vehicle sent until then; ``tick``
        between reads. Raises :class:`CredentialsRefused` (after closing) at ``deadline`` (time.monotonic()): the vehicle
        does not hold our key, or does not sign."""
        system, signing = port.target_system, self._signing
        while time.monotonic() < deadline:
            msg = port.recv_msg()
            if msg is None:
                tick()
                port.select(0.05)
                continue
            if msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == system \
                    and msg.get_srcComponent() == port.target_component and signing.accept(msg):
                return msg
            if msg.get_type() not in ("BAD_DATA",) and not msg.get_type().startswith("UNKNOWN_"):
                signing.accept(msg)  # counted and reported when dropped; not dispatched before the vehicle is known
        unsigned, bad = signing.unsigned, signing.bad_signature
        self.close()
        raise CredentialsRefused(f"robot {self.robot_id!r}: no correctly signed heartbeat from system {system} within "
                           f"{timeout:g} s on {self._settings.connection!r} (mavlink.signing_key_file "
                           f"{self._settings.signing_key_file!r}; {unsigned} unsigned and {bad} wrongly signed "
                           f"messages from it): the vehicle does not hold this key or does not sign; provision it with "
                           f"`aerodaas mavlink signing setup`")

    def attach(self, system: int, component: int) -> None:
        """Take the autopilot at ``system``/``component`` as found and the link as up, without :meth:`open`'s
        HEARTBEAT exchange (messages handed to :meth:`dispatch` by hand: tests/mavlink/mavlink_wire.py)."""
        self._sysid, self._compid, self._link_ok = system, component, True

    @property
    def running(self) -> bool:
        """Connected, with the I/O thread started and not yet told to stop."""
        return self.port is not None and self._io is not None and not self._stop.is_set()

    @property
    def io_alive(self) -> bool:
        """The I/O thread is running."""
        return self._io is not None and self._io.is_alive()

    def close(self) -> None:
        """Stop the I/O thread and close the connection (idempotent, never raises)."""
        self._stop.set()
        if self._io is not None and self._io is not threading.current_thread():
            self._io.join(timeout=2)
        self._io = None
        self._signing.close()
        if self.port is not None:
            try:
                self.port.close()
            except Exception:  # noqa: BLE001
                pass
            self.port = None

    def _is_autopilot_heartbeat(self, msg: Any) -> bool:
        ours = (self._settings.source_system, self._settings.source_component)
        if (msg.get_srcSystem(), msg.get_srcComponent()) == ours:
            return False
        if msg.autopilot == M.MAV_AUTOPILOT_INVALID or msg.type in _NOT_VEHICLES:
            return False
        return not self._sysid or msg.get_srcSystem() == self._sysid

    def identify(self, hb: Any) -> None:
        """Take the autopilot of HEARTBEAT ``hb`` as ours: its flavour (``mavlink.autopilot``, else the HEARTBEAT's
        MAV_AUTOPILOT; an ``autopilot_mismatch`` event when they differ), ids and ArduPilot mode table. Raises
        ValueError (after closing) for a flavour that cannot be told or a vehicle that is not a multirotor."""
        found = {M.MAV_AUTOPILOT_ARDUPILOTMEGA: "ardupilot", M.MAV_AUTOPILOT_PX4: "px4"}.get(hb.autopilot)
        flavour = found if self._settings.autopilot == "auto" else self._settings.autopilot
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

    def mode_params(self, name: str) -> tuple[float, ...]:
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
        conn = self.port
        while not self._stop.is_set():
            got, start = 0, time.monotonic()
            # at most a quarter of PX4's offboard-loss timeout (wall seconds at the vehicle's speed-up) between sends
            loss_s = self._setpoints.loss_timeout_s if self._setpoints is not None else 1.0
            budget = min(_DRAIN_S, 0.25 * loss_s / max(self._clock.ratio, 1.0))
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
                    self.dispatch(msg, time.monotonic())
                except Exception as e:  # noqa: BLE001 - a malformed message must never stop telemetry
                    self._event("receive_error", message=msg.get_type(), error=str(e))
                if time.monotonic() - start > budget:
                    break
            now = time.monotonic()
            try:
                self.periodic(now)
            except Exception as e:  # noqa: BLE001
                self._io_error = e
            if not got:
                try:
                    conn.select(0.005)
                except Exception:  # noqa: BLE001
                    time.sleep(0.005)

    def dispatch(self, msg: Any, now: float) -> None:
        """One received message (``now``: wall time): counted, skipped when malformed, a duplicate or not the
        autopilot's system, else handed to its receiver (HEARTBEAT and STATUSTEXT here, COMMAND_ACK, the mission
        protocol's messages, then :attr:`handlers` under ``lock``)."""
        mtype = msg.get_type()
        self.messages_received += 1
        if mtype == "BAD_DATA" or mtype.startswith("UNKNOWN_"):
            return
        if not self._signing.accept(msg):
            return  # unsigned, wrongly signed or replayed: counted and reported by the signing check (signing.py)
        key = (msg.get_srcSystem(), msg.get_srcComponent(), msg.get_seq(), msg.get_msgId(), getattr(msg, "_crc", 0))
        if key in self._recent:
            return  # the same packet again (captured on two links)
        self._recent.append(key)
        src_sys, src_comp = msg.get_srcSystem(), msg.get_srcComponent()
        if self._sysid and src_sys != self._sysid:
            return
        for receiver in self._components:  # cameras are components of their own: before the autopilot-only filter
            receiver.on_message(msg)
        if mtype == "HEARTBEAT":
            if src_comp == self._compid and self._is_autopilot_heartbeat(msg):
                self.on_heartbeat(msg, now)
            return
        if mtype == "STATUSTEXT":
            self._texts.on_statustext(msg, now)
            return
        if self._compid and src_comp != self._compid:
            return
        if mtype == "COMMAND_ACK":
            if self._commands is not None and getattr(msg, "target_system", 0) in (0, self._settings.source_system):
                self._commands.on_command_ack(now, msg)
            return
        if mtype in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_COUNT", "MISSION_ITEM_INT",
                     "MISSION_ITEM"):
            if self._mission is not None:  # kept for the exchange under way, when it is for us (transfer.py)
                self._mission.offer(msg)
            return
        handler = self.handlers.get(mtype)  # registered by the concerns (handle)
        if handler is not None:
            with self._lock:
                handler(msg)

    def on_heartbeat(self, msg: Any, now: float) -> None:
        """The autopilot's HEARTBEAT at wall time ``now``: the link is up (``link_regained`` after a loss, the
        streams asked for again), the armed flag, the mode (a failsafe mode checked: :meth:`_check_failsafe`) and
        ``system_status``."""
        with self._lock:
            self._last_hb = now
            self._hb_boot_ms = self._clock.boot_ms
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
        asked = self._commands.mode_asked if self._commands is not None else None
        if not self._armed or mode not in FAILSAFE_MODES.get(self.autopilot or "", ()):
            return
        if asked is not None and asked[0] == mode:
            return
        texts = self._texts.recent(now, 2.0)
        self.failsafe = {"mode": mode, "previous": previous, "t": round(self._clock.t, 3),
                         "text": "; ".join(texts[-3:])}
        if self._setpoints is not None:
            self._setpoints.stop_quiet()
        self._failsafe_undelivered += 1
        self._event("autopilot_failsafe", **{k: v for k, v in self.failsafe.items() if k != "t"})

    def periodic(self, now: float) -> None:
        """The I/O thread's work after each read (``now``: wall time): link drop reports, stale status texts, our GCS
        HEARTBEAT (1 Hz of the vehicle's clock, at most 20 Hz), the link-loss watch, and the setpoint stream."""
        self.losses.report(self.port, now)
        self._signing.report(now)
        self._texts.flush_stale(now)
        if now >= self._hb_next:
            self._hb_next = now + 1.0 / max(1.0, min(self._clock.ratio, 20.0))
            self._send_gcs_heartbeat()
        with self._lock:
            # lost only once everything received until past the deadline has been read (LinkPort.live_since): after
            # a stall of this process the heartbeats of the stall may still wait in the socket
            # (and in any case after twice the timeout: a link whose socket is never empty, e.g. a noisy serial line)
            read_until, timeout = self.live_since(now), self._settings.heartbeat_timeout_s
            missed = now - self._last_hb > timeout and self._clock.heartbeats_missed(now, self._hb_boot_ms)
            if self._link_ok and missed \
                    and (read_until - self._last_hb > timeout or now - self._last_hb > 2.0 * timeout):
                self._link_ok = False
                self._event("link_lost", silent_s=round(now - self._last_hb, 3))
                self._clock.link_lost()
            resume = self._resume_streams
            self._resume_streams = False
            sp = self._setpoints.setpoint if self._link_ok and self._setpoints is not None else None
        if resume:
            self.request_streams(wait=False)
        if sp is not None:
            self._setpoints.send_due(sp, now)

    # ------------------------------------------------------------------ sending
    def live_since(self, now: float) -> float:
        """Everything received until this wall time has been read (shared_link.py ``LinkPort.live_since``; ``now``
        without a connection)."""
        return getattr(self.port, "live_since", now)

    def send(self, fn: Callable[[Any], None]) -> None:
        """Send with ``fn(mav)`` (a pymavlink ``MAVLink`` encoder) under the link's send lock. Raises LinkLost when
        not connected or the socket fails."""
        conn = self.port
        if conn is None:
            raise LinkLost(f"robot {self.robot_id!r}: not connected")
        with self._send_lock:
            try:
                mav = conn.mav
                self._signing.before_send(mav)
                fn(mav)
                self._signing.after_send(mav)
            except OSError as e:
                raise LinkLost(f"robot {self.robot_id!r}: send failed: {e}") from None

    def _command(self, name: str, command: int, *params: float, retries: int | None = None) -> None:
        """COMMAND_LONG through the command protocol that :meth:`serve_commands` named. Raises BackendError without
        one, else as :meth:`CommandRoute.command_long`."""
        if self._commands is None:
            raise BackendError(f"robot {self.robot_id!r}: no command protocol on this link for {name}")
        self._commands.command_long(name, command, *params, retries=retries)

    def _send_gcs_heartbeat(self) -> None:
        try:
            self.send(lambda mav: mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                                      M.MAV_STATE_ACTIVE))
        except (LinkLost, Exception):  # noqa: BLE001 - the link may be down; the heartbeat watch reports it
            pass

    def check_link(self, command: str) -> None:
        """Raise before ``command`` runs: BackendError when not connected or the I/O thread failed, LinkLost while
        the link is lost."""
        if self.port is None:
            raise BackendError(f"robot {self.robot_id!r}: {command}: not connected (call connect() first)")
        if self._io_error is not None:
            raise BackendError(f"robot {self.robot_id!r}: {command}: the MAVLink I/O thread failed: {self._io_error}")
        if not self._link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {command}: link lost (no HEARTBEAT for more than "
                           f"{self._settings.heartbeat_timeout_s:g} s)")

    # ------------------------------------------------------------------ streams and home
    def request_streams(self, wait: bool = True) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL for each telemetry message (rates in the vehicle's time); on UNSUPPORTED or
        no acknowledgement fall back to REQUEST_DATA_STREAM. ``wait=False`` (from the I/O thread, after the link
        returns) re-sends the method chosen at connect without waiting for acknowledgements."""
        rate = self._settings.stream_rate_hz
        if not wait:
            for msg_id, hz in self._streams() if not self._stream_legacy else ():
                self.send(lambda mav, m=msg_id, h=hz: mav.command_long_send(
                    self._sysid, self._compid, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, m, 1e6 / (h or rate), 0, 0, 0, 0, 0))
            if self._stream_legacy:
                self._legacy_streams(rate)
            return
        for msg_id, hz in self._streams():
            name = f"SET_MESSAGE_INTERVAL for message {msg_id}"
            try:
                self._command(name, M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / (hz or rate), retries=1)
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
        """(message id, Hz or None for ``stream_rate_hz``) of every telemetry message requested (the extra streams:
        the gimbal's attitude when a gimbal is configured)."""
        extra = _ESTIMATOR_STREAM.get(self.autopilot or "")
        return _TELEMETRY + ((extra,) if extra else ()) + tuple(x for source in self._stream_sources for x in source.streams())

    def _legacy_streams(self, rate: float) -> None:
        for _ in range(3):  # no acknowledgement exists for REQUEST_DATA_STREAM
            for stream, hz in _LEGACY_STREAMS:
                self.send(lambda mav, s=stream, h=hz: mav.request_data_stream_send(
                    self._sysid, self._compid, s, max(1, int(round(h or rate))), 1))

    def request_home(self) -> None:
        """MAV_CMD_REQUEST_MESSAGE(HOME_POSITION), MAV_CMD_GET_HOME_POSITION where that is unsupported; a refusal
        or no answer is no error (the autopilot sends home once it has one). Raises LinkLost."""
        try:
            self._command("request HOME_POSITION", M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION,
                              retries=1)
        except CommandRefused as e:
            if e.result == "MAV_RESULT_UNSUPPORTED":
                try:
                    self._command("request HOME_POSITION", M.MAV_CMD_GET_HOME_POSITION, retries=1)
                except BackendError:
                    pass
            # FAILED / DENIED: no home yet; it is sent when it is set
        except LinkLost:
            raise
        except BackendError:
            pass

    # ------------------------------------------------------------------ state
    @property
    def target(self) -> tuple[int, int]:
        """The autopilot's system and component id (0, 0 before it is identified)."""
        return self._sysid, self._compid

    @property
    def armed(self) -> bool:
        """The armed flag of the autopilot's latest HEARTBEAT."""
        return self._armed

    @property
    def was_armed(self) -> bool:
        """Armed at least once since the backend was made."""
        return self._was_armed

    @property
    def link_ok(self) -> bool:
        """HEARTBEATs keep coming (false before connect and after ``heartbeat_timeout_s`` without one)."""
        return self._link_ok

    @property
    def mode(self) -> str:
        """The flight mode from the latest HEARTBEAT, in pymavlink's names (``GUIDED``, ``OFFBOARD``, ``LOITER``...)."""
        return self._mode

    @property
    def mode_changes(self) -> int:
        """How many times the HEARTBEAT's mode changed."""
        return self._mode_changes

    @property
    def system_status(self) -> int:
        """The latest HEARTBEAT's ``system_status`` (MAV_STATE)."""
        return self._system_status

    @property
    def last_heartbeat(self) -> float:
        """Wall time (time.monotonic()) of the autopilot's latest HEARTBEAT."""
        return self._last_hb

    @property
    def ekf_report_unavailable(self) -> bool:
        """EKF_STATUS_REPORT will never come: its stream was refused, or the legacy REQUEST_DATA_STREAM is in use."""
        return M.MAVLINK_MSG_ID_EKF_STATUS_REPORT in self._streams_refused or self._stream_legacy

    @property
    def failsafe_undelivered(self) -> int:
        """``autopilot_failsafe`` events not yet handed out by the backend's ``drain_events``."""
        return self._failsafe_undelivered

    def failsafe_delivered(self) -> None:
        """An ``autopilot_failsafe`` event was handed out. Caller holds ``lock``."""
        self._failsafe_undelivered = max(0, self._failsafe_undelivered - 1)

    @property
    def wire_version(self) -> str:
        """The MAVLink wire protocol the connection speaks (``"1.0"`` / ``"2.0"``; ``"2.0"`` when not connected)."""
        return getattr(getattr(self.port, "mav", None), "WIRE_PROTOCOL_VERSION", "2.0")

    @property
    def io_error(self) -> BaseException | None:
        """What stopped the I/O thread's periodic work, if anything did."""
        return self._io_error
