"""The bad-input and fault catalogue, and the command that measures it: ``python -m aerodaas.reliability --out
docs/reliability.md``.

Each input case is something a hostile or unlucky user gives AeroDaaS (an environment file, a command-line flag, a
record path, a mission file, a HITL request); each must be refused before Ray starts with an error naming the field
(:mod:`aerodaas.reliability.cli_cases` also holds applications whose own code raises: exit 1 with the app's
traceback, never "bad input"; :mod:`aerodaas.reliability.hitl_probe` the HITL API's answers). Each fault
case (in :mod:`aerodaas.reliability.faults`) injects a failure into a real run and checks that it ends cleanly.
The tests (``tests/inputs/test_bad_input.py``, ``tests/runtime/test_faults.py``, marker ``faults``) run the same cases, so the
table and the suite cannot drift apart.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import math
import os
import random
import struct
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from aerodaas.config import ConfigError, parse_environment_config
from aerodaas.recording.record_path import check_record_path
from aerodaas.recording.writer import McapRecorder
from aerodaas.reliability.app_cases import run_app_cases
from aerodaas.reliability.cli_cases import base_env, run_cli_cases
from aerodaas.reliability.faults import render, run_faults
from aerodaas.reliability.file_cases import run_file_cases
from aerodaas.reliability.flight import Excursion, fly_commands, random_commands
from aerodaas.reliability.hitl_probe import run_hitl_cases
from aerodaas.reliability.input_report import guarded, summarize

__all__ = ["InputCase", "ENV_CASES", "PATH_CASES", "base_env", "check_env_case", "check_path_case", "main"]


@dataclass(frozen=True)
class InputCase:
    """``name``; ``mutate(env, tmp)`` edits a copy of :func:`base_env` (``tmp``: a scratch folder for files);
    ``expect``: text the error must contain (the field it names); ``category``: the report's group (ids, strict
    types, bounds / cross-field, ...)."""

    name: str
    mutate: Callable[[dict, Path], None]
    expect: str
    category: str = ""


def _category(category: str, cases: list[InputCase]) -> list[InputCase]:
    return [dataclasses.replace(c, category=category) for c in cases]


def _robot(d: dict) -> dict:
    return d["robots"][0]


def _cam(d: dict) -> dict:
    return _robot(d)["sensors"][0].setdefault("properties", {})


def _png(tmp: Path, w: int = 64, h: int = 48) -> str:
    import cv2  # lazy: heavy dependency (OpenCV)

    p = tmp / f"img_{w}x{h}.png"
    cv2.imwrite(str(p), np.full((h, w, 3), 128, np.uint8))
    return str(p)


def _png_bomb(tmp: Path, w: int = 100_000, h: int = 100_000) -> str:
    """A PNG "decompression bomb": a valid 8-bit grey PNG whose header declares ``w`` x ``h`` pixels (10 GB decoded)
    in a file of a few hundred bytes (its data holds the first rows only: the header alone must refuse it)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    p = tmp / f"bomb_{w}x{h}.png"
    p.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                  + chunk(b"IDAT", zlib.compress(b"\0" * (w + 1) * 4, 9)) + chunk(b"IEND", b""))
    return str(p)


def _tlog_without_position(tmp: Path) -> str:
    """A MAVLink telemetry log holding only autopilot HEARTBEATs (written with pymavlink): nothing to replay."""
    p = tmp / "heartbeats.tlog"
    link = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    with open(p, "wb") as f:
        for i in range(5):
            msg = mav.MAVLink_heartbeat_message(2, 3, 81, 4, 3, 3)  # quadrotor, ArduPilot, armed GUIDED, active
            f.write(struct.pack(">Q", 1_700_000_000_000_000 + i * 1_000_000) + msg.pack(link))
    return str(p)


def _replay_camera(tmp: Path, recording: bool) -> dict:
    """A camera replaying ``source: mcap``: a text file named ``.mcap`` (``recording`` False), or a recording of
    ours whose only camera channel is another robot's (its own topic absent)."""
    p = tmp / ("other.mcap" if recording else "notes.mcap")
    if recording:
        with McapRecorder(p) as rec:
            rec.write_image("/other/camera/cam", 1, np.zeros((8, 8, 3), np.uint8))
    else:
        p.write_text("field notes, not a recording")
    return {"source": "mcap", "mcap": str(p)}


