"""Geo-located tracks recorded during a run.

tests/apps/fleet_tracks.py: two simulated drones at 20 m, each over two of the simulator's cars (moving and parked); a
pixel colour detector (missing 10 % of the cars, 20 % at a low score) and one shared TrackAnalytics. From the recording (read with the ``mcap`` library): the track
channels of both drones exist (declared from the plan, so they are in the file's channel list), each track of the
scene is matched against the simulator's truth (``/world/targets``, written by the camera from the world model, not
from our detections): at most 1 id switch per 100 frames and a geo-location error within 1.5 m at 20 m altitude; the
LocationFix of each track agrees with its ENU position through the drone's home.

The fast tests check the recorder's side alone: declared channels exist before any message and are advertised by
the live view; write_tracks' three kinds of messages.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from aerodaas.model.types import GeoPoint
from aerodaas.bench.tracks import score_tracks
from aerodaas.model.geo import geodetic_to_enu

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import REPO

APP = REPO / "tests" / "apps" / "fleet_tracks.py"


def _read(path):
    """(channels {topic: schema name} from the file's summary, [(topic, log_time_ns, decoded message)])."""
    from aerodaas.recording.reader import read_messages

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    chans = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    return chans, [(topic, t, m) for topic, _s, t, m in read_messages(path)]


@pytest.fixture(scope="module")
def tracks_run(ray_session, tmp_path_factory):
    """One ``aerodaas run tests/apps/fleet_tracks.py --record tracks.mcap --live 127.0.0.1:0`` in-process on the
    pytest worker's shared Ray session (:func:`tests.inputs.cli_inprocess.run_cli`), a Foxglove protocol client
    (tests/liveview/foxglove_ws_client.py, written from the spec) connected from the live view's start to the run's
    end (:func:`tests.liveview.inprocess_live.run_with_live_client`, a token set): ``{"cli": the CliResult,
    "recording": path, "live": what the client got, "client_error": its exception}``."""
    import os
    import secrets

    from tests.liveview.foxglove_ws_client import collect
    from tests.liveview.inprocess_live import run_with_live_client

    tmp = tmp_path_factory.mktemp("tracks")
    rec = tmp / "tracks.mcap"
    env = dict(os.environ, AERODAAS_STATE_DIR=str(tmp / "state"), AERODAAS_LIVE_TOKEN=secrets.token_urlsafe(24))
    run = run_with_live_client(
        ["run", str(APP), "--record", str(rec), "--live", "127.0.0.1:0", "--quiet"], env,
        lambda url: collect(url, {"/d1/tracks/tracks/scene": 10**9, "/d1/tracks/tracks": 10**9}, timeout_s=300), cwd=tmp)
    return {"cli": run.cli, "recording": rec, "live": run.got, "client_error": run.error}


@pytest.mark.e2e
def test_a_run_records_geolocated_tracks_with_stable_ids(tracks_run):
    cli = tracks_run["cli"]
    assert cli.returncode == 0 and "mission outcome: success" in cli.stdout, cli.stdout[-3000:] + cli.stderr[-3000:]
    record = str(tracks_run["recording"])
    chans, msgs = _read(record)
    for robot in ("d1", "d2"):
        assert chans[f"/{robot}/tracks/tracks"] == "foxglove.ImageAnnotations"
        assert chans[f"/{robot}/tracks/tracks/scene"] == "foxglove.SceneUpdate"
        assert chans[f"/{robot}/tracks/tracks/fixes"] == "foxglove.LocationFixes"
    tracks = sorted(t for t in chans if t.startswith(("/d1/tracks/tracks", "/d2/tracks/tracks")))
    assert len(tracks) == 6, tracks  # one fixes topic per drone, not one per track
    rep = score_tracks(record)  # against /world/targets, at 19-21 m
    assert rep["frames"] >= 100, rep  # both drones hovered 25 s at 20 m, 5 frames/s
    assert all(r["frames"] >= 50 and r["matched"] >= 50 for r in rep["per_robot"].values()), rep
    assert rep["recall"] >= 0.8, rep  # the detector misses 10 % of the cars on purpose: no track on those frames
    assert rep["id_switches_per_100_frames"] <= 1.0, rep
    assert rep["error_m"]["max"] <= 1.5, rep
    frames = rep["frames"]
    # each LocationFix of the fixes is its track's scene ENU position through the drone's home, with its covariance
    home = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
    scene_at = {(topic.rsplit("/", 1)[0], t): m for topic, t, m in msgs if topic.endswith("/scene")}
    checked, ids = 0, set()
    for topic, t, m in msgs:
        if topic.endswith("/tracks/fixes"):
            ents = {int(dict((kv.key, kv.value) for kv in e.metadata)["track_id"]): e
                    for e in scene_at[(topic.rsplit("/", 1)[0], t)].entities}
            tids = [int(dict((kv.key, kv.value) for kv in f.metadata)["track_id"]) for f in m.fixes]
            assert sorted(tids) == sorted(ents), (topic, t)  # the same tracks on the map as in the scene
            for tid, f in zip(tids, m.fixes):
                e, n, _ = geodetic_to_enu(f.latitude, f.longitude, f.altitude, home)
                pos = ents[tid].spheres[0].pose.position
                assert abs(e - pos.x) < 0.01 and abs(n - pos.y) < 0.01
                assert f.position_covariance[0] > 0 and f.position_covariance[4] > 0
                ids.add((topic, tid))
                checked += 1
    assert checked >= frames and len(ids) >= 4, ids  # two cars under each drone
    # `aerodaas layout` of this recording shows the tracks: ids on the image, the scene in 3D, the fixes on the map
    from aerodaas.liveview.layout import layout_for_recording

    text = json.dumps(layout_for_recording(record))
    assert '"/d1/tracks/tracks/scene"' in text and '"/d1/tracks/tracks"' in text
    assert '"/d1/tracks/tracks/fixes"' in text


def test_declared_track_channels_exist_before_any_message_and_are_advertised_live(tmp_path):
    from aerodaas.actors.recording.recorder import RecorderService
    from aerodaas.perception.track_records import declared_track_channels
    from aerodaas.analytics.track import TrackAnalytics
    from aerodaas import FollowAnalytics
    from aerodaas.perception.tracking import ByteTrackConfig

    graphs = {"d1": [TrackAnalytics(), FollowAnalytics()], "d2": [FollowAnalytics(tracker=ByteTrackConfig())]}
    declare = declared_track_channels(["d1", "d2"], graphs)
    assert [t for t, _ in declare] == ["/d1/tracks/tracks", "/d1/tracks/tracks/scene", "/d1/tracks/tracks/fixes",
                                       "/d2/follow/tracks", "/d2/follow/tracks/scene",
                                       "/d2/follow/tracks/fixes"]  # the plain follow does not track
    svc = RecorderService(str(tmp_path / "r.mcap"), live="127.0.0.1:0", declare=declare,
                          homes={"d1": {"lat": 47.0, "lon": 8.0, "alt": 400.0}})
    try:
        assert set(svc.live._channels) == {t for t, _ in declare}  # advertised before the first message
    finally:
        svc.close()
    chans, msgs = _read(tmp_path / "r.mcap")
    assert chans == dict(declare) and msgs == []


def test_write_tracks_writes_annotations_scene_and_one_fixes_message_with_a_fix_per_track(tmp_path):
    from aerodaas.model.types import CameraIntrinsics, Detection, FrameMeta, FramePose
    from aerodaas.perception.track_records import track_rows, write_tracks
    from aerodaas.perception.tracking import ByteTracker
    from aerodaas.recording.reader import read_messages
    from aerodaas.recording.writer import McapRecorder

    k = CameraIntrinsics.from_hfov(320, 240, 60.0)
    meta = FrameMeta(robot_id="d1", sensor_id="cam", seq=0, capture_time=0.0, wall_time=0.0,
                     pose=FramePose(position=(10.0, 5.0, 20.0), yaw=90.0, camera_pitch=90.0), intrinsics=k)
    dets = [Detection(class_id=2, class_name="car", score=0.9, box=(150, 110, 170, 130)),  # the image centre
            Detection(class_id=2, class_name="car", score=0.9, box=(10, 10, 30, 30))]
    rows = track_rows(ByteTracker().update(dets), meta)
    assert [r["track_id"] for r in rows] == [1, 2]
    assert np.allclose(rows[0]["enu"][:2], (10.0, 5.0), atol=0.05)  # straight below the drone
    home = GeoPoint(lat=47.0, lon=8.0, alt=400.0)
    with McapRecorder(tmp_path / "t.mcap") as rec:
        write_tracks(rec, "/d1/tracks/tracks", 1_000, "d1", rows, home, (320, 240))
    got = {topic: m for topic, _s, _t, m in read_messages(tmp_path / "t.mcap")}
    assert set(got) == {"/d1/tracks/tracks", "/d1/tracks/tracks/scene", "/d1/tracks/tracks/fixes"}
    assert [t.text.split()[0] for t in got["/d1/tracks/tracks"].texts] == ["#1", "#2"]
    assert len(got["/d1/tracks/tracks/scene"].deletions) == 1  # ended tracks leave the scene
    fixes = got["/d1/tracks/tracks/fixes"].fixes
    assert [dict((kv.key, kv.value) for kv in f.metadata) for f in fixes] == [
        {"robot": "d1", "track_id": "1", "class_name": "car"}, {"robot": "d1", "track_id": "2", "class_name": "car"}]
    e, n, _ = geodetic_to_enu(fixes[0].latitude, fixes[0].longitude, 0.0, home)
    assert abs(e - 10.0) < 0.05 and abs(n - 5.0) < 0.05
    # each track's colour on the map is its box's colour on the image, and the two differ
    boxes = [p.outline_color for p in got["/d1/tracks/tracks"].points]
    assert [(f.color.r, f.color.g, f.color.b) for f in fixes] == [(c.r, c.g, c.b) for c in boxes]
    assert (fixes[0].color.r, fixes[0].color.g, fixes[0].color.b) != (fixes[1].color.r, fixes[1].color.g,
                                                                      fixes[1].color.b)


def test_many_tracks_are_one_fixes_topic_with_every_id_and_info_lists_one_track_topic(tmp_path):
    """30 frames in which 40 tracks come and go (five at a time) give ONE ``foxglove.LocationFixes``
    channel whose messages carry exactly each frame's track ids (metadata ``track_id``), 40 distinct ids in all;
    ``aerodaas info`` (the command line) lists three track channels, not one per track."""

    from aerodaas.perception.track_records import write_tracks
    from aerodaas.recording.reader import read_messages
    from aerodaas.recording.writer import McapRecorder

    home = GeoPoint(lat=47.0, lon=8.0, alt=400.0)
    frames = {}
    with McapRecorder(tmp_path / "many.mcap") as rec:
        for k in range(30):
            ids = sorted({(k + j) % 40 + 1 for j in range(0, 20, 4)} | {(k * 7) % 40 + 1})
            rows = [{"track_id": i, "class_name": "car", "score": 0.9, "box": [10.0, 10.0, 30.0, 30.0],
                     "enu": [float(i), -float(i), 0.0], "cov": [[0.5, 0.0], [0.0, 0.5]], "sigma_m": 0.7}
                    for i in ids]
            frames[1_000 + k] = ids
            write_tracks(rec, "/d1/tracks/tracks", 1_000 + k, "d1", rows, home, (320, 240))
    got = {}
    for topic, schema, t, m in read_messages(tmp_path / "many.mcap"):
        if schema == "foxglove.LocationFixes":
            assert topic == "/d1/tracks/tracks/fixes"
            got[t] = [int(dict((kv.key, kv.value) for kv in f.metadata)["track_id"]) for f in m.fixes]
    assert got == frames
    all_ids = {i for ids in frames.values() for i in ids}
    assert len(all_ids) == 40
    p = run_cli("info", str(tmp_path / "many.mcap"))  # in-process: a reader, no Ray
    assert p.returncode == 0, p.stderr
    lines = [ln.split() for ln in p.stdout.splitlines() if "/tracks" in ln]
    assert [tuple(ln[:3]) for ln in lines] == [("/d1/tracks/tracks", "foxglove.ImageAnnotations", "30"),
                                                ("/d1/tracks/tracks/fixes", "foxglove.LocationFixes", "30"),
                                                ("/d1/tracks/tracks/scene", "foxglove.SceneUpdate", "30")], p.stdout


# ------------------------------------------------------------------ the runtime's side, without Ray
class _Host:
    def mark_processed(self) -> None:
        pass


class _Recorder:
    """Collects what the analytics component hands the recorder."""

    def __init__(self) -> None:
        self.got: list[tuple] = []
        self.other: list[str] = []

    def tracks(self, prefix, t_ns, robot, rows, size):
        self.got.append((prefix, t_ns, robot, rows, size))

    def json(self, topic, *a):
        self.other.append(topic)

    def detections(self, topic, *a):
        self.other.append(topic)

    def declare_analytics(self, cid, name):
        """The component declares itself so its outputs are accounted against its inputs."""
        self.declared = (cid, name)

    def count_no_output(self, *a):
        """A frame processed without an output (counted, not recorded)."""


class _StubDetector:
    """Stands in for the onnxruntime detector inside ObjectDetector: the cars of ``CARS`` as boxes."""

    last_timing = {"inference_ms": 1.0, "preprocess_ms": 0.1, "postprocess_ms": 0.1}

    def __init__(self, meta_of) -> None:
        self.meta_of = meta_of

    def detect(self, frame):
        return list(self.meta_of(frame))


def _frame_meta(robot: str, seq: int):
    from aerodaas.model.types import CameraIntrinsics, FrameMeta, FramePose

    return FrameMeta(robot_id=robot, sensor_id="cam", seq=seq, capture_time=0.2 * seq, wall_time=0.0,
                     pose=FramePose(position=(0.0, 0.0, 20.0), yaw=90.0, camera_pitch=90.0),
                     intrinsics=CameraIntrinsics.from_hfov(320, 240, 60.0))


def _car(x: float):
    from aerodaas.model.types import Detection

    return Detection(class_id=2, class_name="car", score=0.9, box=(x, 100.0, x + 30.0, 120.0))


@pytest.mark.parametrize("kind", ["detector", "follow", "plain_follow"])
def test_the_analytics_component_records_each_drones_tracks_whatever_the_output(kind):
    """ObjectDetector(tracker=...) and FollowAnalytics(tracker=...) hand their tracks to the recorder under
    /<robot>/<name>/tracks on every frame (the follow's output is often None); a follow without a tracker records
    none. Two drones share the analytics: each keeps its own track ids."""
    from aerodaas import ByteTrackConfig, FollowAnalytics, ObjectDetector
    from aerodaas.actors.analytics.component import AnalyticsComponent
    from aerodaas.protocol.messages import DetectionsMsg, FrameMsg

    if kind == "detector":
        obj = ObjectDetector(tracker=ByteTrackConfig())
        obj.setup = lambda: None
        obj.detector = _StubDetector(lambda frame: [_car(frame[0])])
    else:
        obj = FollowAnalytics(target_classes=["car"], tracker=ByteTrackConfig() if kind == "follow" else None)
    rec = _Recorder()
    comp = AnalyticsComponent(_Host(), "c#1", obj.name, obj, rec, epoch_ns=10**18)
    for seq in range(6):
        for robot, x in (("d1", 40.0 + 3 * seq), ("d2", 200.0 - 3 * seq)):
            meta = _frame_meta(robot, seq)
            if kind == "detector":
                msg = FrameMsg(robot=robot, sim_t=meta.capture_time, data=[x], meta=meta, trace={})
            else:
                msg = DetectionsMsg(robot=robot, sim_t=meta.capture_time, data=[_car(x)], meta=meta, trace={})
            comp.handle(None, msg)
    if kind == "plain_follow":
        assert rec.got == []
        return
    assert len(rec.got) == 12
    for robot in ("d1", "d2"):
        mine = [r for r in rec.got if r[2] == robot]
        assert {r[0] for r in mine} == {f"/{robot}/{obj.name}/tracks"}
        assert [[row["track_id"] for row in r[3]] for r in mine] == [[1]] * 6  # one car, one stable id per drone
        assert all(r[4] == (320, 240) and r[3][0]["enu"] is not None for r in mine)
    assert rec.got[0][1] == 10**18  # the frame's log time (epoch + capture time)


def test_bench_tracks_refuses_a_recording_without_truth_or_tracks(tmp_path):
    """`aerodaas bench tracks` on a recording that is not a simulated run with a tracking analytics: exit 2 with the
    reason, no traceback."""

    from aerodaas.recording.writer import McapRecorder

    path = tmp_path / "plain.mcap"
    with McapRecorder(path) as rec:
        rec.write_json("/d1/odometry", 1, {"robot_id": "d1", "position": [0, 0, 20]}, schema_name="aerodaas.Odometry")
    with pytest.raises(ValueError, match="world/targets"):
        score_tracks(str(path))
    p = run_cli("bench", "tracks", str(path))  # in-process: bad input
    assert p.returncode == 2 and "no /world/targets" in p.stdout + p.stderr, (p.stdout, p.stderr)
    p = run_cli("bench", "tracks", str(tmp_path / "none.mcap"))
    assert p.returncode == 2 and "no such file" in p.stdout + p.stderr


@pytest.mark.e2e
def test_the_live_view_advertises_the_track_channels_from_the_start_and_serves_the_tracks(tracks_run):
    """`aerodaas run tests/apps/fleet_tracks.py --live` with a Foxglove protocol client (tests/liveview/foxglove_ws_client.py,
    written from the spec): the track image and scene channels are advertised before the camera's (declared from
    the plan, not created by a first message), the tracks' one LocationFixes channel is advertised with them, and the scene arrives live
    with the track entities."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    from tests.liveview.foxglove_ws_client import schema_bytes

    cli, got = tracks_run["cli"], tracks_run["live"]
    assert cli.returncode == 0, cli.stdout[-3000:] + cli.stderr[-3000:]
    assert got is not None, f"the live client failed: {tracks_run['client_error']!r}"
    scene, cam = "/d1/tracks/tracks/scene", "/d1/camera/cam"
    order = [topic for _t, op, topic in got["timeline"] if op == "advertise"]
    # the declared track channels are advertised no later than the camera's: in an earlier advertise message, or in
    # the same one (a client that connects late gets every channel in one message, in the server's map order)
    first: dict[str, float] = {}
    for t, op, topic in got["timeline"]:
        if op == "advertise":
            first.setdefault(topic, t)
    assert first[scene] <= first[cam] and first["/d1/tracks/tracks"] <= first[cam], got["timeline"]
    # one LocationFixes topic for all of the drone's tracks, declared from the plan as well
    assert "/d1/tracks/tracks/fixes" in order and first["/d1/tracks/tracks/fixes"] <= first[cam], got["timeline"]
    assert not [t for t in order if t.endswith("/fix")], order  # no channel per track any more
    ch = got["channels"][scene]
    assert ch["schemaName"] == "foxglove.SceneUpdate" and ch["encoding"] == "protobuf"
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema_bytes(ch))  # decode with the advertised schema only
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("foxglove.SceneUpdate"))
    msgs = [cls.FromString(d) for _t, d in got["messages"][scene]]
    assert len(msgs) >= 50, len(msgs)
    ids = {e.id for m in msgs for e in m.entities}
    assert ids and all(i.startswith("d1/track/") for i in ids), ids
