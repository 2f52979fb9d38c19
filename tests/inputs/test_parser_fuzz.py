"""Property-based fuzzing (hypothesis) of the environment and mission-file parsers: any document —
random JSON of any shape, a valid one with a field replaced by random JSON, nesting thousands deep, random WPL
lines — is either accepted or refused with the parser's own error naming the file (ConfigError /
MissionFileError); never another exception (a traceback), never a hang (bounded sizes in the strategies, and
the JSON reader's own depth and size limits)."""
from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aerodaas.config import ConfigError, load_environment_config
from aerodaas.missionfile import MissionFileError, load_mission, plan_to_flight

HOME = {"lat": 47.3977, "lon": 8.5456, "alt": 488.0}
FUZZ = settings(max_examples=120, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

scalars = st.one_of(st.none(), st.booleans(), st.integers(min_value=-(10 ** 40), max_value=10 ** 40),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20))
json_values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                           st.dictionaries(st.text(max_size=12), inner, max_size=5)),
                           max_leaves=30)
ENV_KEYS = ["robots", "simulation", "world", "compute", "analytics", "hitl", "recording", "targets"]
ROBOT_KEYS = ["id", "home", "limits", "safety", "sensors", "backend", "noise", "battery", "compute", "mavlink"]


def _env_doc(draw_key: str, robot_key: str | None, value) -> dict:
    doc: dict = {"robots": [{"id": "r", "home": dict(HOME)}]}
    if robot_key is not None:
        doc["robots"][0][robot_key] = value
    else:
        doc[draw_key] = value
    return doc


def _loads_env(tmp_path, text: str) -> None:
    p = tmp_path / "env.json"
    p.write_text(text)
    try:
        load_environment_config(p)
    except ConfigError as e:
        assert str(p) in str(e) or "env.json" in str(e), f"the error does not name the file: {e}"


@FUZZ
@given(doc=json_values)
def test_any_json_document_is_accepted_or_refused_as_config(tmp_path_factory, doc):
    _loads_env(tmp_path_factory.mktemp("env"), json.dumps(doc))


@FUZZ
@given(key=st.sampled_from(ENV_KEYS), robot_key=st.one_of(st.none(), st.sampled_from(ROBOT_KEYS)), value=json_values)
def test_a_valid_environment_with_any_field_replaced_is_accepted_or_refused(tmp_path_factory, key, robot_key, value):
    _loads_env(tmp_path_factory.mktemp("env"), json.dumps(_env_doc(key, robot_key, value)))


@FUZZ
@given(depth=st.integers(min_value=1, max_value=200_000), opener=st.sampled_from(["[", '{"a":']))
def test_nesting_of_any_depth_is_refused_with_a_named_error(tmp_path_factory, depth, opener):
    closer = "]" if opener == "[" else "}"
    _loads_env(tmp_path_factory.mktemp("env"), '{"robots": ' + opener * depth + "1" + closer * depth + "}")


ITEM = {"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, None, 47.398, 8.546, 20.0],
        "autoContinue": True, "doJumpId": 1}
ITEM_KEYS = ["type", "command", "frame", "params", "autoContinue", "doJumpId", "complexItemType"]


def _plan(items) -> dict:
    return {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "mission": {"version": 2, "items": items, "plannedHomePosition": [HOME["lat"], HOME["lon"], HOME["alt"]],
                        "firmwareType": 12, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5},
            "geoFence": {"version": 2, "polygons": [], "circles": []}, "rallyPoints": {"version": 2, "points": []}}


def _loads_mission(tmp_path, name: str, text: str) -> None:
    p = tmp_path / name
    p.write_text(text)
    try:
        plan = load_mission(p)
        if plan.home is not None:
            plan_to_flight(plan, max_altitude=120.0, max_distance=10_000.0)
    except MissionFileError as e:
        assert name in str(e), f"the error does not name the file: {e}"


@FUZZ
@given(field=st.sampled_from(ITEM_KEYS), value=json_values, n=st.integers(min_value=1, max_value=4))
def test_a_plan_with_any_item_field_replaced_is_accepted_or_refused(tmp_path_factory, field, value, n):
    items = [dict(ITEM, doJumpId=i + 1) for i in range(n)]
    items[-1][field] = value
    _loads_mission(tmp_path_factory.mktemp("plan"), "m.plan", json.dumps(_plan(items)))


@FUZZ
@given(doc=json_values)
def test_any_json_as_a_plan_is_accepted_or_refused(tmp_path_factory, doc):
    _loads_mission(tmp_path_factory.mktemp("plan"), "m.plan", json.dumps(doc))


wpl_fields = st.one_of(st.integers(min_value=-(10 ** 30), max_value=10 ** 30).map(str),
                       st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=8))


@FUZZ
@given(rows=st.lists(st.lists(wpl_fields, min_size=0, max_size=14), min_size=0, max_size=6))
def test_any_wpl_lines_are_accepted_or_refused(tmp_path_factory, rows):
    body = "\n".join("\t".join(r) for r in rows)
    _loads_mission(tmp_path_factory.mktemp("wpl"), "m.waypoints", "QGC WPL 110\n" + body + "\n")
