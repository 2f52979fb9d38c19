"""A simulated drone's odometry as recorded: every ``/<robot>/odometry`` message of the MCAP is exactly the bytes of
the validated :class:`~aerodaas.model.types.Odometry` model's JSON dump (the drone builds the sample's dict without
the model; the recording must not tell). A drone actor's host built in this process (no Ray), recorded to a file,
read back with the MCAP reader."""
from __future__ import annotations

import json

from mcap.reader import make_reader

from aerodaas import Environment
from aerodaas.config import parse_environment_config
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Odometry, Waypoint
from aerodaas.schedulers import TrajectoryScheduler

from tests.runtime.test_dataplane import _host_for


def _flying_env() -> Environment:
    """One simulated drone without a camera, GPS and velocity noise on, flying a square."""
    from aerodaas.bench.fleet import fleet_config

    cfg = fleet_config(1, camera=False)
    cfg["robots"][0]["noise"] = {"gps_std_m": 0.3, "velocity_std_mps": 0.05, "seed": 7}
    cfg["robots"][0]["takeoff_altitude"] = 1.0
    env = Environment(parse_environment_config(cfg))
    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)
    wps = [Waypoint(id=f"w{k}", x=[0, 3, 3, 0][k % 4], y=[0, 0, 3, 3][k % 4], z=1.0) for k in range(8)]
    env.get_robot_by_id("d00").navigate(sched.generate_navigation(
        AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.ORDERED)))
    return env


def test_recorded_odometry_is_the_models_json_byte_for_byte(tmp_path):
    path = tmp_path / "run.mcap"
    _host, rt, _plan = _host_for(_flying_env(), record=str(path))
    try:
        rt.run(timeout_s=4.0)
    finally:
        rt.close()  # the data plane's pool, then the recorder finishes the file
    with open(path, "rb") as f:
        msgs = [(ch.message_encoding, sc.name, m.data)
                for sc, ch, m in make_reader(f).iter_messages(topics=["/d00/odometry"])]
    assert len(msgs) >= 20, len(msgs)  # 10 Hz for the flight's simulated seconds
    moving = 0
    for enc, schema, data in msgs:
        assert (enc, schema) == ("json", "aerodaas.Odometry")
        model = Odometry.model_validate(json.loads(data))
        assert data == json.dumps(model.model_dump(mode="json"), allow_nan=False, separators=(",", ":")).encode()
        moving += model.in_air and abs(model.velocity[0]) + abs(model.velocity[1]) > 0.5
    assert moving >= 1  # samples of the flight itself, not only of the drone on the ground
