"""The drone actor's clock outside lock-step: it wakes for the physics steps with something due (a control tick,
a camera frame, an odometry sample), not for every step, and computes nothing before its wall time. Built in
this process (no Ray); the counts are of simulated steps, not of wall time."""
from __future__ import annotations

import pytest

from tests.runtime.test_dataplane import FrameProbe, _env, _host_for


@pytest.fixture
def wakes(monkeypatch):
    """Every wall time the clock slept until, in order (the real sleep still happens)."""
    from aerodaas.actors.host import assembly

    seen: list[float] = []
    real = assembly._sleep_until

    def record(wall: float) -> float:
        seen.append(wall)
        return real(wall)

    monkeypatch.setattr(assembly, "_sleep_until", record)
    return seen


def _run(seconds: float):
    env = _env(1, fps=15.0)
    FrameProbe().analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())  # the camera renders
    host, rt, _plan = _host_for(env)
    try:
        reports = rt.run(timeout_s=seconds)
    finally:
        host.close()
    return rt, reports["d00"]


def test_the_clock_wakes_for_due_work_not_for_every_physics_step(wakes):
    """50 Hz physics, control and odometry at 10 Hz, a camera at 15 Hz: the due times fall on 20 of the 50 steps of
    a simulated second (0, 1/15, 0.1, 2/15, 0.2, ... : 10 + 15 - 5 shared), so the clock wakes about 20 times a
    second (plus the end of the run), and every control tick still runs."""
    rt, rep = _run(2.0)
    sim_s = rep["ticks"] / 10.0  # ten control ticks per simulated second
    frames = rt.stats()["d00/cam"]["ticks"]
    assert rep["ticks"] >= 15 and frames >= 1.5 * rep["ticks"] - 2, (rep["ticks"], frames)  # 15 frames per 10 ticks
    assert len(wakes) <= 21 * sim_s + 2, (len(wakes), sim_s)
    assert len(wakes) >= 19 * sim_s - 2, (len(wakes), sim_s)  # still a wake per due frame and tick


def test_no_control_tick_runs_before_its_wall_time(wakes):
    """Each control tick's lateness (its wall time minus its due wall time) is never negative: the steps a wake
    computes are the ones whose wall time has come."""
    rt, rep = _run(1.5)
    assert len(rt.tick_lateness) == rep["ticks"] - 1 or len(rt.tick_lateness) >= 10, (rt.tick_lateness, rep)
    assert min(rt.tick_lateness) >= 0.0, rt.tick_lateness
    assert wakes == sorted(wakes)
