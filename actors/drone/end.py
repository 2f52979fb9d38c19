"""How a drone's run ends: a real vehicle still armed is brought down by its backend's safe end while its events,
state and odometry go on being recorded; a finished drone waits (bounded) until its recorded odometry shows the
vehicle's end state. An object of its drone (:attr:`~aerodaas.actors.drone.component.DroneComponent.end`); it knows nothing
else of the drone (the drone records its last odometry and the mission result itself: ``DroneComponent.finish``)."""
from __future__ import annotations

import threading
import time
from typing import Any, Callable

from aerodaas.actors.drone.odometry import OdometryPublisher
from aerodaas.navigation.fsm import MissionFSM, MissionState as S

#: vehicle seconds a landed, still armed vehicle is given to disarm by itself at the end (:meth:`RunEnd._await_disarm`)
DISARM_WAIT_S = 15.0
#: ... and wall seconds at most
DISARM_WAIT_WALL_S = 20.0
#: wall seconds a finished drone's odometry may wait for a position sample that shows its end state (:meth:`RunEnd.settled`)
SETTLE_WALL_S = 2.0


class RunEnd:
    """The end of robot ``robot_id``'s run on ``backend`` (see the module): its mission state machine ``fsm`` follows
    the vehicle down, ``event(kind, **fields)`` records the drone's events and ``odometry`` (the drone's
    :class:`~aerodaas.actors.drone.odometry.OdometryPublisher`) records and publishes its samples meanwhile.
    :attr:`ended`: how the run ended for this robot (None until :meth:`close`), e.g. ``"landed and disarmed"``."""

    def __init__(self, backend: Any, robot_id: str, fsm: MissionFSM, event: Callable[..., None],
                 odometry: OdometryPublisher) -> None:
        self.backend, self.robot_id, self.fsm, self.event, self.odometry = backend, robot_id, fsm, event, odometry
        self.ended: str | None = None
        self._settle_until: float | None = None  # wall deadline of the wait for the end state's first sample

    def close(self) -> None:
        """Close the backend. A real vehicle still armed (run timeout, error, Ctrl-C) is brought down first by the
        backend's safe end (LAND/RTL, wait for the disarm: ``mavlink.on_close``), and meanwhile its events (the mode
        change, ``safe_end``), state (LANDING, LANDED) and odometry are recorded until the disarm; :attr:`ended`
        says how the run ended for this robot."""
        b = self.backend
        safe_end, now = getattr(b.guidance, "safe_end", None), b.state()
        if callable(safe_end) and b.navigable and now.armed and now.link_ok and (now.in_air or self.fsm.state != S.LANDED):
            result: dict[str, Any] = {}

            def run() -> None:
                try:
                    result["how"] = safe_end()
                except Exception as e:  # noqa: BLE001 - recorded; closing goes on
                    result["error"] = f"{type(e).__name__}: {e}"

            self.event("safe_end_started", state=self.fsm.state.value, mode=now.mode or None,
                        on_close=getattr(getattr(b, "cfg", None), "on_close", None))
            th = threading.Thread(target=run, name=f"safe-end-{self.robot_id}", daemon=True)
            th.start()
            while th.is_alive():
                th.join(0.05)
                self._record_safe_end()
            self._record_safe_end()
            self._await_end_sample()
            how, now = result.get("how") or "failed: " + result.get("error", "?"), b.state()
            if how == "nothing":  # not ours to end (armed by someone else), or already down
                how = "landed" if not now.armed else "left armed (not commanded by us)"
            self.ended = {"landed": "safe end: landed and disarmed", "disarmed": "safe end: disarmed on the ground",
                          "timeout": "safe end: TIMEOUT, vehicle still armed",
                          "link lost": "safe end: link lost, vehicle left to its autopilot's failsafe"}.get(
                how, f"safe end {how}")
            self.event("run_end", how=self.ended, armed=bool(now.armed), in_air=bool(now.in_air))
        elif self.ended is None and b.navigable and now.armed and now.link_ok and self.fsm.state == S.LANDED:
            self.ended = self._await_disarm()
            self._await_end_sample()
            now = b.state()
            self.event("run_end", how=self.ended, armed=bool(now.armed), in_air=bool(now.in_air))
        elif self.ended is None:
            st = self.fsm.state
            self.ended = ("landed and disarmed" if st == S.LANDED and not now.armed else
                          f"state {st.value}, {'armed' if now.armed else 'disarmed'}" if b.navigable else
                          f"observed to the end ({st.value})")
            self.event("run_end", how=self.ended, armed=bool(now.armed), in_air=bool(now.in_air))
        b.close()

    def _await_disarm(self) -> str:
        """Landed and still armed when the run ends (our disarm at touchdown refused while the autopilot's
        land detector has not confirmed the landing, or its HEARTBEAT not showing it yet): the autopilot disarms by
        itself after touchdown (PX4 ``COM_DISARM_LAND``, 2 s; ArduCopter in LAND at touchdown), so wait for it up to
        :data:`DISARM_WAIT_S` vehicle seconds (and :data:`DISARM_WAIT_WALL_S` wall seconds) while recording state and
        odometry, then disarm it ourselves (on the ground; ``disarmed_by_us`` event). Returns how the run ended."""
        b = self.backend
        now = b.state()
        t_end, wall_end = now.t + DISARM_WAIT_S, time.monotonic() + DISARM_WAIT_WALL_S
        while now.armed and now.link_ok and not now.in_air and now.t < t_end and time.monotonic() < wall_end:
            time.sleep(0.05)
            self._record_safe_end()
            now = b.state()
        if not now.armed:
            return "landed and disarmed"
        if now.in_air or not now.link_ok:
            return f"state {self.fsm.state.value}, armed"
        try:
            b.actions.disarm()
        except Exception as e:  # noqa: BLE001 - recorded; closing goes on
            self.event("disarm_failed", error=f"{type(e).__name__}: {e}")
            return "landed, still armed (disarm refused)"
        self.event("disarmed_by_us", waited_vehicle_s=round(b.t - t_end + DISARM_WAIT_S, 1))
        self._record_safe_end()
        return "landed and disarmed (by us)"

    def _await_end_sample(self) -> None:
        """Go on recording (:meth:`_record_safe_end`) until the recorded odometry shows the vehicle's end state
        (:meth:`settled`: a position sample taken after the disarm; bounded by :data:`SETTLE_WALL_S` wall seconds).
        Each sample is recorded with the state the vehicle had when it was taken, so the one before the disarm
        still says armed."""
        self._settle_until = None  # a wait of its own (settled() may have run out while the drone was landing)
        while self.backend.state().link_ok and not self.settled():
            time.sleep(0.02)
            self._record_safe_end()

    def _record_safe_end(self) -> None:
        """While the backend's safe end runs: its events, the stat-stream (LANDING, then LANDED at the disarm) and
        each new odometry sample (at the odometry sensor's rate)."""
        b = self.backend
        for ev in b.drain_events():
            self.event(ev.pop("event", "backend_event"), **ev)
        st, now = self.fsm.state, b.state()
        if st not in (S.LANDING, S.LANDED) and now.mode in ("LAND", "RTL"):
            if self.fsm.can(S.LANDING):
                self.fsm.transition(S.LANDING, now.t)
        if self.fsm.state == S.LANDING and not now.armed and not now.in_air:
            self.fsm.transition(S.LANDED, now.t)
            self.event("landed", reason="safe end")
        self.odometry.publish(paced=True)

    def settled(self, wait_s: float = SETTLE_WALL_S) -> bool:
        """After the mission ended: True once the recorded odometry shows the vehicle's armed / in-air state as the
        backend reports it now, or ``wait_s`` wall seconds after the first call. A real vehicle reports its landed
        state (EXTENDED_SYS_STATE) and its disarm (HEARTBEAT) in other messages than its position, so the position
        sample recorded last may still say "in air"; the clock keeps stepping this drone (odometry only, no control)
        until the next position sample carries the end state. A backend without ``sample_key`` (the simulator)
        is settled at once."""
        b, o = self.backend, self.odometry.last
        if b.telemetry.sample_key is None or o is None:
            return True
        now = b.state()
        if o.get("in_air") == bool(now.in_air) and o.get("armed") == bool(now.armed):
            return True
        now = time.monotonic()
        if self._settle_until is None:
            self._settle_until = now + wait_s
        return now >= self._settle_until
