"""Live view and Foxglove completeness of recordings (second half).

* ``aerodaas run --live`` and ``aerodaas replay --live`` are exercised in-process (the run on the pytest worker's
  shared Ray session: tests/liveview/inprocess_live.py; the example plug-in app's test runs ``aerodaas run --live``
  as a subprocess, on loopback without a token), with a WebSocket client that speaks the Foxglove protocol (tests/liveview/foxglove_ws_client.py, written from the spec) and decodes
  what arrives with the schemas the server advertised;
* recordings are validated with readers we did not write: the ``mcap`` Python reader decoding every message
  (protobuf through mcap-protobuf-support's decoder factory, JSON with ``json.loads`` and ``jsonschema`` against the
  channel's own schema), plus the transform tree, the camera calibration and the schema fields Foxglove needs; and,
  when npm can install it, the npm ``@mcap/core`` reader.
"""
from __future__ import annotations

import base64
import json
import os
import queue
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory

from aerodaas.liveview.server import LiveServer, parse_address
from aerodaas.recording.writer import McapRecorder
from aerodaas.recording.values import camera_mount_quaternion, quaternion_from_euler_deg
from aerodaas.recording.schemas import JSON_SCHEMA_MODELS, json_schema_for

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import REPO, skip_or_fail
from tests.liveview.foxglove_ws_client import collect, schema_bytes
from tests.recording.mcap_validation import rotation, validate_recording

AERODAAS = [sys.executable, "-m", "aerodaas.cli"]
ROBOT = "uav"
CAMERA_TOPIC, POSE_TOPIC, DETECTIONS_TOPIC = f"/{ROBOT}/camera/cam", f"/{ROBOT}/pose", f"/{ROBOT}/detector/detections"
#: JSON schemas whose fields are free-form by design (an analytics' own dict output)
FREE_FORM = {"aerodaas.AnalyticsOutput"}


# --------------------------------------------------------------------------------------------- helpers
def _decode_with(channel: dict):
    """A decoder for an advertised channel, built from the schema the server sent (not from our classes)."""
    if channel["encoding"] == "json":
        return json.loads
    schema = Schema(id=1, name=channel["schemaName"], encoding=channel["schemaEncoding"], data=schema_bytes(channel))
    return DecoderFactory().decoder_for(channel["encoding"], schema)


def _recorded(path: Path, topics: set[str]) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list] = {t: [] for t in topics}
    with open(path, "rb") as f:
        for _s, ch, msg in make_reader(f).iter_messages(topics=sorted(topics), log_time_order=True):
            out[ch.topic].append((msg.log_time, bytes(msg.data)))
    return out


# --------------------------------------------------------------------------------------------- no Ray
def test_every_json_schema_is_generated_from_a_model_and_declares_its_fields():
    for name, model in JSON_SCHEMA_MODELS.items():
        js = json_schema_for(name)
        assert js["title"] == name and js["type"] == "object"
        if name not in FREE_FORM:
            assert set(js["properties"]) == {f.alias or k for k, f in model.model_fields.items()}, name
    out = json_schema_for("aerodaas.AnalyticsOutput", {"t": 1.5, "battery": 99, "gps": [1.0, 2.0, 3.0]})
    assert out["properties"]["battery"] == {"type": "number"} and out["properties"]["gps"]["type"] == "array"


def test_camera_mount_is_the_simulators_camera_in_the_body_frame():
    from aerodaas.model.camera import camera_rotation

    for yaw in (0.0, 37.0, 200.0):
        for pitch in (90.0, 45.0, 10.0):
            body = rotation(quaternion_from_euler_deg(0.0, 0.0, yaw))
            cam = body @ rotation(camera_mount_quaternion(pitch))
            assert np.allclose(cam, camera_rotation(yaw, pitch).T, atol=1e-12)


def test_live_address_parsing_names_the_bad_value():
    assert parse_address(None) == ("127.0.0.1", 8765)
    assert parse_address("") == ("127.0.0.1", 8765)
    assert parse_address("0") == ("127.0.0.1", 0)
    assert parse_address(":9000") == ("127.0.0.1", 9000)
    assert parse_address("0.0.0.0:9000") == ("0.0.0.0", 9000)
    assert parse_address("[::1]:9000") == ("::1", 9000)
    with pytest.raises(ValueError, match=r"--live: port 'x' in 'h:x'"):
        parse_address("h:x")
    with pytest.raises(ValueError, match="outside"):
        parse_address("h:70000")
    with pytest.raises(ValueError, match="brackets"):
        parse_address("::1:80")


