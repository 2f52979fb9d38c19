"""``aerodaas recover FILE``: rewrite an unfinished MCAP recording (the process was killed, the disk filled up)
into a finished, indexed one.

An unfinished file has no summary section, no chunk and message indexes and no footer, so readers that seek
(``mcap.reader.make_reader(f).iter_messages()`` on a seekable stream, ``get_summary()``, Foxglove's file reader)
reject it or see nothing. Every record up to the last complete chunk is read front to back (the same tolerant scan
as ``aerodaas info``), and written again with mcap's own :class:`mcap.writer.Writer` — schemas, channels, messages
(raw bytes, log and publish times, sequence numbers) and metadata records unchanged — which adds the indexes, the
statistics and the footer. The result replaces ``FILE`` atomically (``os.replace``) unless ``--out`` names another
file; a finished input is left alone.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

__all__ = ["recover_mcap"]


def recover_mcap(path: str | os.PathLike, out: str | os.PathLike | None = None) -> dict[str, Any]:
    """Rewrite ``path`` (unfinished MCAP) as a finished one at ``out`` (default: in place). Returns
    ``{"path", "was_finished", "messages", "channels", "out"}``. Raises FileNotFoundError, ValueError (not an MCAP
    file) or OSError (cannot write the output)."""
    from mcap.writer import CompressionType, Writer  # lazy: heavy mcap

    from aerodaas.recording.reader import _open_mcap, _scan_linear  # lazy: heavy mcap

    src = Path(path)
    dst = Path(out) if out is not None else src
    f, finished = _open_mcap(src)
    with f:
        if finished and dst == src:
            return {"path": str(src), "was_finished": True, "messages": None, "channels": None, "out": str(dst)}
        tmp = dst.with_name(dst.name + ".recovering")
        metadata: list = []
        n = 0
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        with open(tmp, "wb") as o:
            w = Writer(o, compression=CompressionType.ZSTD)
            w.start(profile="", library="aerodaas recover")
            for schema, channel, msg in _scan_linear(f, on_metadata=metadata.append):
                if schema is not None and schema.id not in schema_ids:
                    schema_ids[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                if channel.id not in channel_ids:
                    channel_ids[channel.id] = w.register_channel(
                        channel.topic, channel.message_encoding,
                        schema_ids.get(channel.schema_id, 0) if channel.schema_id else 0, dict(channel.metadata))
                w.add_message(channel_ids[channel.id], msg.log_time, msg.data, msg.publish_time, msg.sequence)
                n += 1
            for m in metadata:
                w.add_metadata(m.name, dict(m.metadata))
            w.finish()
            o.flush()
            os.fsync(o.fileno())
    os.replace(tmp, dst)
    return {"path": str(src), "was_finished": finished, "messages": n, "channels": len(channel_ids), "out": str(dst)}
