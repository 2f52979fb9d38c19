"""Tests for aerodaas.recording.writer: MCAP mission recording with Foxglove protobuf schemas and JSON channels."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from aerodaas.model.types import Detection
from aerodaas.recording.writer import McapRecorder
from aerodaas.recording.values import quaternion_from_euler_deg
from aerodaas.recording.reader import read_messages, summarize_mcap

REPO_ROOT = Path(__file__).resolve().parents[2]
T0 = 1_700_000_000_000_000_000  # ns
MS = 1_000_000

PROTO_SCHEMAS = {
    "/camera/image": "foxglove.CompressedImage",
    "/camera/detections": "foxglove.ImageAnnotations",
    "/gps": "foxglove.LocationFix",
    "/pose": "foxglove.PoseInFrame",
    "/tf": "foxglove.FrameTransform",
}


def _image(i: int, h: int = 48, w: int = 64) -> np.ndarray:
    img = np.zeros((h, w, 3), np.uint8)
    img[:, :, 0] = 200  # blue
    img[h // 4: h // 2, (i * 5) % w: (i * 5) % w + 10, 2] = 255
    return img


def _write_full_mission(path: Path) -> None:
    det = Detection(class_id=2, class_name="car", score=0.9, box=(10, 20, 110, 70))
    with McapRecorder(path, metadata={"mission": "survey-1", "drone": "sim0"}) as rec:
        for i in range(5):
            t = T0 + i * 100 * MS  # 10 Hz for 0.4 s
            rec.write_image("/camera/image", t, _image(i))
            rec.write_detections("/camera/detections", t, [det], image_size=(640, 480))
            rec.write_location("/gps", t, 47.3977 + i * 1e-6, 8.5456, 488.0 + i)
            rec.write_pose("/pose", t, (1.0 * i, 2.0, 3.0), 90.0)
            rec.write_transform("/tf", t, "enu", "base_link", (1.0 * i, 2.0, 3.0), 90.0)
            rec.write_json("/mission/state", t, {"state": "IN_MISSION" if i < 4 else "LANDED", "i": np.int64(i),
                                                 "v": np.float32(0.5)}, schema_name="aerodaas.MissionState")
        rec.write_json("/mission/result", T0 + 400 * MS, {"outcome": "success"}, schema_name="aerodaas.MissionResult")


@pytest.fixture()
def mission_file(tmp_path: Path) -> Path:
    path = tmp_path / "sub" / "mission.mcap"  # parent dir is created by the recorder
    _write_full_mission(path)
    return path


def _decoded_by_topic(path: Path) -> dict[str, list]:
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        for ch in summary.channels.values():
            schema = summary.schemas[ch.schema_id]
            if ch.topic in PROTO_SCHEMAS:
                assert schema.name == PROTO_SCHEMAS[ch.topic], ch.topic
                assert schema.encoding == "protobuf"
                assert ch.message_encoding == "protobuf"
            else:
                assert schema.encoding == "jsonschema"
                assert ch.message_encoding == "json"
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "json":
                out.setdefault(channel.topic, []).append((message, json.loads(message.data)))
        for schema, channel, message, decoded in reader.iter_decoded_messages(topics=list(PROTO_SCHEMAS)):
            out.setdefault(channel.topic, []).append((message, decoded))
    return out


def test_roundtrip_foxglove_schemas_and_values(mission_file: Path) -> None:
    msgs = _decoded_by_topic(mission_file)
    assert set(msgs) == set(PROTO_SCHEMAS) | {"/mission/state", "/mission/result"}
    assert {t: len(v) for t, v in msgs.items() if t in PROTO_SCHEMAS} == {t: 5 for t in PROTO_SCHEMAS}

    # image: JPEG decoding to the original shape, timestamp from log time
    message, img_msg = msgs["/camera/image"][2]
    assert img_msg.format == "jpeg" and img_msg.frame_id == "camera"
    assert message.log_time == message.publish_time == T0 + 200 * MS
    assert img_msg.timestamp.seconds * 10**9 + img_msg.timestamp.nanos == T0 + 200 * MS
    decoded = cv2.imdecode(np.frombuffer(img_msg.data, np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (48, 64, 3)
    assert abs(float(decoded[..., 0].mean()) - 200) < 10  # still mostly blue in BGR order

    # detections: LINE_LOOP box through 4 corners + label text
    _, ann = msgs["/camera/detections"][0]
    assert len(ann.points) == 1 and len(ann.texts) == 1
    box = ann.points[0]
    assert box.type == 2  # PointsAnnotation.LINE_LOOP
    assert [(p.x, p.y) for p in box.points] == [(10, 20), (110, 20), (110, 70), (10, 70)]
    assert ann.texts[0].text == "car 0.90"
    assert (ann.texts[0].position.x, ann.texts[0].position.y) == (10, 20)
    assert ann.timestamp.seconds * 10**9 + ann.timestamp.nanos == T0

    # location: lat/lon/alt round-trip
    _, fix = msgs["/gps"][3]
    assert fix.latitude == pytest.approx(47.3977 + 3e-6, abs=1e-12)
    assert fix.longitude == pytest.approx(8.5456, abs=1e-12)
    assert fix.altitude == pytest.approx(491.0)

    # pose and transform: yaw 90 deg -> (0, 0, sin45, cos45)
    s45 = math.sin(math.radians(45))
    _, pose = msgs["/pose"][1]
    assert pose.frame_id == "enu"
    assert (pose.pose.position.x, pose.pose.position.y, pose.pose.position.z) == (1.0, 2.0, 3.0)
    q = pose.pose.orientation
    assert (q.x, q.y, q.z, q.w) == pytest.approx((0.0, 0.0, s45, s45), abs=1e-12)
    _, tf = msgs["/tf"][4]
    assert (tf.parent_frame_id, tf.child_frame_id) == ("enu", "base_link")
    assert tf.translation.x == 4.0
    assert (tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w) == pytest.approx((0, 0, s45, s45), abs=1e-12)

    # JSON: numpy scalars converted to plain numbers
    _, state = msgs["/mission/state"][0]
    assert state == {"state": "IN_MISSION", "i": 0, "v": 0.5}


def test_header_metadata_and_counts(mission_file: Path) -> None:
    with open(mission_file, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().library == "aerodaas"
        meta = list(reader.iter_metadata())
    assert [(m.name, m.metadata) for m in meta] == [("aerodaas", {"mission": "survey-1", "drone": "sim0"})]


def test_quaternion_convention() -> None:
    assert quaternion_from_euler_deg(0, 0, 0) == pytest.approx((0, 0, 0, 1))
    s45 = math.sqrt(0.5)
    assert quaternion_from_euler_deg(90, 0, 0) == pytest.approx((s45, 0, 0, s45))
    assert quaternion_from_euler_deg(0, 90, 0) == pytest.approx((0, s45, 0, s45))
    # ZYX: yaw 90 then roll 90 about the rotated x axis == q_z(90) * q_x(90)
    assert quaternion_from_euler_deg(90, 0, 90) == pytest.approx((0.5, 0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match="yaw_deg"):
        quaternion_from_euler_deg(0, 0, float("nan"))


def test_summarize_finished(mission_file: Path) -> None:
    s = summarize_mcap(mission_file)
    assert s["finished"] is True
    assert s["path"] == str(mission_file)
    assert s["message_count"] == 5 * 6 + 1
    assert s["start_ns"] == T0 and s["end_ns"] == T0 + 400 * MS
    assert s["duration_s"] == pytest.approx(0.4)
    by_topic = {c["topic"]: c for c in s["channels"]}
    assert set(by_topic) == set(PROTO_SCHEMAS) | {"/mission/state", "/mission/result"}
    for topic, schema in PROTO_SCHEMAS.items():
        assert by_topic[topic]["schema"] == schema
        assert by_topic[topic]["encoding"] == "protobuf"
        assert by_topic[topic]["count"] == 5
        assert by_topic[topic]["rate_hz"] == pytest.approx(5 / 0.4)
    assert by_topic["/mission/state"] == {"topic": "/mission/state", "schema": "aerodaas.MissionState",
                                          "encoding": "json", "count": 5, "rate_hz": pytest.approx(12.5)}
    assert s["metadata"] == {"mission": "survey-1", "drone": "sim0"}
    assert s["mission"] == {"outcome": "success", "final_state": "LANDED"}


def test_summarize_without_mission_topics(tmp_path: Path) -> None:
    path = tmp_path / "gps.mcap"
    with McapRecorder(path) as rec:
        rec.write_location("/gps", T0, 1.0, 2.0, 3.0)
    s = summarize_mcap(path)
    assert s["mission"] is None and s["message_count"] == 1 and s["duration_s"] == 0.0
    assert s["channels"][0]["rate_hz"] == 0.0 and s["metadata"] == {}


def test_read_messages_decodes_and_filters(mission_file: Path) -> None:
    got = list(read_messages(mission_file, topics=["/gps", "/mission/result"]))
    assert [(t, n) for t, n, _, _ in got].count(("/gps", "foxglove.LocationFix")) == 5
    assert ("/mission/result", "aerodaas.MissionResult", T0 + 400 * MS, {"outcome": "success"}) in got
    times = [t for _, _, t, _ in got]
    assert times == sorted(times)
    gps = [d for t, _, _, d in got if t == "/gps"]
    assert gps[0].latitude == pytest.approx(47.3977)
    assert len(list(read_messages(mission_file))) == 31


def test_jpeg_passthrough_and_bad_inputs(tmp_path: Path) -> None:
    ok, buf = cv2.imencode(".jpg", _image(0, 32, 40))
    assert ok
    with McapRecorder(tmp_path / "j.mcap", jpeg_quality=50) as rec:
        rec.write_image("/cam", T0, jpeg=buf.tobytes(), frame_id="front")
        with pytest.raises(ValueError, match="exactly one"):
            rec.write_image("/cam", T0)
        with pytest.raises(ValueError, match=r"\(H, W, 3\) uint8"):
            rec.write_image("/cam", T0, np.zeros((4, 4, 3), np.float32))
        with pytest.raises(ValueError, match="JPEG"):
            rec.write_image("/cam", T0, jpeg=b"not a jpeg")
        with pytest.raises(ValueError, match="lat"):
            rec.write_location("/gps", T0, 91.0, 0.0, 0.0)
        with pytest.raises(TypeError, match="nanoseconds"):
            rec.write_location("/gps", 1.5, 1.0, 0.0, 0.0)
        assert rec.message_counts == {"/cam": 1}
    [(topic, schema, t, img)] = list(read_messages(tmp_path / "j.mcap"))
    assert (topic, schema, t, img.frame_id, img.data) == ("/cam", "foxglove.CompressedImage", T0, "front", buf.tobytes())


def test_topic_keeps_one_schema_and_closed_writes_fail(tmp_path: Path) -> None:
    rec = McapRecorder(tmp_path / "x.mcap")
    rec.write_location("/gps", T0, 1.0, 2.0, 3.0)
    with pytest.raises(ValueError, match="/gps"):
        rec.write_pose("/gps", T0, (0, 0, 0), 0.0)
    with pytest.raises(ValueError, match="/gps"):
        rec.write_json("/gps", T0, {"a": 1}, schema_name="x")
    rec.write_json("/state", T0, {"state": "A"}, schema_name="aerodaas.MissionState")
    with pytest.raises(ValueError, match="/state"):
        rec.write_json("/state", T0, {"state": "A"}, schema_name="aerodaas.Other")
    assert rec.message_counts == {"/gps": 1, "/state": 1}
    rec.close()
    rec.close()  # idempotent
    assert rec.closed
    with pytest.raises(RuntimeError, match="closed"):
        rec.write_location("/gps", T0, 1.0, 2.0, 3.0)
    with pytest.raises(RuntimeError):
        rec.write_json("/new", T0, {}, schema_name="x")
    s = summarize_mcap(tmp_path / "x.mcap")
    assert s["finished"] and s["message_count"] == 2


def test_unopenable_path_raises_clear_error(tmp_path: Path) -> None:
    (tmp_path / "adir").mkdir()
    with pytest.raises(OSError, match="adir"):
        McapRecorder(tmp_path / "adir")
    with pytest.raises(ValueError, match="not an MCAP"):
        summarize_mcap(_write_text(tmp_path / "plain.mcap"))


def _write_text(p: Path) -> Path:
    p.write_text("hello, this is not an mcap file at all")
    return p


def test_threaded_writes(tmp_path: Path) -> None:
    path = tmp_path / "threads.mcap"
    with McapRecorder(path, chunk_size=2048) as rec:
        def worker(k: int) -> None:
            for i in range(200):
                rec.write_json(f"/w{k}", T0 + i * MS, {"i": i, "k": k}, schema_name="aerodaas.Tick")
        threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    s = summarize_mcap(path)
    assert s["message_count"] == 800
    assert sorted(c["count"] for c in s["channels"]) == [200] * 4


_CRASH_SCRIPT = textwrap.dedent("""
    import os, sys
    import numpy as np
    from aerodaas.recording.writer import McapRecorder
    rec = McapRecorder(sys.argv[1], chunk_size=4096, metadata={{"run": "crash"}})
    for i in range({n}):
        t = {t0} + i * 10_000_000
        rec.write_json("/mission/state", t, {{"state": "IN_MISSION", "i": i, "pad": "x" * 200}},
                       schema_name="aerodaas.MissionState")
        rec.write_location("/gps", t, 47.0 + i * 1e-6, 8.0, 400.0)
    sys.stdout.flush()
    os._exit(1)  # simulated crash: no close(), no buffer flush
