"""The autopilot's per-step logic: auto-disarm, the targets' timeouts, PX4's offboard-loss failsafe, take-off
completion, and the RTL or the mission being flown."""
from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.arming import Arming
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.mission_run import MissionRunner
from aerodaas.emulators.mavlink.modes import FlightModes
from aerodaas.emulators.mavlink.motion import Motion
from aerodaas.emulators.mavlink.state import EmulatorState, MissionStore

M = mavlink

__all__ = ["AutopilotLoop"]


class AutopilotLoop:
    """What the firmware does by itself every physics step over ``state``: disarms with ``arming``, tracks and
    times out targets with ``motion``, falls back and completes take-offs through ``modes``, flies the RTL
    (``modes``) or the mission (``runner``, the ``store``'s run state), telling the ground stations on ``link``. Not
    locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState, store: MissionStore, link: EmulatorLink, arming: Arming,
                 modes: FlightModes, motion: Motion, runner: MissionRunner) -> None:
        self.state, self.store, self.link = state, store, link
        self.arming, self.modes, self.motion, self.runner = arming, modes, motion, runner

    def _climbing(self) -> bool:
        return self.state.takeoff_alt is not None or self.store.run_state == "running"

    def _auto_disarm(self) -> None:
        """On the ground: disarm ``COM_DISARM_PRFLT`` / ``DISARM_DELAY`` s after arming without a take-off, and
        after landing (PX4 ``COM_DISARM_LAND``, -1 disables it; ArduCopter 1 s)."""
        st = self.state
        s = st.veh.state
        if not (s.armed and not s.in_air):
            return
        delay = st.params["COM_DISARM_PRFLT" if st.px4 else "DISARM_DELAY"]
        if not st.took_off and delay > 0 and st.t - st.armed_at > delay and not self._climbing():
            self.arming.disarm("auto disarm (no take-off)")
        elif st.took_off and st.landed_at is not None:
            after = st.params["COM_DISARM_LAND"] if st.px4 else 1.0
            if after >= 0 and st.t - st.landed_at > after:  # PX4: COM_DISARM_LAND -1 disables it
                mode = st.mode
                self.arming.disarm("landed")
                if st.px4 and mode in ("AUTO.RTL", "AUTO.LAND"):
                    self.modes.enter("AUTO.LOITER")  # PX4 SIH shows Hold once disarmed after an RTL/LAND (trace)

    def step(self) -> None:
        """One physics step of the firmware's own logic (after the flight model moved)."""
        st = self.state
        s = st.veh.state
        mode = st.mode
        self._auto_disarm()
        if st.posvel is not None:
            if mode in ("GUIDED", "OFFBOARD") and s.armed and s.in_air:
                self.motion.track_posvel()
            else:
                st.posvel = None
        # ArduPilot GUIDED velocity targets time out after 3 s
        if st.velocity_deadline is not None and st.t > st.velocity_deadline:
            st.velocity_deadline = None
            if s.in_air:
                st.veh.hold()
        # PX4 offboard loss: a mode fallback (commander/failsafe/failsafe.cpp checkModeFallback, COM_OBL_RC_ACT).
        # With the default parameters and no RC, PX4 SITL returns (AUTO.RTL; firmware trace of 2026-11-24). The
        # pilot's mode stays OFFBOARD: when setpoints come again the fallback ends (modes.offboard_signal_back)
        if st.px4 and mode == "OFFBOARD" and st.t - st.last_setpoint_t > st.params["COM_OF_LOSS_T"]:
            self.link.text(M.MAV_SEVERITY_WARNING, "Failsafe activated: offboard control lost, returning")
            self.modes.enter("AUTO.RTL")
            st.offboard_fallback = "AUTO.RTL"
        # take-off completion
        if st.takeoff_alt is not None and s.armed:
            if abs(st.rel()[2] - st.takeoff_alt) < 0.1:
                st.takeoff_alt = None
                if st.px4 and mode == "AUTO.TAKEOFF":
                    self.modes.enter("AUTO.LOITER")
        if mode in ("RTL", "AUTO.RTL") or (mode in ("AUTO", "AUTO.MISSION") and st.phase):
            self.modes.rtl_step()
        elif mode in ("AUTO", "AUTO.MISSION"):
            self.runner.step()
