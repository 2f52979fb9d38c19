"""What a recording says about its stream cameras (``aerodaas info RUN.mcap``): per camera whose ``source`` was a
video stream, the reader's final counters from ``<topic>/video_stats`` (``aerodaas.VideoStats``) and the
capture-to-hand-off latency of the frames it recorded, from ``<topic>/timing`` (``aerodaas.FrameTiming``).

Simulated, ``backend`` and ``mcap`` cameras record neither channel and are not listed.
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from aerodaas.recording.reader import read_messages

STATS_SUFFIX, TIMING_SUFFIX = "/video_stats", "/timing"


def video_streams(path: str | os.PathLike, channels: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The stream cameras of the recording at ``path``, whose ``channels`` are :func:`summarize_mcap`'s list
    (``topic``, ``schema``, ``count``). Returns, per camera topic (``/<robot>/camera/<id>``) in topic order::

        {"topic": str, "stats": the last VideoStats message (dict) or None (a run that did not end cleanly),
         "frames_timed": int,                         # FrameTiming messages read
         "handoff_ms": {"median", "p99"} or None,     # capture to hand-off (FrameTiming age_ms), ms
         "arrival_ms": {"median", "p99"} or None}     # capture to decoded arrival (arrival_t - capture_t), ms

    Raises ``FileNotFoundError`` / ``ValueError`` as :func:`~aerodaas.recording.reader.read_messages` does."""
    cams: dict[str, dict[str, Any]] = {}
    topics = []
    for c in channels:
        for suffix, schema in ((STATS_SUFFIX, "aerodaas.VideoStats"), (TIMING_SUFFIX, "aerodaas.FrameTiming")):
            if c["topic"].endswith(suffix) and c["schema"] == schema and c["count"]:
                cams.setdefault(c["topic"][:-len(suffix)], {"stats": None, "age": [], "arrival": []})
                topics.append(c["topic"])
    if not cams:
        return []
    for topic, _schema, _t, msg in read_messages(path, topics=topics):
        if not isinstance(msg, dict):
            continue
        if topic.endswith(STATS_SUFFIX):
            cams[topic[:-len(STATS_SUFFIX)]]["stats"] = msg
        else:
            cam = cams[topic[:-len(TIMING_SUFFIX)]]
            if msg.get("age_ms") is not None:
                cam["age"].append(float(msg["age_ms"]))
            if msg.get("arrival_t") is not None and msg.get("capture_t") is not None:
                cam["arrival"].append((float(msg["arrival_t"]) - float(msg["capture_t"])) * 1e3)
    return [{"topic": topic, "stats": c["stats"], "frames_timed": max(len(c["age"]), len(c["arrival"])),
             "handoff_ms": _percentiles(c["age"]), "arrival_ms": _percentiles(c["arrival"])}
            for topic, c in sorted(cams.items())]


def _percentiles(values: list[float]) -> dict[str, float] | None:
    """Median and 99th percentile of ``values`` (ms), rounded to 0.1; None for none."""
    if not values:
        return None
    a = np.asarray(values)
    return {"median": round(float(np.median(a)), 1), "p99": round(float(np.percentile(a, 99)), 1)}


def format_video_streams(streams: list[dict[str, Any]]) -> list[str]:
    """The lines ``aerodaas info`` prints for :func:`video_streams`' result (none for no stream camera): the
    counters (decoded, taken, replaced by a newer frame, not recorded, damaged packets, outages) and the latency."""
    lines = []
    for s in streams:
        st = s["stats"]
        if st is None:
            lines.append(f"  {s['topic']}: no video_stats (the run did not end cleanly)")
        else:
            lines.append(f"  {s['topic']}: {st.get('source', '?')}: {st.get('decoded', 0)} decoded, "
                         f"{st.get('taken', 0)} taken, {st.get('overwritten', 0)} replaced by a newer frame before "
                         f"use, {st.get('not_recorded', 0)} not recorded, {st.get('decode_errors', 0)} damaged packets;"
                         f" {st.get('lost', 0)} outage(s) ({float(st.get('outage_s', 0.0)):.1f} s without video, "
                         f"{st.get('restored', 0)} restored)")
        lines.append("    " + _latency_line(s))
    return lines


def _latency_line(s: dict[str, Any]) -> str:
    """Capture to hand-off from the frames' timing, else from the stats' own latency fields."""
    h, a, st = s["handoff_ms"], s["arrival_ms"], s["stats"] or {}
    if h is not None:
        line = f"capture to hand-off {h['median']:.0f} ms median, {h['p99']:.0f} ms p99 ({s['frames_timed']} frames)"
        if a is not None:
            line += f"; capture to decoded {a['median']:.0f} ms median, {a['p99']:.0f} ms p99"
        return line
    if "latency_ms_median" in st:
        return (f"capture to hand-off {st['latency_ms_median']:.0f} ms median, {st['latency_ms_p99']:.0f} ms p99 "
                f"(the camera's own count; no frame timing recorded)")
    return "capture to hand-off: no frame timing recorded"
