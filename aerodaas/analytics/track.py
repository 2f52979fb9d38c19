"""``TrackAnalytics``: an analytics that turns each drone's detections into ByteTrack tracks with stable ids and
geo-locates them. Feed it an :class:`~aerodaas.analytics.core.ObjectDetector`'s output
stream; it keeps one :class:`~aerodaas.perception.tracking.ByteTracker` per drone (:meth:`drone_state`)."""
from __future__ import annotations

from typing import Any, Iterable

from aerodaas.analytics.core import Analytics
from aerodaas.model.types import Detection, FrameMeta, GeoPoint
from aerodaas.model.geo import enu_to_geodetic
from aerodaas.perception.detector_values import normalise_classes
from aerodaas.perception.track_records import TrackRecords, track_rows
from aerodaas.perception.tracking import ByteTrackConfig, ByteTracker

__all__ = ["TrackAnalytics"]


class TrackAnalytics(Analytics):
    """Per drone ByteTrack on ``classes`` (None: all) plus the ground position of every active track; in a run
    the tracks are also recorded (:mod:`aerodaas.perception.track_records`: image annotations, 3-D scene and one
    ``LocationFixes`` of all tracks under ``/{robot}/{name}/tracks``).

    Output per frame: a list of dicts ``{"robot", "track_id", "class_name", "score", "box"`` (pixels),
    ``"enu"`` ``(x, y, z)`` metres, ``"sigma_m"`` (1-sigma horizontal, metres), ``"lat"``, ``"lon"`` (degrees,
    only with ``home``)``}``, by track id; ``enu`` is None when the box's ray misses the ground. ``ground_z`` is
    the terrain height (m, ENU). Raises ValueError for bad tracker options or an empty ``classes``."""

    name = "tracks"
    #: fed by an :class:`~aerodaas.analytics.core.ObjectDetector` (checked when the application is loaded, before
    #: Ray starts); its output stream carries the track rows above, type ``"tracks"``
    consumes, produces = ("detections",), ("tracks",)

    def __init__(self, classes: Iterable[str] | str | None = None, tracker: ByteTrackConfig | None = None,
                 home: GeoPoint | None = None, ground_z: float = 0.0, name: str | None = None) -> None:
        super().__init__(name)
        self.classes = normalise_classes(classes)
        self.tracker = tracker or ByteTrackConfig()
        self.tracker.check()
        self.home, self.ground_z = home, float(ground_z)
        self.track_records = TrackRecords()  # the rows the runtime records (aerodaas.perception.track_records)

    def check(self) -> None:
        """Pre-flight: the tracker options (ValueError naming the field)."""
        self.tracker.check()

    def process(self, dets: list[Detection], meta: FrameMeta | None) -> list[dict[str, Any]]:
        """One frame's detections ``dets`` (pixel boxes) and the frame's ``meta`` (its drone, camera pose and
        intrinsics; None: no ground position) into this drone's ByteTrack update: the detections of ``classes``
        update the drone's tracker, and every active track becomes one row (fields in the class docstring), by
        track id; ``[]`` when no track is active. The rows are also kept for the recorder
        (:meth:`~aerodaas.perception.track_records.TrackRecords.keep`)."""
        tr: ByteTracker = self.drone_state(dets, meta, lambda: ByteTracker(self.tracker))
        keep = [d for d in dets if self.classes is None or d.class_name in self.classes]
        robot = getattr(meta, "robot_id", "")
        rows = track_rows(tr.update(keep), meta, ground_z=self.ground_z)
        self.track_records.keep(meta, rows)  # recorded by the runtime (aerodaas.perception.track_records)
        out = []
        for r in rows:
            row: dict[str, Any] = {"robot": robot, "track_id": r["track_id"], "class_name": r["class_name"],
                                   "score": r["score"], "box": tuple(r["box"]),
                                   "enu": None if r["enu"] is None else tuple(r["enu"]), "sigma_m": r["sigma_m"]}
            if r["enu"] is not None and self.home is not None:
                geo = enu_to_geodetic(*r["enu"], self.home)
                row["lat"], row["lon"] = geo.lat, geo.lon
            out.append(row)
        return out

    def stats(self) -> dict:
        """``tracks_by_drone``: robot id -> track ids created so far."""
        return {"tracks_by_drone": {r: st.next_id - 1 for r, st in self.drone_states().items()}}
