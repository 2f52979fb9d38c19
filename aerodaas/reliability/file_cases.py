"""Input cases that are whole files or commands rather than one environment field: JSON
files that are malformed as text (nesting 100,000 deep, UTF-16 / Latin-1, a duplicate key, a 5,000-digit integer),
mission files (100,000 items of a ``.plan`` and of a WPL checked in bounded, linear time; an item 50 km up or
7,100 km away, a far rally point: refused by ``mission upload`` before it connects) and safety-gate probes (an
absolute waypoint thousands of kilometres away, a velocity command that would carry the vehicle beyond
``safety.max_distance``). Each row: ``{"kind", "name", "refused", "message"}`` as in
:func:`aerodaas.reliability.catalogue.run_inputs`; ``refused`` means refused (or, for the big files, checked) as
documented, naming the file, item or field."""
from __future__ import annotations

import contextlib
import io
import json
import time
from pathlib import Path
from typing import Any, Callable

from aerodaas import cli
from aerodaas.config import ConfigError, RobotConfig, load_environment_config
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
from aerodaas.missionfile import load_mission, plan_to_flight
from aerodaas.model.types import GeoPoint, VelocityCommand, Waypoint
from aerodaas.navigation.safety import SafetyGate, SafetyViolation

__all__ = ["JSON_FILE_CASES", "MISSION_CASES", "run_file_cases", "big_plan", "big_wpl"]

HOME = (47.3977, 8.5456, 488.0)


def _valid_env_text() -> str:
    return json.dumps({"robots": [{"id": "d1"}]})


#: (name, bytes of the file, text the error must contain besides the file name)
JSON_FILE_CASES: list[tuple[str, Callable[[], bytes], str]] = [
    ("environment nested 100,000 deep", lambda: ('{"robots": ' + "[" * 100_000 + "]" * 100_000 + "}").encode(),
     "deep"),
    ("environment in UTF-16", lambda: _valid_env_text().encode("utf-16"), "UTF-16"),
    ("environment in Latin-1 (a non-ASCII id)", lambda: '{"robots": [{"id": "dr\u00f6hne"}]}'.encode("latin-1"),
     "UTF-8"),
    ("environment with a duplicate key", lambda: b'{"robots": [{"id": "d1"}], "robots": []}', "duplicate"),
    ("environment with a 5,000-digit integer",
     lambda: ('{"robots": [{"id": "d1", "battery": {"capacity_wh": ' + "9" * 5000 + "}}]}").encode(), "digits"),
]


