"""``aerodaas plot``: figures from synthetic recordings (no Ray): files written and valid, data extraction exact,
latency figure skipped without a latency channel, unfinished recordings, CLI exit codes."""
from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest

from aerodaas.cli import main
from aerodaas.tools.plot import plot_run
from aerodaas.tools.plot_data import load_plot_data, planned_and_flown, tracking_segments
from aerodaas.recording.writer import McapRecorder

T0 = 1_700_000_000_000_000_000  # ns
R = "r1"


def _ns(t: float) -> int:
    return T0 + int(round(t * 1e9))


def _odom(robot: str, t: float, pos: tuple[float, float, float], battery: float) -> dict:
    return {"robot_id": robot, "t": t, "position": list(pos), "geodetic": {"lat": 47.0, "lon": 8.0, "alt": 400.0},
            "velocity": [0.0, 0.0, 0.0], "attitude": {"roll": 0.0, "pitch": 0.0, "yaw": 90.0},
            "battery_pct": battery, "battery_voltage": 16.0, "armed": True, "in_air": pos[2] > 0}


def _write_run(rec: McapRecorder, robot: str = R, *, plan: bool = True, latency: bool = True,
               targets: bool = True) -> None:
    """A 10 s flight: take off at (0, 0), commanded B=(10, 0, 5) then A=(0, 10, 5); C=(10, 10, 5) is planned but
    never commanded; TRACKING from t=4 s to t=6 s. Odometry at 1 Hz, position (t, 0.5 t, z), battery 100 - t."""
    states = [(0.0, "PREFLIGHT"), (0.0, "ARMED"), (0.0, "TAKING_OFF"), (1.0, "NAVIGATING"), (3.0, "WAYPOINT_HOLD"),
              (4.0, "TRACKING"), (6.0, "NAVIGATING"), (8.0, "LANDING"), (10.0, "LANDED")]
    prev = "IDLE"
    for t, s in states:
        rec.write_json("/mission/state", _ns(t), {"robot": robot, "state": s, "previous": prev, "t": t},
                       schema_name="aerodaas.MissionState")
        prev = s
    if plan:
        items = [{"id": "A", "x": 0, "y": 10, "z": 5, "local": [0.0, 10.0, 5.0]},
                 {"id": "B", "x": 10, "y": 0, "z": 5, "local": [10.0, 0.0, 5.0]},
                 {"id": "C", "x": 10, "y": 10, "z": 5, "local": [10.0, 10.0, 5.0]}]
        rec.write_json(f"/{robot}/mission/plan", _ns(0.0),
                       {"robot": robot, "t": 0.0, "missions": [{"name": "survey", "priority": 2, "items": items}]},
                       schema_name="aerodaas.MissionPlan")
        # the queue changes: a follow mission (velocity commands, no waypoint) preempts; B is done
        rec.write_json(f"/{robot}/mission/plan", _ns(4.0),
                       {"robot": robot, "t": 4.0, "missions": [
                           {"name": "follow", "priority": 1, "items": [{"id": "f-1", "vx": 1.0, "vy": 0.0}]},
                           {"name": "survey", "priority": 2, "items": items[::2]}]},
                       schema_name="aerodaas.MissionPlan")
    rec.write_json(f"/{robot}/nav/command", _ns(1.0),
                   {"kind": "waypoint", "waypoint": {"id": "B", "x": 10.0, "y": 0.0, "z": 5.0}, "local": [10, 0, 5],
                    "priority": 2}, schema_name="aerodaas.NavCommand")
    rec.write_json(f"/{robot}/events", _ns(0.0), {"robot": robot, "t": 0.0, "event": "takeoff", "altitude": 5.0},
                   schema_name="aerodaas.MissionEvent")
    rec.write_json(f"/{robot}/events", _ns(1.0), {"robot": robot, "t": 1.0, "event": "navigate", "waypoint": "B",
                                                   "target": [10, 0, 5], "priority": 2, "mission": "survey"},
                   schema_name="aerodaas.MissionEvent")
    rec.write_json(f"/{robot}/events", _ns(3.0), {"robot": robot, "t": 3.0, "event": "waypoint_reached",
                                                   "waypoint": "B", "error_m": 0.2},
                   schema_name="aerodaas.MissionEvent")
    # A only appears as a navigate event (no nav/command message): still commanded, second
    rec.write_json(f"/{robot}/events", _ns(6.0), {"robot": robot, "t": 6.0, "event": "navigate", "waypoint": "A",
                                                   "target": [0, 10, 5], "priority": 2, "mission": "survey"},
                   schema_name="aerodaas.MissionEvent")
    for i in range(11):
        t = float(i)
        rec.write_json(f"/{robot}/odometry", _ns(t), _odom(robot, t, (t, 0.5 * t, min(t, 5.0)), 100.0 - t),
                       schema_name="aerodaas.Odometry")
        rec.write_pose(f"/{robot}/pose", _ns(t), (t, 0.5 * t, min(t, 5.0)), 90.0)
        if targets:
            rec.write_json("/world/targets", _ns(t), {"robot": robot, "seq": i, "t": t, "targets": [
                {"id": "car1", "class_name": "car", "x": 2.0 * t, "y": -3.0, "present": 2 <= t <= 8}]},
                schema_name="aerodaas.GroundTruth")
    if latency:
        rng = np.random.default_rng(0)
        for k in range(40):
            t = 4.0 + k * 0.05
            inf, post = 10.0 + rng.normal(0, 1), 2.0 + abs(rng.normal(0, 0.3))
            e2e = inf + post + 5.0 + abs(rng.normal(0, 1))
            rec.write_json(f"/{robot}/latency", _ns(t), {"robot": robot, "t": t, "e2e_ms": e2e, "inference_ms": inf,
                                                          "post_ms": post, "overhead_ms": e2e - inf - post},
                           schema_name="aerodaas.FrameLatency")
    rec.write_json("/mission/result", _ns(10.0), {"robot": robot, "outcome": "success"},
                   schema_name="aerodaas.MissionResult")


