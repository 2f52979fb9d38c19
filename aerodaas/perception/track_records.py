"""Geo-located tracks in a run's recording: what a tracking analytics hands the recorder and how
the recorder writes it.

An analytics that tracks (:class:`~aerodaas.analytics.track.TrackAnalytics`, or
:class:`~aerodaas.analytics.core.ObjectDetector` / :class:`~aerodaas.analytics.core.FollowAnalytics` with a
``tracker``) owns a :class:`TrackRecords` (``track_records``) that keeps, per drone,
the rows of its last tracker update (:func:`track_rows`); the runtime's analytics component takes them with
``track_records.take(meta)`` after every processed frame (also when the analytics' own output is None, e.g. a follow
that issues no command) and hands them to the recorder, which writes for drone ``robot`` and analytics ``name``,
with ``prefix = /{robot}/{name}/tracks`` (the detections of the same analytics are on ``/{robot}/{name}/detections``):

* ``{prefix}``: ``foxglove.ImageAnnotations``, each track's box and ``#id class`` over the camera image (same log
  time as the frame);
* ``{prefix}/scene``: ``foxglove.SceneUpdate`` in frame ``enu``, one entity per track id (a 2-sigma disc and the id),
  the previous entities deleted first so that ended tracks leave the 3-D view;
* ``{prefix}/fixes``: one ``foxglove.LocationFixes`` per frame for the Map panel, a ``foxglove.LocationFix`` per
  track (WGS-84 from the drone's home, ENU covariance in m^2, the track's colour, metadata ``robot``, ``track_id``,
  ``class_name``); one topic for all tracks (it replaced a ``{prefix}/{id}/fix`` channel per track,
  453 of them on three minutes of real video). Written only when the drone's home is known.

The runtime declares ``{prefix}``, ``{prefix}/scene`` and ``{prefix}/fixes`` for every drone and tracking analytics
of the plan before the run starts (:func:`declared_track_channels`), so the live view advertises them from the first
moment. ``scene`` and ``fixes`` are latched in the live view (:data:`aerodaas.liveview.server.LATCHED_SUFFIXES`): a
late subscriber gets the current scene and the current tracks' fixes.
"""
from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from aerodaas.model.types import FrameMeta, GeoPoint
from aerodaas.perception.geolocate import GroundFix, geolocate_box, record_track_fixes, track_color
from aerodaas.perception.tracking import ByteTracker

__all__ = ["TrackRecords", "records_of", "track_and_keep", "track_rows", "write_tracks", "declared_track_channels",
           "tracks_prefix"]

_ORIGIN = GeoPoint(lat=0.0, lon=0.0, alt=0.0)


def tracks_prefix(robot: str, analytics: str) -> str:
    """``/{robot}/{analytics}/tracks``: the topic prefix of a tracking analytics' recorded tracks."""
    return f"/{robot}/{analytics}/tracks"


def track_rows(tracks: Iterable[Any], meta: FrameMeta | None, *, ground_z: float = 0.0) -> list[dict[str, Any]]:
    """One dict per active ByteTrack track (:class:`aerodaas.perception.tracking.Track`) of the frame ``meta``:
    ``track_id``, ``class_name``, ``score``, ``box`` (pixels ``(x0, y0, x1, y1)``, the associated detection's),
    ``enu`` ``[x, y, z]`` metres from home, ``cov`` ``[[xx, xy], [yx, yy]]`` m^2 (ENU horizontal) and ``sigma_m``
    (1-sigma, metres) from :func:`aerodaas.perception.geolocate.geolocate_box` (``enu``/``cov``/``sigma_m`` None when
    the box's ray misses the ground or ``meta`` is None). ``ground_z``: terrain height, metres ENU."""
    out = []
    for t in tracks:
        d = t.detection
        row: dict[str, Any] = {"track_id": int(t.track_id), "class_name": d.class_name, "score": float(d.score),
                               "box": [float(c) for c in d.box], "enu": None, "cov": None, "sigma_m": None}
        if meta is not None:
            fix = geolocate_box(d.box, meta.pose, meta.intrinsics, _ORIGIN, ground_z=ground_z)
            if fix is not None:
                row.update(enu=list(fix.enu), cov=fix.cov.tolist(), sigma_m=fix.sigma_m)
        out.append(row)
    return out


