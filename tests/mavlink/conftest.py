"""The ``fly`` fixture: an emulated ArduPilot / PX4 vehicle and a connected MAVLink backend, stopped after the test."""
from __future__ import annotations

import pytest

from aerodaas.backends import make_backend
from aerodaas.backends.mavlink import MavlinkBackend
from aerodaas.config import Limits, MavlinkConfig, RobotConfig
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
from tests.mavlink.emulated import CONFIG_HOME, VEHICLE_HOME


@pytest.fixture
def fly():
    """fly(autopilot, speedup=10, emulator kwargs..., mavlink=dict of MavlinkConfig fields, limits=Limits) ->
    (emulator, backend), connected; everything is stopped after the test."""
    made: list = []

    def make(autopilot: str, speedup: float = 10.0, mavlink: dict | None = None, connect: bool = True,
             limits: Limits | None = None, **emu_kw):
        emu_kw.setdefault("home", VEHICLE_HOME)
        emu_kw.setdefault("gps_lock_s", 1.0)
        if autopilot == "px4":
            # PX4 leaves OFFBOARD after COM_OF_LOSS_T (1 s) of vehicle time without a setpoint: 100 ms of wall time
            # at 10x. Emulator and backend share this process, and on a loaded 2-core machine a thread can starve
            # for that long (measured: 118 ms at load average 8), so the tests give the stream 3 s.
            emu_kw["params"] = {"COM_OF_LOSS_T": 3.0, **emu_kw.get("params", {})}
        emu = MavlinkVehicleEmulator(autopilot, speedup=speedup, **emu_kw)
        made.append(emu)
        address = emu.start("tcp:127.0.0.1:0")
        mc = MavlinkConfig(connection=address, **{"stream_rate_hz": 5.0, **(mavlink or {})})
        backend = make_backend(RobotConfig(id="quad", backend="mavlink", home=CONFIG_HOME, mavlink=mc,
                                           **({"limits": limits} if limits is not None else {})))
        made.append(backend)
        if connect:
            backend.connect(timeout_s=10)
        return emu, backend

    yield make
    for obj in reversed(made):
        obj.close() if isinstance(obj, MavlinkBackend) else obj.stop()
