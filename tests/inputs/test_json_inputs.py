"""Every JSON input read within bounds: nesting depth, encodings, duplicate keys, huge integers
give an error naming the file (and line), not a traceback; a 100k-item .plan is converted (linear checks)."""
from __future__ import annotations

import json

import pytest

from aerodaas.config import ConfigError, load_environment_config
from aerodaas.missionfile import MissionFileError, load_mission, plan_to_flight

CASES = {
    "deep": (b'{"robots": ' + b"[" * 100_000 + b"]" * 100_000 + b"}", "nested deeper"),
    "duplicate": (b'{"robots": [],\n "robots": []}', "line 2: duplicate key 'robots'"),
    "utf16": ('{"robots": []}'.encode("utf-16"), "UTF-16"),
    "latin1": ('{"robots": [{"id": "caf\xe9"}]}'.encode("latin-1"), "not UTF-8"),
    "bigint": (b'{"robots": [{"id": "r", "home": {"lat": 1' + b"0" * 5000 + b"}}]}", "5001 digits"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_environment_json_limits(tmp_path, name):
    data, msg = CASES[name]
    p = tmp_path / f"{name}.json"
    p.write_bytes(data)
    with pytest.raises(ConfigError, match=msg) as e:
        load_environment_config(p)
    assert str(p) in str(e.value)


def _plan(items: list) -> dict:
    return {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "geoFence": {"circles": [], "polygons": [], "version": 2}, "rallyPoints": {"points": [], "version": 2},
            "mission": {"version": 2, "firmwareType": 12, "vehicleType": 2, "cruiseSpeed": 5, "hoverSpeed": 3,
                        "plannedHomePosition": [47.3977, 8.5456, 488], "items": items}}


def _item(i: int) -> dict:
    return {"type": "SimpleItem", "autoContinue": True, "command": 16, "doJumpId": i + 1, "frame": 3,
            "params": [0, 0, 0, None, 47.3977 + i * 1e-6, 8.5456, 10]}


def test_deep_plan_is_refused_naming_the_file(tmp_path):
    p = tmp_path / "deep.plan"
    p.write_text('{"fileType": "Plan", "mission": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(MissionFileError, match="nested deeper") as e:
        load_mission(p)
    assert str(p) in str(e.value)


def test_duplicate_key_in_a_plan_is_refused(tmp_path):
    p = tmp_path / "dup.plan"
    doc = json.dumps(_plan([_item(0)]), indent=1).replace('"version": 1,', '"version": 1,\n"version": 1,', 1)
    p.write_text(doc)
    with pytest.raises(MissionFileError, match="duplicate key 'version'"):
        load_mission(p)


@pytest.mark.faults
def test_a_100k_item_plan_is_converted(tmp_path):
    """A 100,000-item plan converts whole (each item checked once: a per-item copy of the items after it, or a
    per-waypoint id search, made this take minutes)."""
    p = tmp_path / "big.plan"
    p.write_text(json.dumps(_plan([_item(i) for i in range(100_000)])))
    fp = plan_to_flight(load_mission(p))
    assert len(fp.navigation.waypoints) == 100_000