""")


def test_crash_leaves_readable_file(tmp_path: Path) -> None:
    n = 200  # ~60 kB of JSON + GPS -> ~15 chunks of 4 KiB
    path = tmp_path / "crash.mcap"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", _CRASH_SCRIPT.format(n=n, t0=T0), str(path)],
                          env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1, proc.stderr
    total = 2 * n

    # the file really is unfinished: mcap's index-based reader cannot use it
    with open(path, "rb") as f:
        with pytest.raises(Exception):
            make_reader(f).get_summary()

    s = summarize_mcap(path)
    assert s["finished"] is False
    assert s["metadata"] == {"run": "crash"}
    # every completed chunk is readable: only the last partial chunk (< 4096 B, i.e. < ~20 messages) is lost
    assert total - 25 <= s["message_count"] < total
    assert s["start_ns"] == T0
    assert s["mission"] == {"outcome": None, "final_state": "IN_MISSION"}
    counts = {c["topic"]: c["count"] for c in s["channels"]}
    assert abs(counts["/gps"] - counts["/mission/state"]) <= 1

    got = list(read_messages(path))
    assert len(got) == s["message_count"]
    states = [d for topic, _, _, d in got if topic == "/mission/state"]
    assert [d["i"] for d in states] == list(range(len(states)))  # a contiguous prefix, in write order
    gps = [d for topic, name, _, d in got if topic == "/gps"]
    assert gps and gps[-1].latitude == pytest.approx(47.0 + (len(gps) - 1) * 1e-6)
    assert list(read_messages(path, topics=["/nope"])) == []


def test_truncated_at_any_offset_is_tolerated(tmp_path: Path) -> None:
    """A crash can cut the file anywhere (even inside a chunk record): readers never raise, and the number of
    readable messages only grows with the file length."""
    full = tmp_path / "full.mcap"
    with McapRecorder(full, chunk_size=1024, metadata={"k": "v"}) as rec:
        for i in range(30):
            rec.write_json("/mission/state", T0 + i, {"state": f"S{i}"}, schema_name="aerodaas.MissionState")
            rec.write_location("/gps", T0 + i, 1.0, 2.0, 3.0)
            if i % 5 == 0:
                rec.write_image("/cam", T0 + i, _image(i, 16, 16))
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    previous = -1
    for n in sorted(set(np.linspace(8, len(data) - 1, 60).astype(int).tolist())):
        cut.write_bytes(data[:n])
        s = summarize_mcap(cut)
        assert s["finished"] is False
        assert len(list(read_messages(cut))) == s["message_count"]
        assert s["message_count"] >= previous
        previous = s["message_count"]
    assert previous == 30 * 2 + 6  # cut inside the summary section: all chunks are still there


def test_flush_makes_everything_durable(tmp_path: Path) -> None:
    """After flush(), a crash loses nothing (the partial chunk is closed and handed to the OS)."""
    path = tmp_path / "flushed.mcap"
    script = textwrap.dedent(f"""
        import os, sys
        from aerodaas.recording.writer import McapRecorder
        rec = McapRecorder(sys.argv[1], chunk_size=1 << 20)
        for i in range(7):
            rec.write_json("/mission/state", {T0} + i, {{"state": "S%d" % i}}, schema_name="s")
        rec.flush()
        rec.write_json("/mission/state", {T0} + 99, {{"state": "LOST"}}, schema_name="s")
        os._exit(3)
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", script, str(path)], env=env, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 3, proc.stderr
    s = summarize_mcap(path)
    assert (s["finished"], s["message_count"]) == (False, 7)
    assert s["mission"] == {"outcome": None, "final_state": "S6"}