def test_a_bad_or_busy_live_address_fails_before_ray(tmp_path):
    import socket

    app = tmp_path / "app.py"
    app.write_text("raise SystemExit('must not run')\n")
    p = run_cli("run", str(app), "--live", "127.0.0.1:99999")  # in-process: Ray refused
    assert p.returncode == 2 and "--live: port 99999" in p.stderr and "must not run" not in p.stderr
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        for cmd in (["run", str(app)], ["replay", str(tmp_path / "none.mcap")]):
            p = run_cli(*cmd, "--live", f"127.0.0.1:{port}")
            assert p.returncode == 2 and f"cannot listen on 127.0.0.1:{port}" in p.stderr, p.stderr


def test_live_server_sends_the_recorders_bytes_to_a_protocol_client():
    """The recorder writes each message once; the live server sends exactly those bytes with the file's schema."""
    server = LiveServer("127.0.0.1:0")
    rec = McapRecorder(None)  # no file: a live view without a recording
    rec.add_sink(server.publish)
    stop = threading.Event()

    def produce():
        i = 0
        while not stop.is_set() and i < 2000:
            t = 10**18 + i * 10**8
            rec.write_pose(POSE_TOPIC, t, (i * 0.1, 0.0, 2.0), 90.0)
            rec.write_json("/mission/state", t, {"robot": ROBOT, "state": "NAVIGATING", "previous": "HOVERING",
                                                 "t": i * 0.1}, schema_name="aerodaas.MissionState")
            i += 1
            stop.wait(0.01)

    th = threading.Thread(target=produce)
    th.start()
    try:
        got = collect(server.url, {POSE_TOPIC: 5, "/mission/state": 5}, timeout_s=60)
    finally:
        stop.set()
        th.join()
        server.stop()
        rec.close()
    assert got["protocol"] in ("foxglove.sdk.v1", "foxglove.websocket.v1")
    assert got["server_info"]["op"] == "serverInfo"
    pose_ch, state_ch = got["channels"][POSE_TOPIC], got["channels"]["/mission/state"]
    assert pose_ch["schemaName"] == "foxglove.PoseInFrame" and pose_ch["encoding"] == "protobuf"
    assert state_ch["schemaName"] == "aerodaas.MissionState" and state_ch["schemaEncoding"] == "jsonschema"
    assert json.loads(state_ch["schema"]) == json_schema_for("aerodaas.MissionState")
    dec = _decode_with(pose_ch)
    for t, data in got["messages"][POSE_TOPIC]:
        msg = dec(data)
        assert msg.frame_id == "enu" and msg.timestamp.seconds * 10**9 + msg.timestamp.nanos == t
    assert all(json.loads(d)["state"] == "NAVIGATING" for _, d in got["messages"]["/mission/state"])


def test_docs_layout_is_the_generated_vehicle_tracking_layout_with_the_panels_asked_for():
    from aerodaas.liveview.layout import build_layout

    doc = json.loads((REPO / "docs" / "foxglove-layout.json").read_text())
    assert doc == build_layout("quadrotor_base", "cam1", ["/quadrotor_base/detector/detections"],
                               tracks=["/quadrotor_base/follow/tracks"])  # the app's follow tracks
    panels = _panels(doc["content"])
    kinds = {p["panelType"]: p["config"] for p in panels}
    assert {"Image", "ThreeDee", "Map", "StateTransitions", "Plot"} <= set(kinds)
    img = kinds["Image"]["imageMode"]
    assert img["imageTopic"] == "/quadrotor_base/camera/cam1"
    assert img["calibrationTopic"] == "/quadrotor_base/camera/cam1/calibration"
    assert img["annotations"]["/quadrotor_base/detector/detections"]["visible"] is True
    assert img["annotations"]["/quadrotor_base/follow/tracks"]["visible"] is True  # track ids on the image
    assert kinds["ThreeDee"]["topics"]["/quadrotor_base/follow/tracks/scene"]["visible"] is True
    assert kinds["ThreeDee"]["followTf"] == "quadrotor_base/base_link"
    assert kinds["Map"]["followTopic"] == "/quadrotor_base/gps"
    assert [p["value"] for p in kinds["Plot"]["paths"]] == ["/quadrotor_base/odometry.battery_pct",
                                                             "/quadrotor_base/odometry.position[2]"]
    assert kinds["StateTransitions"]["paths"][0]["value"].startswith("/mission/state")


