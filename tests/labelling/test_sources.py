"""Frames out of recordings and videos: a recording written on the channels ``aerodaas run --record`` writes, its
frames with the pose nearest in time; files that hold no frame are refused naming the file."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from aerodaas.labelling.sources import LabelInputError, McapSource, VideoSource, open_source
from aerodaas.recording.writer import McapRecorder
from tests.labelling.footage import SIZE, scene, write_recording

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "aerial_sample" / "images"


def _frames(n: int) -> list[np.ndarray]:
    return [cv2.resize(cv2.imread(str(p)), (SIZE[1], SIZE[0])) for p in sorted(SAMPLE.glob("*.jpg"))[:n]]


def test_a_recordings_camera_frames_come_out_with_the_pose_nearest_in_time(tmp_path):
    imgs = _frames(4)
    src = McapSource(write_recording(tmp_path / "DJI_0031.mcap", imgs, period_s=1.0))
    src.check()
    assert src.topics == ["/drone1/camera/cam0"] and src.flight == "DJI-0031"
    got = list(src.frames(lambda ref: True))
    assert [r.name for r, _ in got] == [f"DJI-0031_drone1-cam0-{i:06d}" for i in range(4)]
    for (ref, img), orig in zip(got, imgs):
        assert ref.t_s == pytest.approx(ref.index * 1.0)
        assert ref.pose["position"][0] == pytest.approx(10.0 * ref.t_s) and ref.pose["dt_s"] == 0.0
        assert ref.pose["geodetic"]["lat"] == 52.0
        assert img.shape == orig.shape and np.abs(img.astype(int) - orig).mean() < 6  # one JPEG round trip


def test_frames_not_wanted_are_not_decoded_and_a_recording_without_poses_has_none(tmp_path, monkeypatch):
    src = McapSource(write_recording(tmp_path / "r.mcap", [scene(k) for k in range(3)], odometry=False))
    decoded = []
    real = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a: decoded.append(1) or real(*a))
    got = [(r.index, r.pose) for r, _ in src.frames(lambda r: r.index == 1)]
    assert got == [(1, None)] and len(decoded) == 1


def test_a_recording_without_camera_channels_is_refused_naming_it(tmp_path):
    path = tmp_path / "no_camera.mcap"
    with McapRecorder(path) as rec:
        rec.write_pose("/drone1/pose", 1_000, (0.0, 0.0, 10.0), 0.0)
    with pytest.raises(LabelInputError, match=r"no_camera\.mcap'.*no camera channel.*/drone1/pose"):
        McapSource(path).check()


def test_files_that_are_not_footage_are_refused_naming_them(tmp_path):
    bad_video = tmp_path / "broken.mp4"
    bad_video.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 8)
    with pytest.raises(LabelInputError, match=r"video .*broken\.mp4'"):
        VideoSource(bad_video).check()
    bad_mcap = tmp_path / "notes.mcap"
    bad_mcap.write_text("not a recording")
    with pytest.raises(LabelInputError, match=r"recording .*notes\.mcap'.*cannot be read"):
        open_source(bad_mcap)
    with pytest.raises(LabelInputError, match=r"missing\.mp4'.*no such file"):
        open_source(tmp_path / "missing.mp4")