@pytest.fixture
def run_file(tmp_path):
    path = tmp_path / "run.mcap"
    with McapRecorder(path, chunk_size=4096) as rec:
        _write_run(rec)
    return path


def _check_png(path, min_w=300, min_h=200):
    assert path.is_file() and path.suffix == ".png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = cv2.imread(str(path))
    assert img is not None, path
    h, w = img.shape[:2]
    assert w >= min_w and h >= min_h, (path, img.shape)
    assert img.std() > 5  # not a blank canvas


def test_plot_run_writes_all_figures(run_file, tmp_path):
    out = tmp_path / "figs"
    written = plot_run(run_file, out)
    assert set(written) == {"trajectory", "battery_altitude", "latency"}
    for stem, p in written.items():
        assert p == out / f"{stem}.png"
        _check_png(p)


def test_extraction_gets_planned_and_flown_right(run_file):
    data = load_plot_data(run_file)
    assert list(data.robots) == [R] and data.finished
    r = data.robots[R]
    ids, planned, flown = planned_and_flown(data)
    # numbered in commanded order (B at 1 s via nav/command, A at 6 s via a navigate event), C never commanded
    assert ids == ["B", "A", "C"]
    assert [w.order for w in r.planned] == [1, 2, None]
    assert [w.reached for w in r.planned] == [True, False, False]
    assert r.plan_source == "plan"
    np.testing.assert_allclose(planned, [[10, 0, 5], [0, 10, 5], [10, 10, 5]])
    t = np.arange(11.0)
    np.testing.assert_allclose(r.t, t)  # s since the first message
    np.testing.assert_allclose(flown, np.c_[t, 0.5 * t, np.minimum(t, 5.0)])
    np.testing.assert_allclose(r.battery_pct, 100.0 - t)
    # TRACKING from 4 s to 6 s: the segments starting at t = 4 and 5
    np.testing.assert_array_equal(np.flatnonzero(tracking_segments(r)), [4, 5])
    assert r.states[-1] == (10.0, "LANDED") and r.outcome == "success"
    assert set(r.latency) == {"e2e_ms", "inference_ms", "post_ms", "overhead_ms"} and r.latency["e2e_ms"].size == 40
    np.testing.assert_allclose(r.latency["e2e_ms"],
                               r.latency["inference_ms"] + r.latency["post_ms"] + r.latency["overhead_ms"])
    car = data.targets["car1"]
    assert car.class_name == "car"
    present = np.isfinite(car.xy[:, 0])
    np.testing.assert_array_equal(np.flatnonzero(present), [2, 3, 4, 5, 6, 7, 8])
    np.testing.assert_allclose(car.xy[present], np.c_[2.0 * t[present], np.full(7, -3.0)])