def _target(tmp: Path, tid: str = "car", crop=(0, 0, 10, 10)) -> dict:
    return {"id": tid, "image": _png(tmp), "crop": list(crop), "path": [{"t": 0, "x": 0, "y": 0}, {"t": 5, "x": 5, "y": 0}]}


INF, BIG = float("inf"), 1e308
_FAR_FENCE = {"circles": [{"center": [47.5, 8.6], "radius": 50, "inclusion": True}]}
#: two overlapping inclusion circles, both holding the catalogue's home
_TWO_CIRCLES = {"circles": [{"center": [47.3977, 8.5456], "radius": 50, "inclusion": True},
                            {"center": [47.3980, 8.5456], "radius": 50, "inclusion": True}]}

#: environment files that must be refused (ConfigError naming the field) before anything starts
#: environment cases of category 'ids'
ID_CASES: list[InputCase] = _category('ids', [
    InputCase("duplicate robot ids", lambda d, t: d["robots"].append({"id": "d1"}), "duplicate ids"),
    InputCase("duplicate sensor ids", lambda d, t: _robot(d)["sensors"].append({"id": "cam", "type": "odometry"}),
              "sensors: duplicate ids"),
    InputCase("robot id with a newline", lambda d, t: _robot(d).update(id="d1\n"), "robots.0.id"),
    InputCase("robot id with NUL", lambda d, t: _robot(d).update(id="d\x001"), "robots.0.id"),
    InputCase("robot id with a right-to-left override", lambda d, t: _robot(d).update(id="d\u202e1"), "U+202E"),
    InputCase("robot id with a zero-width space", lambda d, t: _robot(d).update(id="d\u200b1"), "U+200B"),
    InputCase("robot id with a trailing blank", lambda d, t: _robot(d).update(id="d1 "), "robots.0.id"),
    InputCase("robot id 'a/camera' (a topic separator)", lambda d, t: _robot(d).update(id="a/camera"), "robots.0.id"),
    InputCase("robot id NFD 'cafe\u0301'", lambda d, t: _robot(d).update(id="cafe\u0301"), "robots.0.id"),
    InputCase("robot ids 'd1' and 'D1'", lambda d, t: d["robots"].append({"id": "D1"}), "but for case"),
    InputCase("robot id 'mission' (a top-level topic)", lambda d, t: _robot(d).update(id="mission"), "top-level topic"),
    InputCase("camera id 'camera/X'", lambda d, t: _robot(d)["sensors"][0].update(id="camera/X"),
              "robots.0.sensors.0.id"),
    InputCase("compute id with a blank", lambda d, t: d.update(compute=[{"id": "edge 1", "tier": "edge"}]),
              "compute.0.id"),
    InputCase("robot id of 65 characters", lambda d, t: _robot(d).update(id="d" * 65), "longer than 64"),
    InputCase("duplicate target ids", lambda d, t: d.update(world={"targets": [_target(t), _target(t)]}),
              "world.targets: duplicate ids"),
])

#: environment cases of category 'strict types'
STRICT_TYPE_CASES: list[InputCase] = _category('strict types', [
    InputCase("limits.max_speed \"3\" (string)", lambda d, t: _robot(d).update(limits={"max_speed": "3"}), "max_speed"),
    InputCase("limits.max_speed true", lambda d, t: _robot(d).update(limits={"max_speed": True}), "max_speed"),
    InputCase("simulation.lockstep \"yes\"", lambda d, t: d.update(simulation={"lockstep": "yes"}), "lockstep"),
    InputCase("simulation.lockstep 1", lambda d, t: d.update(simulation={"lockstep": 1}), "lockstep"),
    InputCase("camera width 640.5", lambda d, t: _cam(d).update(width=640.5), "width"),
    InputCase("fence inclusion \"yes\"",
              lambda d, t: _robot(d).update(safety={"geofence": {"circles": [
                  {"center": [47.3977, 8.5456], "radius": 50, "inclusion": "yes"}]}}), "inclusion"),
    InputCase("hitl.enabled \"true\" (string)", lambda d, t: d.update(hitl={"enabled": "true"}), "hitl.enabled"),
    # strict numbers everywhere (a JSON string or boolean is never a number)
    InputCase("home.lat \"13.02\" (string)", lambda d, t: _robot(d).update(home={"lat": "13.02", "lon": 8.0}), "home.lat"),
    InputCase("battery.capacity_wh \"60\" (string)", lambda d, t: _robot(d).update(battery={"capacity_wh": "60"}),
              "capacity_wh"),
    InputCase("takeoff_altitude true", lambda d, t: _robot(d).update(takeoff_altitude=True), "takeoff_altitude"),
    InputCase("control_rate_hz \"10\" (string)", lambda d, t: _robot(d).update(control_rate_hz="10"), "control_rate_hz"),
    InputCase("sensor buffer \"2\" (string)", lambda d, t: _robot(d)["sensors"][1].update(buffer="2"), "buffer"),
    InputCase("max_queued_items 10.5 (not an integer)", lambda d, t: _robot(d).update(max_queued_items=10.5),
              "max_queued_items"),
    InputCase("world.ground.home_px [\"10\", 10]",
              lambda d, t: d.update(world={"ground": {"image": _png(t), "home_px": ["10", 10]}}), "home_px"),
])

