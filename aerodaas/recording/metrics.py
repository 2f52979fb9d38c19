"""Mission metrics computed from a recording (MCAP): waypoint visits, detection rate against ground truth,
follow switch time and tracking error. Used by the tests and by ``aerodaas info --metrics``."""
from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

import numpy as np

from aerodaas.recording.reader import read_messages


def load_run(path: str) -> dict[str, Any]:
    """Read the JSON channels and detections of a run into plain Python structures (times in sim seconds
    from the first message)."""
    out: dict[str, Any] = defaultdict(list)
    t0 = None
    for topic, schema, t_ns, msg in read_messages(path):
        if t0 is None:
            t0 = t_ns
        t = (t_ns - t0) / 1e9
        if schema == "foxglove.ImageAnnotations":
            boxes = []
            for p in msg.points:
                xs = [q.x for q in p.points]
                ys = [q.y for q in p.points]
                if xs:
                    boxes.append((min(xs), min(ys), max(xs), max(ys)))
            out["detections"].append((t_ns, boxes))
        elif isinstance(msg, dict):
            if topic.endswith("/odometry"):
                out["odometry"].append(msg)
            elif topic == "/world/targets":
                out["targets"].append((t_ns, msg))
            elif topic.endswith("/mission/plan"):
                out["plans"].append(msg)
            elif topic.endswith("/events"):
                out["events"].append(msg)
            elif topic == "/mission/state":
                out["states"].append(msg)
            elif topic == "/mission/result":
                out["result"].append(msg)
            elif schema == "aerodaas.GimbalAttitude":
                out["gimbal"].append(msg)
            elif schema == "aerodaas.FramePose":
                out["frame_poses"].append(msg)
    return dict(out)


def waypoint_visits(odometry: list[dict], waypoints: list[tuple[float, float, float]], radius_m: float = 0.5) -> list[dict]:
    """For each waypoint (ENU metres): closest approach (m) and time spent within ``radius_m`` (s)."""
    pos = np.array([o["position"] for o in odometry])
    t = np.array([o["t"] for o in odometry])
    dt = np.diff(t, append=t[-1])
    res = []
    for w in waypoints:
        d = np.linalg.norm(pos - np.asarray(w), axis=1)
        res.append({"waypoint": w, "closest_m": float(d.min()), "time_within_s": float(dt[d <= radius_m].sum()),
                    "first_within_t": float(t[np.argmax(d <= radius_m)]) if (d <= radius_m).any() else None})
    return res


def _inside(c: tuple[float, float], b: list[float]) -> bool:
    return b[0] <= c[0] <= b[2] and b[1] <= c[1] <= b[3]


def tracking_metrics(run: dict[str, Any], target_id: str) -> dict[str, Any]:
    """Detection rate in frames where ``target_id`` is fully in view (a detection counts when its box centre lies
    in the target's ground-truth box), time from first detection to the follow switch, and horizontal tracking
    error (m) between drone and target while tracking."""
    dets = dict(run.get("detections", []))
    full = hit = 0
    first_det_t = None
    for t_ns, msg in run.get("targets", []):
        tg = next((x for x in msg["targets"] if x["id"] == target_id), None)
        if tg is None or not tg["fully_in_view"]:
            continue
        full += 1
        boxes = dets.get(t_ns, [])
        if any(_inside(((b[0] + b[2]) / 2, (b[1] + b[3]) / 2), tg["bbox_px"]) for b in boxes):
            hit += 1
            if first_det_t is None:
                first_det_t = msg["t"]
    events = run.get("events", [])
    starts = [e["t"] for e in events if e["event"] == "tracking_started"]
    ends = [e["t"] for e in events if e["event"] == "tracking_ended"]
    # drone-target horizontal error while tracking, from odometry and the ground truth
    gt_t = np.array([m["t"] for _, m in run.get("targets", [])])
    gt_xy = [next((x for x in m["targets"] if x["id"] == target_id), None) for _, m in run.get("targets", [])]
    within5 = 0.0
    errs = []
    if starts and gt_t.size:
        t_end = ends[-1] if ends and ends[-1] > starts[0] else math.inf
        odo = [o for o in run.get("odometry", []) if starts[0] <= o["t"] <= t_end]
        for a, b in zip(odo, odo[1:]):
            i = int(np.clip(np.searchsorted(gt_t, a["t"]), 0, len(gt_t) - 1))
            g = gt_xy[i]
            if g is None or not g["present"]:
                continue
            e = math.hypot(a["position"][0] - g["x"], a["position"][1] - g["y"])
            errs.append(e)
            if e <= 5.0:
                within5 += b["t"] - a["t"]
    return {"frames_fully_in_view": full, "frames_detected": hit, "detection_rate": hit / full if full else 0.0,
            "first_detection_t": first_det_t, "tracking_started_t": starts[0] if starts else None,
            "switch_delay_s": (starts[0] - first_det_t) if (starts and first_det_t is not None) else None,
            "tracking_ended_t": ends[-1] if ends else None, "time_within_5m_s": within5,
            "tracking_error_m": {"median": float(np.median(errs)), "max": float(np.max(errs)),
                                 "mean": float(np.mean(errs))} if errs else None}