def _plan_doc(items: list[dict], rally: list[list[float]] | None = None) -> dict:
    return {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "mission": {"version": 2, "items": items, "plannedHomePosition": list(HOME), "firmwareType": 12,
                        "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5},
            "geoFence": {"version": 2, "polygons": [], "circles": []},
            "rallyPoints": {"version": 2, "points": rally or []}}


def _item(seq: int, lat: float, lon: float, alt: float) -> dict:
    return {"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, None, lat, lon, alt],
            "autoContinue": True, "doJumpId": seq}


def big_plan(n: int) -> str:
    """A ``.plan`` of ``n`` waypoints on a 1 km square around :data:`HOME` (30 m up)."""
    return json.dumps(_plan_doc([_item(i + 1, HOME[0] + 0.009 * ((i % 100) / 100), HOME[1] + 0.013 * (i // 100 % 100)
                                       / 100, 30.0) for i in range(n)]))


def big_wpl(n: int) -> str:
    """A ``QGC WPL 110`` file: the home row and ``n`` waypoints as :func:`big_plan`."""
    rows = ["QGC WPL 110", f"0\t1\t0\t16\t0\t0\t0\t0\t{HOME[0]}\t{HOME[1]}\t{HOME[2]}\t1"]
    for i in range(n):
        rows.append(f"{i + 1}\t0\t3\t16\t0\t0\t0\t0\t{HOME[0] + 0.009 * ((i % 100) / 100):.7f}\t"
                    f"{HOME[1] + 0.013 * (i // 100 % 100) / 100:.7f}\t30\t1")
    return "\n".join(rows) + "\n"


#: (name, file name, text of the file, extra ``mission upload`` flags, text the error must contain; None: the file
#: must be accepted and checked)
MISSION_CASES: list[tuple[str, str, Callable[[], str], list[str], str | None]] = [
    ("mission item 50 km up", "up.plan", lambda: json.dumps(_plan_doc([_item(1, HOME[0], HOME[1], 50_000.0)])), [],
     "above max_altitude 120 m"),
    ("mission item ~7,100 km away", "far.plan", lambda: json.dumps(_plan_doc([_item(1, 1.0, 60.0, 30.0)])), [],
     "beyond max_distance 10000 m"),
    ("rally point 500 m up", "rally.plan",
     lambda: json.dumps(_plan_doc([_item(1, HOME[0], HOME[1], 30.0)], [[HOME[0], HOME[1], 500.0]])), [],
     "rally point 1"),
    ("mission --max-distance 0", "ok.plan", lambda: json.dumps(_plan_doc([_item(1, HOME[0], HOME[1], 30.0)])),
     ["--max-distance", "0"], "--max-distance"),
]


def _json_file_row(name: str, data: bytes, expect: str, tmp: Path) -> dict[str, Any]:
    p = tmp / "env.json"
    p.write_bytes(data)
    try:
        load_environment_config(p)
    except ConfigError as e:
        msg = str(e)
        return {"kind": "JSON file", "name": name, "refused": expect.lower() in msg.lower() and "env.json" in msg,
                "message": msg}
    return {"kind": "JSON file", "name": name, "refused": False, "message": "accepted"}


def _upload_row(name: str, fname: str, text: str, flags: list[str], expect: str, tmp: Path) -> dict[str, Any]:
    f = tmp / fname
    f.write_text(text)
    err = io.StringIO()
    # an emulated vehicle at the plans' home (distances are measured from the vehicle's home): the refusal must come
    # before anything is sent
    emu = MavlinkVehicleEmulator("ardupilot", speedup=10.0, gps_lock_s=1.0,
                                 home=GeoPoint(lat=HOME[0], lon=HOME[1], alt=HOME[2]))
    try:
        conn = emu.start("tcp:127.0.0.1:0")
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = cli.main(["mission", "upload", str(f), "--connection", conn, "--timeout", "10", *flags])
            except SystemExit as e:  # argparse's refusal of a flag
                code = int(e.code or 0)
        sent = emu.snapshot()["mission_len"] > 1  # ArduPilot keeps its home at 0
    finally:
        emu.stop()
    msg = err.getvalue().strip().splitlines()[-1] if err.getvalue().strip() else ""
    return {"kind": "mission upload", "name": name, "refused": code == 2 and expect in err.getvalue() and not sent,
            "message": f"exit {code}: {msg}"}


def _big_file_row(name: str, fname: str, text: str, tmp: Path) -> dict[str, Any]:
    f = tmp / fname
    f.write_text(text)
    t0 = time.perf_counter()
    plan = load_mission(f)
    flight = plan_to_flight(plan, max_altitude=120.0, max_distance=10_000.0)
    dt = time.perf_counter() - t0
    n = len(flight.navigation.waypoints)
    return {"kind": "mission file", "name": name, "refused": n == 100_000,
            "message": f"{n} waypoints read and checked in {dt:.1f} s"}


def _gate_rows() -> list[dict[str, Any]]:
    r = RobotConfig.model_validate({"id": "r", "home": dict(zip(("lat", "lon", "alt"), HOME)),
                                    "safety": {"max_distance": 500.0}})
    gate = SafetyGate(r.safety, r.limits, r.home)
    rows = []
    for name, call in [
        ("absolute waypoint ~7,100 km from home",
         lambda: gate.check_waypoint(Waypoint(id="far", x=1.0, y=60.0, z=10.0, waypoint_type="absolute"))),
        ("velocity 2 m/s for 300 s (max_distance 500 m)",
         lambda: gate.check_velocity(VelocityCommand(vx=2.0, duration=300.0), position=(0.0, 0.0, 10.0))),
    ]:
        try:
            call()
            rows.append({"kind": "safety gate", "name": name, "refused": False, "message": "accepted"})
        except SafetyViolation as e:
            rows.append({"kind": "safety gate", "name": name, "refused": "max_distance" in str(e), "message": str(e)})
    return rows


def run_file_cases(tmp: Path) -> list[dict[str, Any]]:
    """Every case of this module, files written under ``tmp``."""
    rows = [_json_file_row(n, make(), expect, tmp) for n, make, expect in JSON_FILE_CASES]
    rows += [_upload_row(n, f, make(), flags, expect, tmp) for n, f, make, flags, expect in MISSION_CASES]
    rows.append(_big_file_row("100,000-item .plan", "big.plan", big_plan(100_000), tmp))
    rows.append(_big_file_row("100,000-item QGC WPL", "big.waypoints", big_wpl(100_000), tmp))
    rows += _gate_rows()
    return rows
