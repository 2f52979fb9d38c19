"""Geo-located tracks: the ground position of a box seen by the simulator's camera model, its
uncertainty, and the Foxglove messages recorded per track (read back with the mcap library)."""
from __future__ import annotations

import numpy as np
import pytest

from aerodaas.model.geo import geodetic_to_enu
from aerodaas.model.types import CameraIntrinsics, FramePose, GeoPoint
from aerodaas.perception.geolocate import geolocate_box, record_track_fixes
from aerodaas.model.camera import project_points

K = CameraIntrinsics.from_hfov(640, 480, 78.0)
HOME = GeoPoint(lat=47.397742, lon=8.545594, alt=488.0)


def _box(pose, xy, half=6.0, bottom=False):
    uv, front = project_points(np.array([[xy[0], xy[1], 0.0]]), pose, K)
    u, v = uv[0]
    return (u - half, v - 2 * half, u + half, v) if bottom else (u - half, v - half, u + half, v + half)


@pytest.mark.parametrize("pitch, bottom", [(90.0, False), (45.0, True)])
def test_ground_position_of_a_known_target_and_its_lat_lon(pitch, bottom):
    pose = FramePose(position=(5.0, -3.0, 20.0), yaw=30.0, camera_pitch=pitch)
    target = (9.0, 4.0) if pitch == 45.0 else (7.0, -1.0)
    fix = geolocate_box(_box(pose, target, bottom=bottom), pose, K, HOME)
    assert fix.enu[:2] == pytest.approx(target, abs=1e-6)
    e, n, _ = geodetic_to_enu(fix.lat, fix.lon, fix.alt, HOME)
    assert (e, n) == pytest.approx(target, abs=1e-3)
    assert 0.0 < fix.sigma_m < 5.0


def test_uncertainty_grows_with_altitude():
    sig = []
    for alt in (10.0, 20.0, 40.0):
        pose = FramePose(position=(0.0, 0.0, alt), yaw=0.0, camera_pitch=90.0)
        sig.append(geolocate_box(_box(pose, (1.0, 1.0)), pose, K, HOME).sigma_m)
    assert sig[0] < sig[1] < sig[2]


def test_fixes_recorded_as_location_fix_and_scene_update(tmp_path):
    from mcap_protobuf.decoder import DecoderFactory
    from mcap.reader import make_reader

    from aerodaas.recording.writer import McapRecorder

    pose = FramePose(position=(0.0, 0.0, 20.0), yaw=0.0, camera_pitch=90.0)
    fixes = {7: geolocate_box(_box(pose, (2.0, 3.0)), pose, K, HOME)}
    path = tmp_path / "r.mcap"
    with McapRecorder(path) as rec:
        record_track_fixes(rec, 1_000_000_000, "d1", fixes)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs = {c.topic: m for _, c, _, m in reader.iter_decoded_messages()}
    (loc,) = msgs["/d1/tracks/fixes"].fixes  # one LocationFixes for all tracks
    assert dict((kv.key, kv.value) for kv in loc.metadata) == {"robot": "d1", "track_id": "7"}
    assert loc.frame_id == "wgs84" and loc.color.a == 1.0
    assert (loc.latitude, loc.longitude) == pytest.approx((fixes[7].lat, fixes[7].lon))
    assert loc.position_covariance[0] == pytest.approx(fixes[7].cov[0, 0]) and loc.position_covariance[0] > 0
    (ent,) = msgs["/d1/tracks/scene"].entities
    assert ent.texts[0].text == "d1 #7" and ent.spheres[0].pose.position.x == pytest.approx(2.0, abs=1e-6)
