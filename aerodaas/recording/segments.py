"""Segmented recordings: when the run's recorder actor dies mid-run, Ray restarts it and the restarted recorder
continues into a new *segment* file next to the first (``RUN.mcap`` -> ``RUN.1.mcap`` -> ``RUN.2.mcap`` ...), since
a new process cannot append to the half-written file of the dead one. ``aerodaas recover RUN.mcap`` finishes every
segment (:func:`aerodaas.recording.recover.recover_mcap`) and joins them, in log-time order of the segments, into
``RUN.mcap`` (:func:`join_segments`); the joined segment files are then removed.

A segment holds the messages its recorder received; what was in flight when the recorder died (its queue, batches
being delivered) is lost, and the run says so ("recording lost at t = ...", exit code 4 of ``aerodaas run``).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from aerodaas.recording.recover import recover_mcap

__all__ = ["segment_path", "list_segments", "next_segment", "remove_stale_segments", "join_segments",
           "message_time_range"]

#: at most this many segments per recording (the recorder actor's restarts are bounded far below it)
MAX_SEGMENTS = 1000


def segment_path(base: str | os.PathLike, k: int) -> Path:
    """Segment ``k`` of the recording ``base``: ``k = 0`` is ``base`` itself, ``RUN.mcap`` -> ``RUN.<k>.mcap``
    (a base without the ``.mcap`` suffix gets ``.<k>`` appended)."""
    p = Path(base)
    if k == 0:
        return p
    if p.suffix == ".mcap":
        return p.with_name(f"{p.stem}.{k}.mcap")
    return p.with_name(f"{p.name}.{k}")


def list_segments(base: str | os.PathLike) -> list[Path]:
    """The existing segments of ``base`` in order: ``base`` (when it exists), then ``RUN.1.mcap``, ``RUN.2.mcap``
    ... up to the first index that does not exist."""
    out = [Path(base)] if Path(base).exists() else []
    for k in range(1, MAX_SEGMENTS):
        p = segment_path(base, k)
        if not p.exists():
            break
        out.append(p)
    return out


def next_segment(base: str | os.PathLike) -> tuple[int, Path]:
    """(index, path) of the first segment of ``base`` that does not exist yet (a restarted recorder writes there)."""
    for k in range(1, MAX_SEGMENTS):
        p = segment_path(base, k)
        if not p.exists():
            return k, p
    raise OSError(f"{base}: {MAX_SEGMENTS} segments exist already")


def remove_stale_segments(base: str | os.PathLike) -> list[Path]:
    """Remove ``RUN.1.mcap``, ``RUN.2.mcap`` ... left by an earlier run recorded to the same ``base`` (a new run
    overwrites ``base``; its segments would otherwise be joined to it). Returns what was removed."""
    gone = []
    for p in list_segments(base)[1:] if Path(base).exists() else []:
        p.unlink()
        gone.append(p)
    if not Path(base).exists():  # base absent: still remove a stale RUN.1.mcap ...
        for k in range(1, MAX_SEGMENTS):
            p = segment_path(base, k)
            if not p.exists():
                break
            p.unlink()
            gone.append(p)
    return gone


def message_time_range(path: str | os.PathLike) -> tuple[int | None, int | None, int]:
    """(first log time ns, last log time ns, message count) of a finished MCAP file, from its summary statistics
    (mcap's reader). (None, None, 0) when the file has no summary or no message."""
    from mcap.reader import make_reader  # lazy: heavy mcap

    with open(path, "rb") as f:
        s = make_reader(f).get_summary()
    if s is None or s.statistics is None or not s.statistics.message_count:
        return None, None, 0
    st = s.statistics
    return st.message_start_time, st.message_end_time, st.message_count


def join_segments(base: str | os.PathLike, out: str | os.PathLike | None = None) -> dict[str, Any]:
    """Finish every segment of ``base`` and write them, one after the other, into one finished MCAP file at
    ``out`` (default ``base``, replaced atomically); the segment files after the first are removed once the joined
    file is in place (unless ``out`` names another file). Schemas and channels are registered once per
    (topic, schema) across segments; messages keep their log/publish times and sequence numbers. Returns
    ``{"segments": [...], "messages": n, "channels": n, "out": path}``. Raises FileNotFoundError (no ``base``),
    ValueError (not an MCAP file) or OSError."""
    from mcap.writer import CompressionType, Writer  # lazy: heavy mcap

    from aerodaas.recording.reader import _open_mcap, _scan_linear  # lazy: heavy mcap

    segs = list_segments(base)
    if not segs or segs[0] != Path(base):
        raise FileNotFoundError(f"{base}: no such recording")
    for p in segs:
        recover_mcap(p)  # a finished segment is left alone
    dst = Path(out) if out is not None else Path(base)
    tmp = dst.with_name(dst.name + ".joining")
    n = 0
    schemas: dict[tuple, int] = {}
    channels: dict[tuple, int] = {}
    metadata: list = []
    with open(tmp, "wb") as o:
        w = Writer(o, compression=CompressionType.ZSTD)
        w.start(profile="", library="aerodaas recover (joined segments)")
        for p in segs:
            f, _ = _open_mcap(p)
            sid_map: dict[int, int] = {}
            cid_map: dict[int, int] = {}
            with f:
                for schema, channel, msg in _scan_linear(f, on_metadata=metadata.append):
                    if schema is not None and schema.id not in sid_map:
                        key = (schema.name, schema.encoding, bytes(schema.data))
                        if key not in schemas:
                            schemas[key] = w.register_schema(schema.name, schema.encoding, schema.data)
                        sid_map[schema.id] = schemas[key]
                    if channel.id not in cid_map:
                        sid = sid_map.get(channel.schema_id, 0) if channel.schema_id else 0
                        key = (channel.topic, channel.message_encoding, sid)
                        if key not in channels:
                            channels[key] = w.register_channel(channel.topic, channel.message_encoding, sid,
                                                               dict(channel.metadata))
                        cid_map[channel.id] = channels[key]
                    w.add_message(cid_map[channel.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
                    n += 1
        seen_meta = set()
        for m in metadata:
            key = (m.name, tuple(sorted(m.metadata.items())))
            if key not in seen_meta:
                seen_meta.add(key)
                w.add_metadata(m.name, dict(m.metadata))
        w.add_metadata("aerodaas.segments", {"joined": ",".join(p.name for p in segs)})
        w.finish()
        o.flush()
        os.fsync(o.fileno())
    os.replace(tmp, dst)
    if out is None:
        for p in segs[1:]:
            p.unlink()
    return {"segments": [str(p) for p in segs], "messages": n, "channels": len(channels), "out": str(dst)}