def test_a_plugins_schema_given_to_the_recorder_is_its_channels_schema_and_a_builtin_name_is_refused(tmp_path):
    """The plug-ins' message schemas are the recorder's own (``McapRecorder(json_schemas=...)``, no process-wide
    table): the channel of a plug-in's schema name carries that JSON Schema, a name nobody declared the permissive
    one, and a plug-in cannot replace a built-in schema (ValueError naming it, before the file is opened)."""
    gas = {"type": "object", "title": "my_plugin.GasReading", "properties": {"ppm": {"type": "number"}}}
    path = tmp_path / "plugin.mcap"
    with McapRecorder(path, json_schemas={"my_plugin.GasReading": gas}) as rec:
        rec.write_json("/uav/gas", T0, {"ppm": 1.5}, schema_name="my_plugin.GasReading")
        rec.write_json("/uav/other", T0, {"x": 1}, schema_name="my_plugin.Undeclared")
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    by_topic = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    assert json.loads(by_topic["/uav/gas"].data) == gas
    assert json.loads(by_topic["/uav/other"].data) == {"type": "object"}
    with McapRecorder(tmp_path / "second.mcap") as rec:  # another recorder of this process: not declared there
        rec.write_json("/uav/gas", T0, {"ppm": 1.5}, schema_name="my_plugin.GasReading")
    with open(tmp_path / "second.mcap", "rb") as f:
        assert json.loads(next(iter(make_reader(f).get_summary().schemas.values())).data) == {"type": "object"}
    with pytest.raises(ValueError, match="aerodaas.MissionState"):
        McapRecorder(tmp_path / "refused.mcap", json_schemas={"aerodaas.MissionState": gas})
    assert not (tmp_path / "refused.mcap").exists()
