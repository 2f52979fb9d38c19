"""Geo-located tracks: a track's ground position from the camera pose, the intrinsics and the
ground plane, as ENU metres and WGS-84 lat/lon with its uncertainty, and its recording as Foxglove
``SceneUpdate`` (3-D) and ``LocationFixes`` (map: one message with every track's ``LocationFix``) messages.

The position is the intersection of the ray through the box's bottom-centre pixel (where a standing object meets
the ground in an oblique view; the centre in a nadir view, where both coincide) with the plane
``z = ground_z`` (:func:`aerodaas.model.camera.pixel_to_ground`, the same pinhole model as the simulator's camera).
The uncertainty is first-order propagation (``Sigma = J S J^T``, J by central differences) of independent errors
on the pixel (``sigma_px`` plus 10 % of the box size: where in the box the object's footprint is), the yaw and the
camera pitch (``sigma_att_deg``) and the height above ground (``sigma_alt_m``); it grows with altitude and with
obliquity, as it should. Lat/lon from ENU: :func:`aerodaas.model.geo.enu_to_geodetic` (pymap3d, WGS-84).
"""
from __future__ import annotations

import colorsys
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerodaas.model.camera import pixel_to_ground
from aerodaas.model.types import CameraIntrinsics, FramePose, GeoPoint

__all__ = ["GroundFix", "geolocate_box", "record_track_fixes", "track_color"]


@dataclass
class GroundFix:
    """A ground position: ``enu`` ``(x, y, z)`` metres from home, ``lat``/``lon`` degrees and ``alt`` metres
    (WGS-84), ``cov`` ``(2, 2)`` ENU horizontal covariance (m^2) and ``sigma_m`` (sqrt of its largest eigenvalue)."""

    enu: tuple[float, float, float]
    lat: float
    lon: float
    alt: float
    cov: np.ndarray
    sigma_m: float


def _ground(u, v, pose: FramePose, k: CameraIntrinsics, ground_z: float, dyaw=0.0, dpitch=0.0, dalt=0.0):
    p = pose.model_copy(update={"yaw": pose.yaw + dyaw, "camera_pitch": pose.camera_pitch + dpitch,
                                "position": (pose.position[0], pose.position[1], pose.position[2] + dalt)})
    g = pixel_to_ground(u, v, p, k, ground_z)
    return None if g is None else np.array(g)


def geolocate_box(box: tuple[float, float, float, float], pose: FramePose, k: CameraIntrinsics, home: GeoPoint, *,
                  ground_z: float = 0.0, nadir: bool | None = None, sigma_px: float = 2.0,
                  sigma_att_deg: float = 1.0, sigma_alt_m: float = 0.5) -> GroundFix | None:
    """Ground position of a pixel box ``(x0, y0, x1, y1)`` seen by camera ``k`` at ``pose`` (ENU metres, yaw and
    camera pitch in degrees, pitch 90 = straight down); ``ground_z`` the terrain height (m, ENU) where known.
    ``nadir`` (default: pitch >= 80 degrees) uses the box centre, else the bottom centre. Returns None when the
    ray does not meet the ground (above the horizon). Raises ValueError for a negative sigma."""
    for n, s in (("sigma_px", sigma_px), ("sigma_att_deg", sigma_att_deg), ("sigma_alt_m", sigma_alt_m)):
        if not s >= 0:
            raise ValueError(f"{n} must be >= 0, got {s!r}")
    x0, y0, x1, y1 = box
    if nadir is None:
        nadir = pose.camera_pitch >= 80.0
    u, v = (x0 + x1) / 2, ((y0 + y1) / 2 if nadir else y1)
    g = _ground(u, v, pose, k, ground_z)
    if g is None:
        return None
    s_u = sigma_px + 0.1 * (x1 - x0)
    s_v = sigma_px + 0.1 * (y1 - y0)
    steps = [(dict(u=1.0), s_u), (dict(v=1.0), s_v), (dict(dyaw=0.1), sigma_att_deg / 0.1),
             (dict(dpitch=0.1), sigma_att_deg / 0.1), (dict(dalt=0.1), sigma_alt_m / 0.1)]
    cols = []
    for d, scale in steps:
        def at(sign):
            kw = {kk: sign * vv for kk, vv in d.items()}
            return _ground(u + kw.pop("u", 0.0), v + kw.pop("v", 0.0), pose, k, ground_z, **kw)
        a, b = at(1.0), at(-1.0)
        cols.append(np.zeros(2) if a is None or b is None else (a - b) / 2 * scale)
    j = np.stack(cols, axis=1)  # (2, 5), each column already scaled by its sigma
    cov = j @ j.T
    from aerodaas.model.geo import enu_to_geodetic  # lazy: heavy pymap3d

    geo = enu_to_geodetic(float(g[0]), float(g[1]), float(ground_z), home)
    return GroundFix((float(g[0]), float(g[1]), float(ground_z)), geo.lat, geo.lon, geo.alt, cov,
                     float(np.sqrt(np.linalg.eigvalsh(cov).max())))