def write_tracks(recorder: Any, prefix: str, log_time_ns: int, robot: str, rows: list[dict[str, Any]],
                 home: GeoPoint | None, image_size: tuple[int, int] | None = None) -> None:
    """Write one frame's track ``rows`` (:func:`track_rows`) of drone ``robot`` on ``recorder``
    (:class:`aerodaas.recording.writer.McapRecorder`) under ``prefix`` (module docstring); lat/lon from the ENU
    positions and the drone's ``home`` (pymap3d, WGS-84; None: rows are written to the image and scene only).
    ``image_size`` ``(width, height)`` pixels clips the boxes. Raises ValueError for a malformed row."""
    from foxglove_schemas_protobuf.Color_pb2 import Color  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.Point2_pb2 import Point2  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation  # lazy: heavy protobuf
    from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation  # lazy: heavy protobuf

    from aerodaas.model.geo import enu_to_geodetic  # lazy: heavy pymap3d
    from aerodaas.recording.values import _timestamp  # lazy: heavy protobuf

    stamp = _timestamp(log_time_ns)
    ann = ImageAnnotations()
    fixes: dict[int, GroundFix] = {}
    classes: dict[int, str] = {}
    for r in rows:
        tid = int(r["track_id"])
        x0, y0, x1, y1 = (float(c) for c in r["box"])
        if image_size is not None:
            w, h = image_size
            x0, x1 = min(max(x0, 0.0), w), min(max(x1, 0.0), w)
            y0, y1 = min(max(y0, 0.0), h), min(max(y1, 0.0), h)
        color = track_color(tid)
        classes[tid] = str(r["class_name"])
        ann.points.append(PointsAnnotation(
            timestamp=stamp, type=PointsAnnotation.LINE_LOOP, thickness=2.0, outline_color=color,
            points=[Point2(x=x0, y=y0), Point2(x=x1, y=y0), Point2(x=x1, y=y1), Point2(x=x0, y=y1)],
            metadata=[KeyValuePair(key="track_id", value=str(tid)),
                      KeyValuePair(key="class_name", value=str(r["class_name"]))]))
        sigma = r.get("sigma_m")
        label = f"#{tid} {r['class_name']}" + (f" ±{sigma:.1f} m" if sigma is not None else "")
        ann.texts.append(TextAnnotation(timestamp=stamp, position=Point2(x=x0, y=y0), text=label, font_size=14.0,
                                        text_color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
                                        background_color=Color(r=color.r, g=color.g, b=color.b, a=0.6)))
        if r.get("enu") is not None:
            e, n, u = (float(c) for c in r["enu"])
            cov = np.asarray(r["cov"], dtype=float).reshape(2, 2)
            geo = enu_to_geodetic(e, n, u, home) if home is not None else None
            fixes[tid] = GroundFix((e, n, u), geo.lat if geo else float("nan"), geo.lon if geo else float("nan"),
                                   geo.alt if geo else float("nan"), cov, float(sigma or 0.0))
    recorder.write_proto(prefix, log_time_ns, ann)
    record_track_fixes(recorder, log_time_ns, robot, fixes, prefix=prefix, with_fix=home is not None,
                       classes=classes)


def declared_track_channels(robots: Iterable[str], graphs: dict[str, Iterable[Any]]) -> list[tuple[str, str]]:
    """``[(topic, schema)]`` of the track channels known from the plan (``graphs``: robot id -> its analytics):
    ``{prefix}`` (``foxglove.ImageAnnotations``), ``{prefix}/scene`` (``foxglove.SceneUpdate``) and ``{prefix}/fixes``
    (``foxglove.LocationFixes``) for each drone and each of its analytics that tracks (:func:`records_of`)."""
    out: list[tuple[str, str]] = []
    for rid in robots:
        for a in graphs.get(rid, ()):
            if records_of(a) is not None:
                p = tracks_prefix(rid, a.name)
                out += [(p, "foxglove.ImageAnnotations"), (f"{p}/scene", "foxglove.SceneUpdate"),
                        (f"{p}/fixes", "foxglove.LocationFixes")]
    return out


class TrackRecords:
    """The tracks a tracking analytics hands the recorder, one frame per drone: the analytics owns one
    (``analytics.track_records``, None when it does not track) and calls :meth:`keep` after each tracker update;
    the runtime's analytics component takes the frame's rows once with :meth:`take` to record them (module
    docstring). Not thread-safe: one analytics replica processes one frame at a time."""

    def __init__(self) -> None:
        self._kept: dict[str, tuple[int, list[dict[str, Any]]]] = {}

    def keep(self, meta: FrameMeta | None, rows: list[dict[str, Any]]) -> None:
        """Keep ``rows`` (:func:`track_rows`) as drone ``meta.robot_id``'s tracks of frame ``meta.seq`` (nothing
        without ``meta``); replaces that drone's earlier rows."""
        if meta is not None:
            self._kept[meta.robot_id] = (meta.seq, rows)

    def take(self, meta: FrameMeta | None) -> list[dict[str, Any]] | None:
        """The rows kept for the frame ``meta`` (and forgotten), or None when this frame produced none (not
        tracked: another drone's frame, or no ``meta``)."""
        if meta is None:
            return None
        got = self._kept.get(meta.robot_id)
        if got is None or got[0] != meta.seq:
            return None
        del self._kept[meta.robot_id]
        return got[1]


def records_of(analytics: Any) -> TrackRecords | None:
    """The :class:`TrackRecords` of ``analytics`` (its ``track_records``), or None for an analytics that does not
    track (no such attribute, or None: e.g. a follow without ``tracker``)."""
    rec = getattr(analytics, "track_records", None)
    return rec if isinstance(rec, TrackRecords) else None


def track_and_keep(analytics: Any, records: TrackRecords, dets: list, meta: FrameMeta | None, config: Any,
                   classes: Iterable[str] | None = None) -> list:
    """Advance ``analytics``' ByteTracker of the drone of ``meta`` (one per drone, in its
    :meth:`~aerodaas.analytics.core.Analytics.drone_state`) with ``dets`` (only ``classes`` when given), keep the
    geo-located rows for the recorder in ``records`` (:meth:`TrackRecords.keep`) and return the active tracks."""
    tr = analytics.drone_state(dets, meta, lambda: ByteTracker(config))
    keep = dets if classes is None else [d for d in dets if d.class_name in classes]
    active = tr.update(keep)
    records.keep(meta, track_rows(active, meta))
    return active