#: environment cases of category 'bounds / cross-field'
BOUND_CASES: list[InputCase] = _category('bounds / cross-field', [
    InputCase("limits.max_speed Infinity", lambda d, t: _robot(d).update(limits={"max_speed": INF}), "max_speed"),
    InputCase("limits.max_speed 1e308", lambda d, t: _robot(d).update(limits={"max_speed": BIG}), "max_speed"),
    InputCase("limits.max_speed NaN", lambda d, t: _robot(d).update(limits={"max_speed": math.nan}), "max_speed"),
    InputCase("limits.max_altitude -5", lambda d, t: _robot(d).update(limits={"max_altitude": -5}), "max_altitude"),
    InputCase("home.alt Infinity", lambda d, t: _robot(d).update(home={"lat": 47.0, "lon": 8.0, "alt": INF}), "home.alt"),
    InputCase("home.alt 1e308", lambda d, t: _robot(d).update(home={"lat": 47.0, "lon": 8.0, "alt": BIG}), "home.alt"),
    InputCase("home.lat 95", lambda d, t: _robot(d).update(home={"lat": 95.0, "lon": 8.0}), "home.lat"),
    InputCase("simulation.speedup 1e308", lambda d, t: d.update(simulation={"speedup": BIG}), "simulation.speedup"),
    InputCase("simulation.speedup Infinity", lambda d, t: d.update(simulation={"speedup": INF}), "simulation.speedup"),
    InputCase("simulation.physics_hz 0", lambda d, t: d.update(simulation={"physics_hz": 0}), "physics_hz"),
    InputCase("camera fps 1e308", lambda d, t: _cam(d).update(fps=BIG), "fps"),
    InputCase("camera fps Infinity", lambda d, t: _cam(d).update(fps=INF), "fps"),
    InputCase("camera 100000 x 100000", lambda d, t: _cam(d).update(width=100000, height=100000), "width"),
    InputCase("camera hfov_deg 200", lambda d, t: _cam(d).update(hfov_deg=200), "hfov_deg"),
    InputCase("odometry rate_hz 0", lambda d, t: _robot(d)["sensors"][1].update(properties={"rate_hz": 0}), "rate_hz"),
    InputCase("takeoff_altitude 16 above max_altitude 10 (clamp)",
              lambda d, t: _robot(d).update(takeoff_altitude=16, safety={"max_altitude": 10, "on_violation": "clamp"}),
              "takeoff_altitude"),
    InputCase("takeoff_altitude below min_altitude", lambda d, t: _robot(d).update(takeoff_altitude=1, safety={"min_altitude": 3}),
              "takeoff_altitude"),
    InputCase("min_altitude >= max_altitude", lambda d, t: _robot(d).update(safety={"min_altitude": 20, "max_altitude": 10}),
              "min_altitude"),
    InputCase("safety.command_latency_s -1", lambda d, t: _robot(d).update(safety={"command_latency_s": -1}),
              "command_latency_s"),
    InputCase("battery initial_pct 150", lambda d, t: _robot(d).update(battery={"initial_pct": 150}), "initial_pct"),
    InputCase("simulation.physics_hz 1 (the gate's model needs >= 10)", lambda d, t: d.update(simulation={"physics_hz": 1}),
              "physics_hz"),
    InputCase("simulation.physics_hz 1e-6", lambda d, t: d.update(simulation={"physics_hz": 1e-6}), "physics_hz"),
    InputCase("simulation.speedup 1e-300", lambda d, t: d.update(simulation={"speedup": 1e-300}), "speedup"),
    InputCase("simulation.speedup 1e-9", lambda d, t: d.update(simulation={"speedup": 1e-9}), "speedup"),
    InputCase("ground 100 km at 1 mm/px", lambda d, t: d.update(world={"ground": {"size_m": 100000,
                                                                                  "metres_per_pixel": 0.001}}),
              "metres_per_pixel"),
    InputCase("world.ground.seed -1", lambda d, t: d.update(world={"ground": {"seed": -1}}), "seed"),
    InputCase("noise.seed -1", lambda d, t: _robot(d).update(noise={"seed": -1}), "seed"),
    InputCase("safety.max_distance 200 km", lambda d, t: _robot(d).update(safety={"max_distance": 2e5}),
              "max_distance"),
    InputCase("mavlink.setpoint_rate_hz 1e308",
              lambda d, t: _robot(d).update(backend="mavlink", mavlink={"setpoint_rate_hz": BIG}), "setpoint_rate_hz"),
    InputCase("mavlink.connection \"tcp:999.1.1.1:99999\" (refused by the drone actor, after Ray)",
              lambda d, t: _robot(d).update(backend="mavlink", mavlink={"connection": "tcp:999.1.1.1:99999"}),
              "mavlink.connection"),
    # every rate, size and duration bounded, the cross-field rules
    InputCase("control_rate_hz 1e-6", lambda d, t: _robot(d).update(control_rate_hz=1e-6), "control_rate_hz"),
    InputCase("limits.max_yaw_rate 1e308", lambda d, t: _robot(d).update(limits={"max_yaw_rate": BIG}), "max_yaw_rate"),
    InputCase("idle_land_s 1e308", lambda d, t: _robot(d).update(idle_land_s=BIG), "idle_land_s"),
    InputCase("sensor buffer 10^15", lambda d, t: _robot(d)["sensors"][1].update(buffer=10**15), "buffer"),
    InputCase("battery voltage_empty 17 above voltage_full 16.8",
              lambda d, t: _robot(d).update(battery={"voltage_empty": 17.0, "voltage_full": 16.8}), "voltage_empty"),
    InputCase("battery start 4 % below critical_battery_pct 5 %",
              lambda d, t: _robot(d).update(battery={"initial_pct": 4}), "battery.initial_pct"),
    InputCase("battery start 20 % at low_battery_rtl_pct 20 %",
              lambda d, t: _robot(d).update(battery={"initial_pct": 20}), "battery.initial_pct"),
    InputCase("world.ground.home_px [1e300, -1e300]",
              lambda d, t: d.update(world={"ground": {"image": _png(t), "home_px": [1e300, -1e300]}}), "home_px"),
    InputCase("1,001 robots", lambda d, t: d.update(robots=[{"id": f"d{i}"} for i in range(1001)]), "robots"),
    InputCase("a fence of 1,001 circles",
              lambda d, t: _robot(d).update(safety={"geofence": {"circles": [
                  {"center": [47.3977, 8.5456], "radius": 50 + i, "inclusion": True} for i in range(1001)]}}),
              "circles"),
    InputCase("world.ground.home_px without an image", lambda d, t: d.update(world={"ground": {"home_px": [1, 1]}}),
              "home_px"),
])