def _panels(node: dict) -> list[dict]:
    if node.get("type") == "panel":
        return [node]
    return [p for item in node.get("items", []) for p in _panels(item["content"])]


def _layout_topics(doc: dict) -> set[str]:
    """Every topic a layout names (message paths cut at their first '.', '{' or '[')."""
    import re

    text = json.dumps(doc)
    return {re.split(r"[.{\[]", m)[0] for m in re.findall(r'"(/[A-Za-z0-9_/]+(?:[.{\[][^"]*)?)"', text)}


# --------------------------------------------------------------------------------------------- a live run, a replay
ENV = {
    "name": "live-view",
    "robots": [{"id": ROBOT, "backend": "sim", "home": {"lat": 13.0213, "lon": 77.5671, "alt": 920.0},
                "takeoff_altitude": 3.0,
                "limits": {"max_speed": 2.0, "max_vertical_speed": 2.0, "max_acceleration": 2.0},
                "sensors": [{"id": "cam", "type": "camera",
                             "properties": {"width": 320, "height": 240, "hfov_deg": 70, "fps": 5, "pitch_deg": 60}},
                            {"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}]}],
    "compute": [{"id": "edge", "tier": "edge", "properties": {"cpus": 2, "memory_gb": 8, "accelerators": []}},
                {"id": "cloud", "tier": "cloud", "properties": {"cpus": 8, "memory_gb": 32, "accelerators": []}}],
    "world": {"ground": {"seed": 3, "metres_per_pixel": 0.05, "size_m": 60}},
    "simulation": {"speedup": 4, "physics_hz": 50},
}
APP = '''"""Test app: a detector deployed on CLOUD compute looks at the camera of a short flight."""
from aerodaas import *
from aerodaas.bench.pipeline import FixedCostDetector

env = Environment({env!r})
drone = env.get_robot_by_id("uav")
sched = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(sched)
detector = FixedCostDetector(2.0)
detector.deploy(env.get_compute_resource_by_id("cloud"))
detector.analyse(drone.get_sensor_by_id("cam").get_data_stream())
drone.navigate(sched.generate_navigation(PriorityQueue(AeroListData(
    [Waypoint(id="wp1", x=3.0, y=0.0, z=3.0, hover_duration=3.0)]), priority=2)))
result = drone.start_mission()
'''


def _start(cmd: list[str], env: dict | None = None) -> tuple[subprocess.Popen, "queue.Queue[str]"]:
    p = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    lines: queue.Queue[str] = queue.Queue()

    def pump():  # drain the output (a full pipe would block the process)
        for line in p.stdout:
            lines.put(line)
        lines.put("")

    threading.Thread(target=pump, daemon=True).start()
    return p, lines


def _wait_for_url(p: subprocess.Popen, lines: "queue.Queue[str]", marker: str, timeout_s: float = 240) -> tuple[str, list]:
    seen = []
    while True:
        line = lines.get(timeout=timeout_s)
        seen.append(line)
        if line == "":
            raise AssertionError(f"exited ({p.wait()}) before serving:\n{''.join(seen)}")
        if marker in line:
            url = next(w for w in line.split() if w.startswith("ws://"))
            return url.rstrip(".,;"), seen


@pytest.fixture(scope="module")
def live_run(ray_session, tmp_path_factory):
    """``aerodaas run app.py --record run.mcap --live 127.0.0.1:0`` with a protocol client connected for the whole
    run (subscribed to camera, pose and the cloud detector's detections): in-process on the pytest worker's shared
    Ray session, the client on a thread finding the URL in live.json (a token set:
    :func:`tests.liveview.inprocess_live.run_with_live_client`)."""
    from tests.liveview.inprocess_live import run_with_live_client

    tmp = tmp_path_factory.mktemp("live")
    (tmp / "live.json").write_text(json.dumps(ENV))
    app = tmp / "app.py"
    app.write_text(APP.format(env=str(tmp / "live.json")))
    rec = tmp / "run.mcap"
    env = {**os.environ, "AERODAAS_STATE_DIR": str(tmp / "state"), "AERODAAS_LIVE_TOKEN": "live-run-token-0123456789"}
    run = run_with_live_client(
        ["run", str(app), "--record", str(rec), "--live", "127.0.0.1:0", "--quiet"], env,
        lambda url: collect(url, {CAMERA_TOPIC: 10**9, POSE_TOPIC: 10**9, DETECTIONS_TOPIC: 10**9}, timeout_s=240))
    assert run.got is not None, f"the protocol client failed: {run.error!r}\n{run.cli.stdout[-3000:]}{run.cli.stderr[-3000:]}"
    return {"rc": run.cli.returncode, "got": run.got, "recording": rec, "url": run.info["url"],
            "output": run.cli.stdout + run.cli.stderr}


@pytest.mark.e2e
def test_live_run_serves_the_recordings_channels_to_a_protocol_client_and_stops_with_the_run(live_run):
    got, rec = live_run["got"], live_run["recording"]
    assert live_run["rc"] == 0, live_run["output"]
    assert live_run["url"].startswith("ws://127.0.0.1:")  # loopback unless told otherwise
    assert got["closed_by_server"], "the live server must close the connection when the run ends"
    expected = {CAMERA_TOPIC: "foxglove.CompressedImage", POSE_TOPIC: "foxglove.PoseInFrame",
                DETECTIONS_TOPIC: "foxglove.ImageAnnotations"}
    recorded = _recorded(rec, set(expected))
    with open(rec, "rb") as f:
        summary = make_reader(f).get_summary()
    file_schemas = {ch.topic: summary.schemas[ch.schema_id] for ch in summary.channels.values()}
    for topic, schema_name in expected.items():
        ch = got["channels"][topic]
        assert ch["schemaName"] == schema_name and ch["encoding"] == "protobuf" == ch["schemaEncoding"]
        assert schema_bytes(ch) == file_schemas[topic].data  # the recording's schema, byte for byte
        msgs = got["messages"][topic]
        assert len(msgs) >= 3, (topic, len(msgs), got["timeline"], live_run["output"])
        decode = _decode_with(ch)
        for t, data in msgs:
            m = decode(data)
            assert m.timestamp.seconds * 10**9 + m.timestamp.nanos == t
        # one serializer: every live message is a recorded message, same log time, same bytes, in order. The
        # server may drop a message for a client that falls behind (foxglove-sdk's bounded per-client queue; seen
        # once at load ~3 beside a SITL run), so the live messages are an ordered subsequence of the recording,
        # and at most one in ten may be missing from the span they cover
        rec_list = recorded[topic]
        start = rec_list.index(msgs[0])
        it = iter(rec_list[start:])
        assert all(any(m == r for r in it) for m in msgs), topic  # in order, each one recorded
        span = rec_list.index(msgs[-1]) - start + 1
        assert len(msgs) >= 0.9 * span, (topic, len(msgs), span)
    dec = _decode_with(got["channels"][DETECTIONS_TOPIC])
    assert all(len(dec(d).points) == 1 for _, d in got["messages"][DETECTIONS_TOPIC])  # the cloud detector's box
    assert len(recorded[DETECTIONS_TOPIC]) > 0  # outputs of cloud-deployed analytics are recorded


@pytest.mark.e2e
def test_the_live_run_recording_validates_with_the_mcap_reader(live_run):
    cam = ENV["robots"][0]["sensors"][0]["properties"]
    out = validate_recording(live_run["recording"], ROBOT, {"cam": cam})
    assert out["counts"][DETECTIONS_TOPIC] > 0


@pytest.mark.e2e
def test_aerodaas_layout_names_only_topics_the_recording_has(live_run, tmp_path):
    out = tmp_path / "layout.json"
    p = run_cli("layout", str(live_run["recording"]), "--out", str(out))  # in-process: a reader, no Ray
    assert p.returncode == 0, p.stderr
    doc = json.loads(out.read_text())
    with open(live_run["recording"], "rb") as f:
        topics = {ch.topic for ch in make_reader(f).get_summary().channels.values()}
    named = _layout_topics(doc)
    assert {CAMERA_TOPIC, DETECTIONS_TOPIC, f"/{ROBOT}/gps", f"/{ROBOT}/odometry", "/mission/state"} <= named
    assert named <= topics, named - topics


@pytest.mark.e2e
def test_replay_serves_a_recording_to_a_protocol_client(live_run, tmp_path):
    from tests.liveview.inprocess_live import run_with_live_client

    rec = live_run["recording"]
    topics = {CAMERA_TOPIC, POSE_TOPIC, DETECTIONS_TOPIC}
    recorded = _recorded(rec, topics)
    env = {**os.environ, "AERODAAS_STATE_DIR": str(tmp_path / "state"), "AERODAAS_LIVE_TOKEN": "replay-token-0123456789"}
    run = run_with_live_client(["replay", str(rec), "--live", "127.0.0.1:0", "--speed", "4"], env,
                               lambda url: collect(url, {t: 10**9 for t in topics}, timeout_s=180), shared_ray=False)
    got = run.got
    assert run.cli.returncode == 0 and "aerodaas replay: serving" in run.cli.stdout, run.cli.stdout + run.cli.stderr
    assert got is not None and got["closed_by_server"], f"the protocol client failed: {run.error!r}"
    for topic in topics:
        ch = got["channels"][topic]
        decode = _decode_with(ch)
        assert got["messages"][topic] == recorded[topic], topic  # every message, in order, as recorded
        for _, data in got["messages"][topic]:
            decode(data)


# --------------------------------------------------------------------------------------------- npm @mcap/core
# (The vehicle-tracking recording is validated with validate_recording in tests/runtime/test_e2e.py, on the run that test
# already makes: one run of the real detector instead of two.)
def _npm_mcap_reader(tmp_path: Path) -> list[str]:
    """``[node, read.mjs]``: :data:`NODE_READER` with npm ``@mcap/core`` installed in ``tmp_path``. Skips the test
    (:func:`~tests.conftest.skip_or_fail`: fails in CI) when node/npm are missing or npm cannot install."""
    npm, node = shutil.which("npm"), shutil.which("node")
    if not npm or not node:
        skip_or_fail("node/npm not installed (tests/install-rig.sh installs them)")
    try:
        # no retries and a short fetch timeout: offline, npm fails (or uses its cache) in seconds, not minutes
        inst = subprocess.run([npm, "install", "--silent", "--no-audit", "--no-fund", "--prefer-offline",
                               "--fetch-retries=0", "--fetch-timeout=15000", "@mcap/core@2", "fzstd@0.1"],
                              cwd=tmp_path, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        skip_or_fail("npm install @mcap/core timed out (offline?)")
    if inst.returncode != 0:
        skip_or_fail(f"npm install @mcap/core failed (offline?): {inst.stderr[-300:]}")
    script = tmp_path / "read.mjs"
    script.write_text(NODE_READER)
    return [node, str(script)]


def test_the_npm_mcap_reader_reads_many_tracks_from_one_location_fixes_topic(tmp_path):
    """A recording of 12 frames in which tracks 1-14 come and go (three at a time), read with npm
    ``@mcap/core``: one ``foxglove.LocationFixes`` channel for all tracks (no channel per track), each of its
    messages, decoded with the schema the TypeScript reader found in the file, carries that frame's track ids."""
    from aerodaas.model.types import GeoPoint
    from aerodaas.perception.track_records import write_tracks

    reader = _npm_mcap_reader(tmp_path)
    rec, prefix, frames = tmp_path / "tracks.mcap", "/d1/follow/tracks", {}
    with McapRecorder(rec) as r:
        for k in range(12):
            ids = [k + 1, k + 2, k + 3]
            rows = [{"track_id": i, "class_name": "car", "score": 0.9, "box": [10.0, 10.0, 30.0, 30.0],
                     "enu": [float(i), 1.0, 0.0], "cov": [[0.3, 0.0], [0.0, 0.3]], "sigma_m": 0.55} for i in ids]
            frames[10**18 + k * 10**8] = [str(i) for i in ids]
            write_tracks(r, prefix, 10**18 + k * 10**8, "d1", rows, GeoPoint(lat=13.0, lon=77.5, alt=920.0))
    p = subprocess.run([*reader, str(rec), f"{prefix}/fixes"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout)
    assert {t: v["schema"] for t, v in got["channels"].items()} == {
        prefix: "foxglove.ImageAnnotations", f"{prefix}/scene": "foxglove.SceneUpdate",
        f"{prefix}/fixes": "foxglove.LocationFixes"}
    sch = got["schemas"][f"{prefix}/fixes"]
    decode = DecoderFactory().decoder_for("protobuf", Schema(id=1, name=sch["name"], encoding=sch["encoding"],
                                                             data=base64.b64decode(sch["data"])))
    kept = {int(t): [{kv.key: kv.value for kv in f.metadata}["track_id"] for f in decode(base64.b64decode(d)).fixes]
            for t, d in got["kept"]}
    assert kept == frames


@pytest.mark.e2e
def test_the_recording_reads_with_the_npm_mcap_reader(live_run, tmp_path):
    """The TypeScript reader (npm @mcap/core, zstd via fzstd) indexes the file, finds every channel with its schema,
    reads every message and parses every JSON one. Skipped (:func:`~tests.conftest.skip_or_fail`: fails in CI) when node/npm are missing or npm cannot install."""
    rec = live_run["recording"]
    p = subprocess.run([*_npm_mcap_reader(tmp_path), str(rec)], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout)
    with open(rec, "rb") as f:
        summary = make_reader(f).get_summary()
    ours = {ch.topic: summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
    assert {t: v["schema"] for t, v in got["channels"].items()} == ours
    assert got["messages"] == summary.statistics.message_count
    assert got["json_parsed"] == sum(n for cid, n in summary.statistics.channel_message_counts.items()
                                     if summary.channels[cid].message_encoding == "json") > 0


NODE_READER = r"""
import { McapIndexedReader } from "@mcap/core";
import { decompress } from "fzstd";
import { open } from "node:fs/promises";

const fh = await open(process.argv[2], "r");
const readable = {
  size: async () => BigInt((await fh.stat()).size),
  read: async (offset, length) => {
    const buf = new Uint8Array(Number(length));
    await fh.read(buf, 0, Number(length), Number(offset));
    return buf;
  },
};
const reader = await McapIndexedReader.Initialize({
  readable,
  decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
});
// argv[3] (optional): a topic whose messages are returned as [log_time, base64 payload] in "kept", and its schema
// (name, encoding, base64 data) in "schemas"
const keepTopic = process.argv[3];
const channels = {}, schemas = {}, kept = [];
for (const ch of reader.channelsById.values()) {
  const schema = reader.schemasById.get(ch.schemaId);
  channels[ch.topic] = { schema: schema.name, encoding: ch.messageEncoding };
  if (ch.topic === keepTopic) {
    schemas[ch.topic] = { name: schema.name, encoding: schema.encoding,
      data: Buffer.from(schema.data).toString("base64") };
  }
}
let messages = 0, jsonParsed = 0;
const dec = new TextDecoder();
for await (const msg of reader.readMessages()) {
  messages++;
  const ch = reader.channelsById.get(msg.channelId);
  if (ch.messageEncoding === "json") { JSON.parse(dec.decode(msg.data)); jsonParsed++; }
  if (ch.topic === keepTopic) kept.push([msg.logTime.toString(), Buffer.from(msg.data).toString("base64")]);
}
console.log(JSON.stringify({ channels, messages, json_parsed: jsonParsed, schemas, kept }));
await fh.close();
"""


def test_stop_waits_for_a_client_that_follows_every_channel_and_not_for_one_that_follows_a_few(monkeypatch):
    """At the end of a run the server waits (bounded) for a client that follows every channel to subscribe to the
    ones advertised last (the mission result), and not for one that follows only a few (Foxglove's app, its panels'
    topics). Measured on a fake clock: how long stop() waited before it closed."""
    from types import SimpleNamespace

    from aerodaas.liveview import server as srv_mod
    from aerodaas.liveview.server import LiveServer

    def waited(subs: set[str]) -> float:
        # the server module's own clock, not the process's ``time`` module: another thread of this process that
        # sleeps meanwhile (Ray's, a profiler's) must not move it
        clock = [1000.0]
        fake = SimpleNamespace(monotonic=lambda: clock[0], sleep=lambda s: clock.__setitem__(0, clock[0] + s),
                               time=lambda: clock[0])
        with monkeypatch.context() as m:
            m.setattr(srv_mod, "time", fake)
            srv = LiveServer("127.0.0.1:0")
            for t in ("/old", "/older", "/mission/result"):
                srv.advertise(t, "aerodaas.X", "jsonschema", b"{}", "json")
            srv._born["/old"] = srv._born["/older"] = clock[0] - 600.0  # advertised long ago; the result just now
            srv.subscriptions, srv._client_subs = len(subs), {7: set(subs)}
            t0 = clock[0]
            srv.stop(linger_s=0.5)
            return clock[0] - t0 - 0.5

    assert waited({"/old", "/older", "/mission/result"}) < 0.1             # has everything: no wait
    assert waited({"/old"}) < 0.1                                           # follows a few: not waited for
    assert waited({"/old", "/older"}) >= LiveServer.CATCHUP_WAIT_S - 0.1    # lacks only the new one: waited for
