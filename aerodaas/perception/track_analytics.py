"""``TrackAnalytics``: an analytics that turns each drone's detections into ByteTrack tracks with stable ids and
geo-locates them (issue 28, items 3 and 4). Feed it an :class:`~aerodaas.analytics.core.ObjectDetector`'s output
stream; it keeps one :class:`~aerodaas.perception.tracking.ByteTracker` per drone (:meth:`drone_state`)."""
from __future__ import annotations

from typing import Any, Iterable

from aerodaas.analytics.core import Analytics
from aerodaas.app.models import Detection, FrameMeta, GeoPoint
from aerodaas.perception.geolocate import geolocate_box
from aerodaas.perception.tracking import ByteTrackConfig, ByteTracker

__all__ = ["TrackAnalytics"]


class TrackAnalytics(Analytics):
    """Per drone ByteTrack on ``classes`` (None: all) plus the ground position of every active track.

    Output per frame: a list of dicts ``{"robot", "track_id", "class_name", "score", "box"`` (pixels),
    ``"enu"`` ``(x, y, z)`` metres, ``"sigma_m"`` (1-sigma horizontal, metres), ``"lat"``, ``"lon"`` (degrees,
    only with ``home``)``}``, by track id; ``enu`` is None when the box's ray misses the ground. ``ground_z`` is
    the terrain height (m, ENU). Raises ValueError for bad tracker options or an empty ``classes``."""

    name = "tracks"

    def __init__(self, classes: Iterable[str] | str | None = None, tracker: ByteTrackConfig | None = None,
                 home: GeoPoint | None = None, ground_z: float = 0.0, name: str | None = None) -> None:
        from aerodaas.perception.options import normalise_classes

        super().__init__(name)
        self.classes = normalise_classes(classes)
        self.tracker = tracker or ByteTrackConfig()
        self.tracker.check()
        self.home, self.ground_z = home, float(ground_z)

    def check(self) -> None:
        """Pre-flight: the tracker options (ValueError naming the field)."""
        self.tracker.check()

    def process(self, dets: list[Detection], meta: FrameMeta | None) -> list[dict[str, Any]]:
        tr: ByteTracker = self.drone_state(dets, meta, lambda: ByteTracker(self.tracker))
        keep = [d for d in dets if self.classes is None or d.class_name in self.classes]
        out = []
        robot = getattr(meta, "robot_id", "")
        for t in tr.update(keep):
            d = t.detection
            row: dict[str, Any] = {"robot": robot, "track_id": t.track_id, "class_name": d.class_name,
                                   "score": d.score, "box": d.box, "enu": None, "sigma_m": None}
            if meta is not None:
                fix = geolocate_box(d.box, meta.pose, meta.intrinsics, self.home or GeoPoint(lat=0.0, lon=0.0,
                                                                                           alt=0.0),
                                    ground_z=self.ground_z)
                if fix is not None:
                    row["enu"], row["sigma_m"] = fix.enu, fix.sigma_m
                    if self.home is not None:
                        row["lat"], row["lon"] = fix.lat, fix.lon
            out.append(row)
        return out

    def stats(self) -> dict:
        """``tracks_by_drone``: robot id -> track ids created so far."""
        return {"tracks_by_drone": {r: st.next_id - 1 for r, st in self.drone_states().items()}}