def track_color(track_id: int) -> Any:
    """The colour of track ``track_id`` (a ``foxglove.Color``, alpha 1): golden-ratio steps of the hue (saturation
    0.85, value 1), so neighbouring ids get distinct colours; the same on the image, in the 3-D scene and on the map."""
    from foxglove_schemas_protobuf.Color_pb2 import Color  # lazy: heavy protobuf

    r, g, b = colorsys.hsv_to_rgb((track_id * 0.61803398875) % 1.0, 0.85, 1.0)
    return Color(r=r, g=g, b=b, a=1.0)


def record_track_fixes(recorder, log_time_ns: int, robot_id: str, fixes: dict[int, GroundFix], *,
                       prefix: str | None = None, with_fix: bool = True,
                       classes: dict[int, str] | None = None) -> None:
    """Record one frame's :class:`GroundFix` per track (``fixes``: track id -> fix) on ``recorder``
    (:class:`aerodaas.recording.writer.McapRecorder`), ``prefix`` defaulting to ``/{robot_id}/tracks`` (the runtime
    passes ``/{robot}/{analytics}/tracks``):

    * ``{prefix}/fixes``: one ``foxglove.LocationFixes`` (one topic for all tracks, not a channel per
      track) holding one ``foxglove.LocationFix`` per track, in track id order: frame ``wgs84``, WGS-84 lat/lon
      (degrees) and altitude (m), the ENU horizontal covariance in m^2 (``DIAGONAL_KNOWN`` when the axes are
      uncorrelated else ``KNOWN``), ``color`` :func:`track_color` and ``metadata`` ``robot``, ``track_id`` (decimal
      text) and, when ``classes`` (track id -> class name) names it, ``class_name``. Written on every call, also
      with no track, so the latest message is the current set of tracks (ended tracks leave the map). Schema:
      foxglove/schemas ``LocationFixes.proto`` / ``LocationFix.proto`` (``color`` and ``metadata`` as shipped in
      foxglove-schemas-protobuf 0.4).
    * ``{prefix}/scene``: one ``foxglove.SceneUpdate`` (frame ``enu``) that first deletes every entity of the topic
      (``SceneEntityDeletion`` ``ALL``: a track that ended leaves the scene) and then holds, per track, a flat
      ellipse-sized sphere (2 sigma, the track's colour at alpha 0.5, entity id ``{robot_id}/track/{id}``) and the
      track id as text.

    ``with_fix=False`` writes the scene only (no home known, so no lat/lon)."""
    from foxglove_schemas_protobuf.Color_pb2 import Color  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.LocationFixes_pb2 import LocationFixes  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.Pose_pb2 import Pose  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.SceneEntityDeletion_pb2 import SceneEntityDeletion  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.Vector3_pb2 import Vector3  # lazy: heavy protobuf
    from google.protobuf.timestamp_pb2 import Timestamp  # lazy: heavy protobuf

    prefix = prefix or f"/{robot_id}/tracks"
    stamp = Timestamp(seconds=log_time_ns // 1_000_000_000, nanos=log_time_ns % 1_000_000_000)
    scene = SceneUpdate(deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletion.ALL)])
    located = LocationFixes()
    for tid, f in sorted(fixes.items()):
        c = f.cov
        color = track_color(tid)
        if with_fix:
            cov9 = [c[0, 0], c[0, 1], 0.0, c[1, 0], c[1, 1], 0.0, 0.0, 0.0, 0.0]
            meta = [KeyValuePair(key="robot", value=robot_id), KeyValuePair(key="track_id", value=str(tid))]
            if classes and tid in classes:
                meta.append(KeyValuePair(key="class_name", value=str(classes[tid])))
            located.fixes.append(LocationFix(
                timestamp=stamp, frame_id="wgs84", latitude=f.lat, longitude=f.lon, altitude=f.alt,
                position_covariance=[float(x) for x in cov9],
                position_covariance_type=LocationFix.DIAGONAL_KNOWN if abs(c[0, 1]) < 1e-12 else LocationFix.KNOWN,
                color=color, metadata=meta))
        pose = Pose(position=Vector3(x=f.enu[0], y=f.enu[1], z=f.enu[2]), orientation=Quaternion(w=1.0))
        ent = SceneEntity(timestamp=stamp, frame_id="enu", id=f"{robot_id}/track/{tid}",
                          metadata=[KeyValuePair(key="robot", value=robot_id),
                                    KeyValuePair(key="track_id", value=str(tid)),
                                    KeyValuePair(key="sigma_m", value=f"{f.sigma_m:.3f}")])
        ent.spheres.append(SpherePrimitive(pose=pose, size=Vector3(x=4 * np.sqrt(c[0, 0]), y=4 * np.sqrt(c[1, 1]),
                                                                   z=0.2),
                                           color=Color(r=color.r, g=color.g, b=color.b, a=0.5)))
        ent.texts.append(TextPrimitive(pose=pose, billboard=True, font_size=14.0, scale_invariant=True,
                                       color=Color(r=1.0, g=1.0, b=1.0, a=1.0), text=f"{robot_id} #{tid}"))
        scene.entities.append(ent)
    if with_fix:
        recorder.write_proto(f"{prefix}/fixes", log_time_ns, located)
    recorder.write_proto(f"{prefix}/scene", log_time_ns, scene)
