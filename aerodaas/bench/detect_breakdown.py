"""Breakdowns of ``aerodaas bench detect``: recall, precision (IoU 0.5) and AP50 per class by
object size (COCO small < 32², medium < 96², large, in pixels of the frame as scored; rule in
:mod:`aerodaas.perception.breakdown`) and, where the set records it per frame (HIT-UAV file names), by camera view
angle and by flight altitude (one bucket per recorded value), for the JSON report and the printed table.

JSON, per result row: ``by_size`` ``{class: {"small"|"medium"|"large": stats}}``, and when recorded
``by_view_angle`` / ``by_altitude`` ``{class: {"<degrees>"|"<metres>": stats}}``; ``stats`` is ``{"n_gt", "n_det",
"recall@0.5", "precision@0.5", "ap50"}`` (``n_det``: detections counted in the bucket).
"""
from __future__ import annotations

from aerodaas.perception.breakdown import SIZE_BUCKETS, FrameMeta, score_area
from aerodaas.perception.scoring import ClassScore, GroundTruth, score


def _stats(s: ClassScore) -> dict:
    return {"n_gt": s.n_gt, "n_det": s.n_det, "recall@0.5": round(s.recall, 3),
            "precision@0.5": round(s.precision, 3), "ap50": round(s.ap, 3)}


def _by_frame(kept: list[tuple[list, GroundTruth]], classes: list[str], key: dict[str, float]) -> dict:
    values = sorted(set(key.values()))
    return {c: {f"{v:g}": _stats(score([p for p in kept if key.get(p[1].file) == v], c, 0.5)) for v in values}
            for c in classes}


def breakdown(kept: list[tuple[list, GroundTruth]], classes: list[str], metas: dict[str, FrameMeta]) -> dict:
    """``by_size`` and (where ``metas`` records them) ``by_view_angle`` / ``by_altitude`` for the ``(detections,
    ground truth)`` pairs ``kept`` (detections already cut at the row's score threshold)."""
    out = {"by_size": {c: {name: _stats(score_area(kept, c, 0.5, lo, hi)) for name, lo, hi in SIZE_BUCKETS}
                       for c in classes}}
    angle = {f: m.view_angle_deg for f, m in metas.items() if m.view_angle_deg is not None}
    alt = {f: m.altitude_m for f, m in metas.items() if m.altitude_m is not None}
    if angle:
        out["by_view_angle"] = _by_frame(kept, classes, angle)
    if alt:
        out["by_altitude"] = _by_frame(kept, classes, alt)
    return out


_TITLES = (("by_size", "size"), ("by_view_angle", "view angle deg"), ("by_altitude", "altitude m"))


def breakdown_lines(row: dict) -> list[str]:
    """Indented table lines of one result row's breakdowns: ``  size small  car: R 0.50 P 0.40 AP50 0.30 (n 12)``."""
    lines = []
    for field, title in _TITLES:
        for c, buckets in row.get(field, {}).items():
            for name, v in buckets.items():
                if v["n_gt"] or v["n_det"]:
                    lines.append(f"  {title} {name:>6} {c}: R {v['recall@0.5']:.2f} P {v['precision@0.5']:.2f} "
                                 f"AP50 {v['ap50']:.2f} (n {v['n_gt']}, det {v['n_det']})")
    return lines
