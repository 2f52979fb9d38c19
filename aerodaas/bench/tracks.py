"""``aerodaas bench tracks RUN.mcap``: score the geo-located tracks recorded in a simulated run against the
simulator's truth ("numbers to report": id switches per 100 frames, geo-location error).

Truth is ``/world/targets`` (written by the simulated camera from its world model at each frame's capture time);
tracks are the ``foxglove.SceneUpdate`` messages on ``/<robot>/<analytics>/tracks/scene`` with the same log time
(:mod:`aerodaas.perception.track_records`). For every frame of a drone whose altitude (``/<robot>/odometry``,
nearest sample) is within ``--altitude``, each target fully in the image is matched to the nearest track's ground
position within ``--gate`` metres:

* geo-location error: the ENU horizontal distance (metres) of each match (median, p95, max);
* id switches: for each (drone, target) the matched track id changing from one matched frame to the next (the
  MOT "IDSW" count, counted on matches only), per 100 scored frames;
* recall: matched / fully-in-view targets.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from collections import defaultdict
from typing import Any

import numpy as np

from aerodaas.bench.machine import machine_info
from aerodaas.bench.output import print_report
from aerodaas.recording.reader import read_messages

__all__ = ["score_tracks", "add_parser"]


def _track_id(entity: Any) -> int:
    meta = {kv.key: kv.value for kv in entity.metadata}
    return int(meta["track_id"]) if "track_id" in meta else int(entity.id.rsplit("/", 1)[-1])


def score_tracks(path: str, *, altitude: tuple[float, float] = (19.0, 21.0), gate_m: float = 3.0) -> dict[str, Any]:
    """Score the recording at ``path`` (module docstring). Returns ``{"frames", "truth_in_view", "matched",
    "recall", "id_switches", "id_switches_per_100_frames", "error_m": {"median", "p95", "max", "n"},
    "per_robot": {robot: {...}}}``. Raises ValueError when the recording has no ``/world/targets`` or no track
    scene (not a simulated run with a tracking analytics)."""
    truth: dict[tuple[str, int], list] = {}
    scenes: dict[tuple[str, int], list] = {}
    alt: dict[str, list[tuple[int, float]]] = defaultdict(list)
    for topic, _schema, t, m in read_messages(path):
        if topic == "/world/targets":
            truth[(m["robot"], t)] = [g for g in m["targets"] if g.get("fully_in_view")]
        elif topic.endswith("/odometry") and isinstance(m, dict):
            alt[m["robot_id"]].append((t, float(m["position"][2])))
        elif topic.endswith("/tracks/scene"):
            scenes[(topic.split("/")[1], t)] = [
                (_track_id(e), np.array([e.spheres[0].pose.position.x, e.spheres[0].pose.position.y]))
                for e in m.entities if e.spheres]
    if not truth:
        raise ValueError(f"{path}: no /world/targets (the simulator's truth): not a simulated run with targets")
    if not scenes:
        raise ValueError(f"{path}: no /<robot>/<analytics>/tracks/scene channel: the run had no tracking analytics")
    alts = {r: (np.array([a for a, _ in v]), np.array([z for _, z in v])) for r, v in alt.items()}
    per: dict[str, dict[str, Any]] = defaultdict(lambda: {"frames": 0, "truth_in_view": 0, "matched": 0,
                                                           "id_switches": 0, "errors": []})
    last_id: dict[tuple[str, str], int] = {}
    for (robot, t), tracks in sorted(scenes.items(), key=lambda kv: kv[0][1]):
        targets = truth.get((robot, t))
        if targets is None or robot not in alts:
            continue
        ts, zs = alts[robot]
        z = zs[int(np.argmin(np.abs(ts - t)))]
        if not altitude[0] <= z <= altitude[1]:
            continue
        s = per[robot]
        s["frames"] += 1
        for g in targets:
            s["truth_in_view"] += 1
            p = np.array([g["x"], g["y"]])
            best = min(tracks, key=lambda tr: float(np.linalg.norm(tr[1] - p)), default=None)
            if best is None or np.linalg.norm(best[1] - p) > gate_m:
                continue
            s["matched"] += 1
            s["errors"].append(float(np.linalg.norm(best[1] - p)))
            key = (robot, g["id"])
            if key in last_id and last_id[key] != best[0]:
                s["id_switches"] += 1
            last_id[key] = best[0]

    def summary(s: dict[str, Any]) -> dict[str, Any]:
        e = np.array(s["errors"] or [np.nan])
        return {"frames": s["frames"], "truth_in_view": s["truth_in_view"], "matched": s["matched"],
                "recall": s["matched"] / s["truth_in_view"] if s["truth_in_view"] else None,
                "id_switches": s["id_switches"],
                "id_switches_per_100_frames": 100.0 * s["id_switches"] / s["frames"] if s["frames"] else None,
                "error_m": {"median": float(np.median(e)), "p95": float(np.percentile(e, 95)),
                            "max": float(np.max(e)), "n": len(s["errors"])}}

    total = {"frames": 0, "truth_in_view": 0, "matched": 0, "id_switches": 0, "errors": []}
    for s in per.values():
        for k in ("frames", "truth_in_view", "matched", "id_switches"):
            total[k] += s[k]
        total["errors"] += s["errors"]
    out = summary(total)
    out.update(altitude_m=list(altitude), gate_m=gate_m, per_robot={r: summary(s) for r, s in sorted(per.items())})
    return out


def main(args: argparse.Namespace) -> int:
    if not os.path.isfile(args.recording):
        print(f"aerodaas bench tracks: recording {args.recording!r}: no such file", file=sys.stderr)
        return 2
    if not args.altitude[0] <= args.altitude[1] or args.gate <= 0:
        print(f"aerodaas bench tracks: --altitude {args.altitude} must be MIN <= MAX and --gate {args.gate} > 0",
              file=sys.stderr)
        return 2
    try:
        rep = score_tracks(args.recording, altitude=tuple(args.altitude), gate_m=args.gate)
    except ValueError as e:
        print(f"aerodaas bench tracks: {e}", file=sys.stderr)
        return 2
    rep = {"recording": os.path.abspath(args.recording), "machine": machine_info(), **rep}
    text = json.dumps(rep, indent=2)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")

    print_report(text)
    return 0
