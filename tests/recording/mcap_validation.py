"""Validation of AeroDaaS recordings with readers we did not write (used by several test modules).

:func:`validate_recording` reads a file with the ``mcap`` Python reader and decodes every message: protobuf through
mcap-protobuf-support's decoder factory, JSON with ``json.loads``, each JSON message validated with ``jsonschema``
against its own channel's schema; it also checks the schema fields, the transform tree and the camera calibration
that Foxglove needs to show a run fully populated.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from aerodaas.recording.values import camera_mount_quaternion


class JsonDecoderFactory:
    """mcap reader decoder factory for JSON channels (the mcap package ships none)."""

    def decoder_for(self, message_encoding: str, schema):
        return json.loads if message_encoding == "json" else None


def rotation(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def validate_recording(path: Path, robot: str, cameras: dict[str, dict]) -> dict:
    """Validate a recording with the ``mcap`` reader: every message decoded (protobuf via mcap-protobuf-support, JSON
    via json.loads and validated with jsonschema against its channel's schema); JSON schemas declare their fields;
    the transform tree links enu -> base_link -> gps and each camera's optical frame with its mount pitch; each
    camera has a CameraCalibration per image with the configured intrinsics. ``cameras``: sensor id ->
    {"width", "height", "hfov_deg", "pitch_deg"}. Returns per-topic counts, what was checked and, per
    ``foxglove.LocationFixes`` topic of geo-located tracks, the set of track ids it carried (``track_ids``)."""
    import jsonschema

    counts: dict[str, int] = {}
    tf: dict[tuple[str, str], object] = {}
    calib: dict[str, list] = {}
    images: dict[str, list] = {}
    locations: set[str] = set()
    track_ids: dict[str, set[int]] = {}  # geo-located tracks: fixes topic -> the track ids its LocationFixes carry
    validators: dict[int, object] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        for ch in summary.channels.values():
            schema = summary.schemas[ch.schema_id]
            assert schema.name, f"{ch.topic}: no schema name"
            if ch.message_encoding == "json":
                assert schema.encoding == "jsonschema", ch.topic
                js = json.loads(schema.data)
                jsonschema.Draft202012Validator.check_schema(js)
                assert js.get("type") == "object" and js.get("title") == schema.name, (ch.topic, js)
                # real fields for Foxglove's Plot / Raw Message panels (free-form outputs: from their first message)
                assert js.get("properties"), f"{ch.topic} ({schema.name}): JSON schema declares no fields"
                validators[ch.id] = jsonschema.Draft202012Validator(js)
            else:
                assert ch.message_encoding == "protobuf" and schema.encoding == "protobuf", ch.topic
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.message_encoding == "json":
                validators[channel.id].validate(decoded)
                continue
            assert decoded is not None
            if schema.name == "foxglove.FrameTransform":
                tf[(decoded.parent_frame_id, decoded.child_frame_id)] = decoded
            elif schema.name == "foxglove.CameraCalibration":
                calib.setdefault(channel.topic, []).append(decoded)
            elif schema.name == "foxglove.CompressedImage":
                assert decoded.format == "jpeg" and decoded.data[:2] == b"\xff\xd8"
                images.setdefault(channel.topic, []).append(decoded)
            elif schema.name == "foxglove.LocationFixes":
                # geo-located tracks (aerodaas.perception.track_records): each track's WGS-84 fix, with covariance,
                # its colour and its id in the metadata
                assert channel.topic.endswith("/tracks/fixes"), channel.topic
                for fix in decoded.fixes:
                    meta = {kv.key: kv.value for kv in fix.metadata}
                    assert fix.frame_id == "wgs84" and fix.position_covariance_type != 0, channel.topic
                    assert fix.color.a > 0 and meta["track_id"].isdigit(), (channel.topic, meta)
                    track_ids.setdefault(channel.topic, set()).add(int(meta["track_id"]))
            elif schema.name == "foxglove.LocationFix":
                locations.add(decoded.frame_id)
    assert sum(counts.values()) == summary.statistics.message_count  # every message was decoded
    base = f"{robot}/base_link"
    assert ("enu", base) in tf
    assert (base, f"{robot}/gps") in tf and locations == {f"{robot}/gps"}
    for sensor, props in cameras.items():
        frame = f"{robot}/{sensor}"
        mount = tf[(base, frame)]
        q = (mount.rotation.x, mount.rotation.y, mount.rotation.z, mount.rotation.w)
        assert np.allclose(rotation(q), rotation(camera_mount_quaternion(props["pitch_deg"])), atol=1e-9)
        optical_axis = rotation(q) @ np.array([0.0, 0.0, 1.0])  # below the horizon by the mount pitch
        below_horizon = math.degrees(math.asin(max(-1.0, min(1.0, -optical_axis[2]))))
        assert below_horizon == pytest.approx(props["pitch_deg"], abs=1e-6)
        topic = f"/{robot}/camera/{sensor}"
        cal = calib[f"{topic}/calibration"]
        assert len(cal) == len(images[topic]) > 0
        f_px = props["width"] / 2 / math.tan(math.radians(props["hfov_deg"]) / 2)
        c = cal[0]
        assert (c.width, c.height, c.frame_id) == (props["width"], props["height"], frame)
        assert list(c.K) == pytest.approx([f_px, 0, props["width"] / 2, 0, f_px, props["height"] / 2, 0, 0, 1])
        assert list(c.P) == pytest.approx([f_px, 0, props["width"] / 2, 0, 0, f_px, props["height"] / 2, 0, 0, 0, 1, 0])
        assert {i.frame_id for i in images[topic]} == {frame}
    return {"counts": counts, "tf": sorted(tf), "track_ids": track_ids}