def test_planned_falls_back_to_nav_commands_without_plan_channel(tmp_path):
    path = tmp_path / "noplan.mcap"
    with McapRecorder(path) as rec:
        _write_run(rec, plan=False)
    ids, planned, _flown = planned_and_flown(path)
    assert ids == ["B", "A"]
    np.testing.assert_allclose(planned, [[10, 0, 5], [0, 10, 5]])
    assert load_plot_data(path).robots[R].plan_source == "commands"


def test_latency_figure_skipped_without_latency_channel(tmp_path, capsys):
    path = tmp_path / "nolat.mcap"
    with McapRecorder(path) as rec:
        _write_run(rec, latency=False, targets=False)
    out = tmp_path / "o"
    written = plot_run(path, out)
    assert set(written) == {"trajectory", "battery_altitude"}
    assert not (out / "latency.png").exists()
    assert "no per-frame latency channel" in capsys.readouterr().err
    for p in written.values():
        _check_png(p)


def test_unfinished_recording_plots_what_is_readable(tmp_path):
    live = tmp_path / "live.mcap"
    rec = McapRecorder(live, chunk_size=1024)
    try:
        _write_run(rec, latency=False, targets=False)
        rec.flush()
        crashed = tmp_path / "crashed.mcap"
        shutil.copyfile(live, crashed)  # what a crash leaves on disk: no summary, no footer
    finally:
        rec.close()
    with open(crashed, "ab") as f:
        f.write(b"\x06\x40\x00\x00")  # plus the torn start of a chunk that never completed
    notes: list[str] = []
    data = load_plot_data(crashed)
    assert not data.finished
    assert len(data.robots[R].t) == 11
    written = plot_run(crashed, tmp_path / "c", note=notes.append)
    assert set(written) == {"trajectory", "battery_altitude"}
    assert any("unfinished" in n for n in notes)
    _check_png(written["trajectory"])


def test_several_robots_get_suffixed_files(tmp_path):
    path = tmp_path / "two.mcap"
    with McapRecorder(path) as rec:
        _write_run(rec, "r1", latency=False, targets=False)
        _write_run(rec, "r2", plan=False, latency=False, targets=False)
    written = plot_run(path, tmp_path / "two", note=lambda _m: None)
    assert set(written) == {"trajectory_r1", "battery_altitude_r1", "trajectory_r2", "battery_altitude_r2"}


def test_cli_plot(run_file, tmp_path, capsys):
    assert main(["plot", str(run_file)]) == 0  # default folder: <stem>_plots next to the recording
    printed = capsys.readouterr().out.split()
    default = run_file.parent / "run_plots"
    assert sorted(printed) == sorted(str(default / f"{s}.png") for s in ("trajectory", "battery_altitude", "latency"))
    assert main(["plot", str(tmp_path / "missing.mcap")]) == 2
    assert "not found" in capsys.readouterr().err
    bogus = tmp_path / "bogus.mcap"
    bogus.write_bytes(b"not an mcap file at all")
    assert main(["plot", str(bogus), "--out", str(tmp_path / "x")]) == 2
    assert "not an MCAP file" in capsys.readouterr().err
    assert main(["plot", str(tmp_path)]) == 2