#: environment cases of category 'unknown keys'
KEY_CASES: list[InputCase] = _category('unknown keys', [
    InputCase("camera property typo 'widht'", lambda d, t: _cam(d).update(widht=640), "did you mean 'width'"),
    InputCase("unknown root key 'robot'", lambda d, t: d.update(robot=[]), "did you mean 'robots'"),
    InputCase("unknown key limits.max_sped", lambda d, t: _robot(d).update(limits={"max_sped": 3}),
              "did you mean 'max_speed'"),
    InputCase("unknown key safety.geofence.circle", lambda d, t: _robot(d).update(safety={"geofence": {"circle": []}}),
              "did you mean 'circles'"),
])

#: environment cases of category 'geofence'
GEOFENCE_CASES: list[InputCase] = _category('geofence', [
    InputCase("inclusion fence not containing home", lambda d, t: _robot(d).update(safety={"geofence": _FAR_FENCE}),
              "safety.geofence"),
    InputCase("PX4 robot, two overlapping inclusion circles (PX4 intersects them, our gate takes the union)",
              lambda d, t: _robot(d).update(backend="mavlink", mavlink={"connection": "udpin:127.0.0.1:14540",
                                                                         "autopilot": "px4"},
                                            safety={"geofence": _TWO_CIRCLES}), "2 inclusion zones"),
    InputCase("mavlink.fence.home_radius_m below safety.max_distance",
              lambda d, t: _robot(d).update(backend="mavlink", mavlink={"connection": "udpin:127.0.0.1:14550",
                                                                         "fence": {"home_radius_m": 80}},
                                            safety={"geofence": _TWO_CIRCLES}), "fence.home_radius_m"),
    InputCase("fence circle radius Infinity",
              lambda d, t: _robot(d).update(safety={"geofence": {"circles": [{"center": [47.39, 8.54], "radius": INF}]}}),
              "radius"),
    InputCase("self-intersecting fence polygon",
              lambda d, t: _robot(d).update(safety={"geofence": {"polygons": [{"points": [
                  [47.39, 8.54], [47.40, 8.55], [47.39, 8.55], [47.40, 8.54]]}]}}), "not a simple polygon"),
])

