"""The embedded simulator as a vehicle backend (see :mod:`aerodaas.sim.vehicle` for the flight model)."""
from __future__ import annotations

import copy
from typing import ClassVar

from aerodaas.config.backends import SimConfig
from aerodaas.sim.gimbal import SimGimbal
from aerodaas.sim.vehicle import SimVehicle
from aerodaas.backends.base import PoseSample, StateSamples, VehicleBackend, VehicleState


class _SimSamples(StateSamples):
    """The simulator's :class:`~aerodaas.backends.base.StateSamples`: its pose sample (a camera's every frame) and its
    recorded odometry read from the vehicle directly, the values ``state()`` and ``odometry()`` would give."""

    def odometry_json(self) -> dict:
        """See :meth:`StateSamples.odometry_json`: the vehicle's own :meth:`SimVehicle.odometry_json`, unless its
        class (a plug-in's flight model) makes its odometry another way."""
        v = self._backend.vehicle
        if type(v).odometry is SimVehicle.odometry and type(v).odometry_json is SimVehicle.odometry_json:
            return v.odometry_json()
        return self.odometry().model_dump(mode="json")

    def pose_sample(self) -> PoseSample:
        v = self._backend.vehicle
        p = v.state.position
        return PoseSample(v.t, (float(p[0]), float(p[1]), float(p[2])), float(v.state.yaw))


class SimBackend(VehicleBackend):
    """Drives a :class:`~aerodaas.sim.vehicle.SimVehicle`; time moves only in :meth:`step` (simulated seconds)."""

    kind = "sim"
    clock = "sim"
    Config = SimConfig  # no settings of its own: the vehicle is the robot's limits, battery and noise
    provides_gimbal = True  # a simulated gimbal when the robot has a ``gimbal`` section (aerodaas.sim.gimbal)

    #: the flight model; a plug-in that changes how the simulated vehicle answers a command (motors that cannot
    #: lift, a landing that never starts) subclasses :class:`~aerodaas.sim.vehicle.SimVehicle` and names it here
    vehicle_class: ClassVar[type[SimVehicle]] = SimVehicle

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig
        """The simulated vehicle (:attr:`vehicle_class`), which is also the command groups :attr:`actions` and
        :attr:`guidance`, and the gimbal when the robot has a ``gimbal`` section."""
        super().__init__(cfg.id, cfg.home)
        self.vehicle = self.vehicle_class(cfg.id, cfg.home, cfg.limits, cfg.battery, cfg.noise)
        self.actions = self.guidance = self.vehicle
        #: the position samples: the simulated vehicle's odometry, with the robot's GPS and velocity noise
        self.telemetry = _SimSamples(self, odometry=self.vehicle.odometry)
        #: the camera gimbal (None: the robot has no ``gimbal`` section), starting at the first camera's mount
        self.gimbal = (SimGimbal(cfg.gimbal, -self._mount_pitch(cfg), clock=lambda: self.vehicle.t)
                       if cfg.gimbal is not None else None)

    @staticmethod
    def _mount_pitch(cfg) -> float:
        """The first camera sensor's ``pitch_deg`` (below the horizon; 90 = nadir), 90 without a camera."""
        for s in cfg.sensors:
            if "pitch_deg" in s.properties:
                return float(s.properties["pitch_deg"])
        return 90.0

    def checkpoint(self) -> dict:
        """The simulated vehicle's state, setpoint, clock and noise generator (deep copies)."""
        v = self.vehicle
        return copy.deepcopy({"state": v.state, "setpoint": v.setpoint, "t": v.t, "rng": v.noise_state,
                              "gimbal": None if self.gimbal is None else self.gimbal.state()})

    def restore(self, state: dict) -> None:
        v, s = self.vehicle, copy.deepcopy(state)
        v.state, v.setpoint, v.t = s["state"], s["setpoint"], s["t"]
        v.noise_state = s["rng"]
        if self.gimbal is not None and s.get("gimbal"):
            self.gimbal.restore(s["gimbal"])

    def step(self, dt: float) -> None:
        self.vehicle.step(dt)
        if self.gimbal is not None:
            self.gimbal.step(dt, self.vehicle.state.position, self.vehicle.state.yaw)

    @property
    def t(self) -> float:
        """Simulated seconds since the start: the vehicle's own clock, which ``state().t`` also reads (the run's
        clock asks for it several times a physics step; a whole :class:`VehicleState` each time is not needed)."""
        return self.vehicle.t

    def state(self) -> VehicleState:
        """The simulated vehicle now (exact: the odometry adds the configured noise); the link is always up."""
        v = self.vehicle
        st = v.state
        return VehicleState(t=v.t, position=st.position, velocity=st.velocity, yaw=st.yaw, armed=st.armed,
                            in_air=st.in_air, battery_pct=v.battery_pct, home=self.home)
