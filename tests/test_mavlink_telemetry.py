"""Telemetry as the vehicle reports it (issue 26 item 3): odometry is recorded once per vehicle sample, stamped
with the vehicle's own time, so speed computed from the recording matches what the vehicle flew. Read back with
the ``mcap`` package's reader."""
from __future__ import annotations

import json
import math

import pytest

from .sitl import read_recording
from .test_backends_e2e import PX4_AT_SPEED, _mavlink_variant, _run_app

STREAM_HZ = 10.0  # mavlink.stream_rate_hz: GLOBAL_POSITION_INT samples per vehicle second
ODOM_HZ = 50.0  # the odometry sensor asks for more than the vehicle sends


def window_speeds(odo: list[dict], lo_s: float = 1.0, hi_s: float = 1.3) -> list[tuple[float, float, float]]:
    """(t, speed from the recorded positions, the magnitude of the vehicle's mean reported horizontal velocity) over every window of
    ``lo_s``-``hi_s`` vehicle seconds in which the reported speed is steady (within 5 % of its mean, above 0.15 m/s: PX4 flies a 0.5 m/s limit at 0.25)."""
    out = []
    for i, a in enumerate(odo):
        for j in range(i + 1, len(odo)):
            dt = odo[j]["t"] - a["t"]
            if dt < lo_s:
                continue
            if dt <= hi_s:
                vs = [math.hypot(*o["velocity"][:2]) for o in odo[i:j + 1]]
                mean = sum(vs) / len(vs)
                if mean > 0.15 and max(vs) < 1.05 * mean and min(vs) > 0.95 * mean:
                    # the displacement over the window is the integral of the velocity vector: on a turn (a corner
                    # of the survey flown slowly) it is shorter than speed x time, so compare with the mean vector
                    vx = sum(o["velocity"][0] for o in odo[i:j + 1]) / len(vs)
                    vy = sum(o["velocity"][1] for o in odo[i:j + 1]) / len(vs)
                    p, q = a["position"], odo[j]["position"]
                    out.append((a["t"], math.hypot(q[0] - p[0], q[1] - p[1]) / dt, math.hypot(vx, vy)))
            break
    return out


@pytest.mark.e2e
@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_odometry_is_recorded_once_per_vehicle_sample(ray_session, run_options, tmp_path, flavour):
    # at 3x the vehicle's 10 Hz stream is 30 samples per wall second, well inside what the odometry sensor's
    # 50 Hz poll takes on a loaded machine (at 10x, 100 per wall second, the poll fell behind and skipped samples)
    emu, env_path = _mavlink_variant("farm_survey", flavour, 3.0, tmp_path, params=PX4_AT_SPEED[flavour],
                                     mavlink={"stream_rate_hz": STREAM_HZ})
    cfg = json.loads(env_path.read_text())
    # 2 m/s instead of the app's 0.5: the same survey in a third of the wall time, and a stamping error (a sample
    # under another's time) shows four times as far in the positions
    cfg["robots"][0]["limits"]["max_speed"] = 2.0
    for s in cfg["robots"][0]["sensors"]:
        if s["type"] == "odometry":
            s["properties"]["rate_hz"] = ODOM_HZ
        if s["type"] == "camera":
            s["properties"].update(width=160, height=120, fps=2)
    env_path.write_text(json.dumps(cfg))
    try:
        res = _run_app("farm_survey", env_path, run_options, tmp_path / "farm.mcap")
    finally:
        emu.stop()
    assert res.outcome == "success", res.robots["quadrotor_base"].get("error")
    odo = [m for _, m in read_recording(tmp_path / "farm.mcap")["/quadrotor_base/odometry"]]
    ts = [o["t"] for o in odo]
    span = ts[-1] - ts[0]
    assert span > 30 and all(b > a for a, b in zip(ts, ts[1:])), ("recorded times must strictly increase", span)
    # at most one record per vehicle sample (10 per vehicle second), though 50/s were asked for; each record a
    # sample of its own (a repeat under a new time stamp would make more)
    assert len(odo) <= STREAM_HZ * span * 1.1 + 5, (len(odo), span)
    assert len(odo) >= STREAM_HZ * span * 0.5, (len(odo), span)  # and samples are not lost either
    # the samples' times are the vehicle's: consecutive records 1/STREAM_HZ apart, mostly (a sample the drone's
    # tick missed makes a double gap, never a fraction)
    gaps = sorted(b - a for a, b in zip(ts, ts[1:]))
    assert abs(gaps[len(gaps) // 2] - 1.0 / STREAM_HZ) < 0.02, gaps[len(gaps) // 2]
    # speed from the recorded positions and times matches the vehicle's own over 1 s windows, within 5 %
    w = window_speeds(odo)
    assert len(w) > 20, len(w)
    bad = [(round(t, 1), round(f, 3), round(v, 3)) for t, f, v in w if abs(f / v - 1.0) > 0.05]
    # a stamping error (a repeat, a sample under the wrong time) is systematic and shows in many windows; a loaded
    # 2-core machine delays the emulated vehicle's own samples now and then (2-3 windows of ~1000 at 6-9 % seen at
    # 0.5 m/s with the parallel test partitions running; a few hundred windows at 2 m/s): at most 1 % of the windows,
    # none beyond 15 %
    assert len(bad) <= max(1, len(w) // 100) and all(abs(f / v - 1.0) <= 0.15 for _, f, v in bad), \
        (len(bad), len(w), bad[:10])