#: environment cases of category 'files and images'
FILE_REF_CASES: list[InputCase] = _category('files and images', [
    InputCase("target crop outside its image", lambda d, t: d.update(world={"targets": [_target(t, crop=(10, 10, 100, 30))]}),
              "world.targets.0.crop"),
    InputCase("ground image not an image", lambda d, t: (t.joinpath("g.png").write_text("x"),
                                                         d.update(world={"ground": {"image": str(t / "g.png")}})),
              "world.ground.image"),
    InputCase("replay log without position data",
              lambda d, t: _robot(d).update(backend="replay", replay={"log": _tlog_without_position(t)}),
              "no position fix"),
    InputCase("ground image a PNG bomb (header 100000 x 100000 px)",
              lambda d, t: d.update(world={"ground": {"image": _png_bomb(t)}}), "world.ground.image"),
    InputCase("target image a PNG bomb (header 100000 x 100000 px)",
              lambda d, t: d.update(world={"targets": [{**_target(t), "image": _png_bomb(t)}]}), "world.targets.0.image"),
    # refused by the camera actor, after Ray had started
    InputCase("camera source mcap naming a file that is not MCAP",
              lambda d, t: _cam(d).update(_replay_camera(t, False)), "robots.0.sensors.0.properties.mcap"),
    InputCase("camera source mcap naming a recording without its topic",
              lambda d, t: _cam(d).update(_replay_camera(t, True)), "robots.0.sensors.0.properties.topic"),
])

#: environment cases of category 'HITL settings'
HITL_SETTING_CASES: list[InputCase] = _category('HITL settings', [
    InputCase("hitl.port 70000", lambda d, t: d.update(hitl={"port": 70000}), "hitl.port"),
    InputCase("hitl.token too short", lambda d, t: d.update(hitl={"token": "abc"}), "hitl.token"),
    InputCase("hitl.token of 16 spaces", lambda d, t: d.update(hitl={"token": " " * 16}), "hitl.token"),
    InputCase("hitl.token with a blank", lambda d, t: d.update(hitl={"token": "abcdefgh ijklmnop"}), "hitl.token"),
    InputCase("hitl.host \"999.999.1.1\"", lambda d, t: d.update(hitl={"host": "999.999.1.1"}), "hitl.host"),
    InputCase("hitl.host empty", lambda d, t: d.update(hitl={"host": ""}), "hitl.host"),
    InputCase("hitl.port -1", lambda d, t: d.update(hitl={"port": -1}), "hitl.port"),
])

#: every environment file that must be refused (ConfigError naming the field) before anything starts
ENV_CASES: list[InputCase] = [*ID_CASES, *STRICT_TYPE_CASES, *BOUND_CASES, *KEY_CASES, *GEOFENCE_CASES, *FILE_REF_CASES, *HITL_SETTING_CASES]

#: ``--record`` paths that must be refused before anything starts (no folder created)
PATH_CASES: list[tuple[str, Callable[[Path], str], str]] = [
    ("missing folder", lambda t: str(t / "no" / "such" / "dir" / "run.mcap"), "does not exist"),
    ("/proc/x.mcap", lambda t: "/proc/x.mcap", "cannot create"),
    ("/dev/full", lambda t: "/dev/full", "not a regular file"),
    ("a directory", lambda t: str(t), "not a regular file"),
    ("an existing file that is not a recording", lambda t: (t / "notes.txt").write_text("mine") and str(t / "notes.txt"),
     "not an AeroDaaS recording; pass --overwrite"),
]


def check_env_case(case: InputCase, tmp: Path) -> tuple[bool, str]:
    """(refused with the expected field named, message) for one environment case."""
    d = copy.deepcopy(base_env())
    case.mutate(d, tmp)
    d = json.loads(json.dumps(d))  # what a file would hold (Infinity/NaN survive as JSON extensions)
    try:
        parse_environment_config(d, source="case")
    except ConfigError as e:
        return case.expect in str(e), str(e)
    return False, "accepted"


def check_path_case(make: Callable[[Path], str], expect: str, tmp: Path) -> tuple[bool, str]:
    """(refused with the expected reason and nothing created, message) for one ``--record`` path."""
    path = make(tmp)
    before = Path(path).parent.exists()
    try:
        check_record_path(path)
    except ValueError as e:
        created = Path(path).parent.exists() and not before
        return expect in str(e) and not created, str(e)
    return False, "accepted"


def run_inputs() -> dict[str, Any]:
    """Run every input case, each (or each batch) under :func:`aerodaas.reliability.input_report.guarded`; returns
    the rows (with their category) and the counts: tried, refused, accepted wrongly, tracebacks, hangs."""
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        for c in ENV_CASES:
            def env_row(c: InputCase = c) -> list[dict[str, Any]]:
                ok, msg = check_env_case(c, tmp)
                return [{"kind": "environment", "category": c.category, "name": c.name, "refused": ok,
                         "message": msg}]

            rows += guarded(env_row, "environment", c.name, c.category, 120.0)
        for name, make, expect in PATH_CASES:
            def path_row(name: str = name, make=make, expect: str = expect) -> list[dict[str, Any]]:
                ok, msg = check_path_case(make, expect, tmp)
                return [{"kind": "--record path", "name": name, "refused": ok, "message": msg}]

            rows += guarded(path_row, "--record path", name, "output paths", 120.0)

        # malformed JSON files, mission files and uploads, safety-gate probes
        rows += guarded(lambda: run_file_cases(tmp), "file", "file, mission and gate cases", "files and images", 1800.0)
        # app values, plug-in imports, output paths, WPL numbering, the gate's own check, `aerodaas inject`
        rows += guarded(lambda: run_app_cases(tmp), "application", "application cases", "app-level errors", 900.0)

    # flags refused before Ray (exit 2), the app's own exceptions (exit 1, its traceback)
    rows += guarded(run_cli_cases, "command line", "command-line cases", "command line", 900.0)
    rows += guarded(run_hitl_cases, "HITL API", "HITL API cases", "HITL API", 900.0)  # in-process server, no Ray
    return summarize(rows)


def run_flights(n: int = 20, seed: int = 0) -> dict[str, Any]:
    """``n`` seeded random command sequences (half ``reject``, half ``clamp``) plus repeated pushes at the fence and
    ceiling, flown on the simulator's vehicle behind the safety gate (:mod:`aerodaas.reliability.flight`); the worst excursions."""
    total, outside = Excursion(), 0
    seqs = [random_commands(random.Random(seed + i)) for i in range(n)]
    seqs += [[("vel", 3.0, 0.0, 0.0, 0.5, 5)] * 80, [("vel", 2.0, 1.2, 0.0, 0.5, 5)] * 80,
             [("vel", 0.0, 0.0, 1.5, 0.5, 5)] * 60]
    for i, seq in enumerate(seqs):
        ex = fly_commands(seq, on_violation="clamp" if i % 2 else "reject")
        outside += int(ex.outside_inclusion_m > 0 or ex.inside_exclusion_m > 0 or ex.above_max_altitude_m > 1e-6)
        total.merge(ex)
    return {"sequences": len(seqs), "samples": total.samples, "accepted": total.accepted, "refused": total.rejected,
            "outside_inclusion_m": total.outside_inclusion_m, "inside_exclusion_m": total.inside_exclusion_m,
            "above_max_altitude_m": total.above_max_altitude_m, "flown_outside_limits": outside}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aerodaas.reliability", description=__doc__.splitlines()[0])
    p.add_argument("--out", help="write the Markdown report here (default: print it)")
    p.add_argument("--no-faults", action="store_true", help="only the input cases (no runs)")
    args = p.parse_args(argv)
    inputs = run_inputs()
    flights = run_flights()
    faults = None
    if not args.no_faults:
        faults = run_faults()

    text = render(inputs, faults, flights)
    if args.out:
        Path(args.out).write_text(text)
        print(f"wrote {args.out}")
    else:
        print(text)
    bad = inputs["accepted_wrongly"] or inputs["tracebacks"] or inputs["hangs"] or flights["flown_outside_limits"] or (
        faults and any(not f["clean"] for f in faults["rows"]))
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
