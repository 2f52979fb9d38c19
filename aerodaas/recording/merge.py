"""One run recorded in several MCAP files, merged into one: ``aerodaas merge RUN.mcap RUN.node-*.mcap --out ALL.mcap``.

A run with one recorder per node (``recording.per_node`` in the environment, see ``docs/architecture.md``) leaves
the driver's file ``RUN.mcap`` and one ``RUN.node-<compute>.mcap`` per edge compute (:func:`node_recording_path`).
:func:`merge_recordings` writes them into one finished MCAP file, with the ``mcap`` library:

* schemas are registered once per (name, encoding, data) and channels once per (topic, message encoding, schema),
  so ``/tf`` written on every node is one channel;
* messages keep their log time, publish time and sequence number and are written in log-time order across the
  files (a k-way merge of each file's messages read through its index in log-time order, ``iter_messages
  (log_time_order=True)``; MCAP itself only asks a writer for ordered chunks, section "Chunk");
* each file's ``/run/accounting`` (:class:`~aerodaas.recording.schemas.RunAccounting`) is summed into one, written
  last: per stream the producers' numbers and the duplicates, per analytics what it was offered and took without
  output, per analytics scheduler its task records (:class:`~aerodaas.recording.task_tally.TaskTally`); the
  files' ``/run/recorder_drops`` are summed the same way. A producer records on one node only, so the sum is the
  run's accounting and :func:`aerodaas.recording.accounting.account_recording` of the merged file is the run's
  (produced - duplicates - recorded);
* each file's metadata records are copied once, plus ``aerodaas.merged`` naming the files.

Inputs must be finished recordings (an unfinished one: ``aerodaas recover FILE`` first), so their index gives the
log-time order without reading a whole file into memory.
"""
from __future__ import annotations

import heapq
import json
import os
from pathlib import Path
from typing import Any, Iterator

from aerodaas.recording.record_path import LIBRARY
from aerodaas.recording.task_tally import TaskTally

__all__ = ["merge_recordings", "node_recording_path", "MERGED_METADATA"]

#: the metadata record a merged file names its inputs in (``files``: comma-separated base names)
MERGED_METADATA = "aerodaas.merged"
_SUMMED_TOPICS = ("/run/accounting", "/run/recorder_drops")


def node_recording_path(base: str | os.PathLike, compute: str) -> Path:
    """The file of the recorder of edge compute ``compute`` in a run recorded to ``base``: ``RUN.mcap`` ->
    ``RUN.node-<compute>.mcap`` (a base without ``.mcap``: ``RUN.node-<compute>.mcap`` appended)."""
    p = Path(base)
    stem = p.stem if p.suffix == ".mcap" else p.name
    return p.with_name(f"{stem}.node-{compute}.mcap")


def _messages(path: Path, index: int) -> Iterator[tuple[int, int, int, Any, Any, Any]]:
    """``(log_time, file index, n, schema, channel, message)`` of a finished file, in log-time order (``n`` keeps
    the sort stable and never compares records)."""
    from mcap.reader import make_reader  # lazy: heavy mcap

    with open(path, "rb") as f:
        for n, (schema, channel, msg) in enumerate(make_reader(f).iter_messages(log_time_order=True)):
            yield msg.log_time, index, n, schema, channel, msg


def _check_inputs(paths: list[Path], out: Path) -> None:
    """Raise ValueError (no input, the output among the inputs, a file twice, a foreign or unfinished file) or
    FileNotFoundError naming the file."""
    from aerodaas.recording.reader import _open_mcap  # lazy: heavy mcap

    if not paths:
        raise ValueError("merge needs at least one recording")
    resolved = [p.resolve() for p in paths]
    if len(set(resolved)) != len(resolved):
        raise ValueError(f"a recording is named twice: {[str(p) for p in paths]}")
    if out.resolve() in resolved:
        raise ValueError(f"--out {str(out)!r} is one of the inputs; name a new file")
    for p in paths:
        f, finished = _open_mcap(p)
        f.close()
        if not finished:
            raise ValueError(f"{str(p)!r} is unfinished (its recorder did not close it): run `aerodaas recover {p}` "
                             f"first")


def _sum_accounting(accs: list[dict]) -> dict[str, Any]:
    """The sum of several ``/run/accounting`` messages (see the module docstring)."""
    chans: dict[str, dict[str, int]] = {}
    analytics: dict[str, dict[str, int]] = {}
    tasks = TaskTally()
    for acc in accs:
        for into, src in ((chans, acc.get("channels") or {}), (analytics, acc.get("analytics") or {})):
            for key, counts in src.items():
                mine = into.setdefault(key, {})
                for k, n in counts.items():
                    mine[k] = mine.get(k, 0) + int(n)
        tasks = tasks.merged(TaskTally.from_dict(acc.get("tasks")))
    out: dict[str, Any] = {"channels": dict(sorted(chans.items())), "analytics": dict(sorted(analytics.items()))}
    if tasks.as_dict():
        out["tasks"] = tasks.as_dict()
    return out


def _sum_drops(drops: list[dict]) -> dict[str, Any]:
    per: dict[str, int] = {}
    for d in drops:
        for topic, n in (d.get("frames_dropped") or {}).items():
            per[topic] = per.get(topic, 0) + int(n)
    return {"frames_dropped": dict(sorted(per.items())), "total": sum(per.values())}


class _Registry:
    """Schemas and channels of the merged file, each registered once (see the module docstring)."""

    def __init__(self, writer: Any) -> None:
        self.w = writer
        self.schemas: dict[tuple, int] = {}
        self.channels: dict[tuple, int] = {}
        self._ids: dict[tuple[int, int], int] = {}  # (file index, channel id) -> merged channel id

    def channel(self, index: int, schema: Any, channel: Any) -> int:
        cid = self._ids.get((index, channel.id))
        if cid is not None:
            return cid
        sid = 0
        if schema is not None:
            skey = (schema.name, schema.encoding, bytes(schema.data))
            if skey not in self.schemas:
                self.schemas[skey] = self.w.register_schema(schema.name, schema.encoding, schema.data)
            sid = self.schemas[skey]
        ckey = (channel.topic, channel.message_encoding, sid)
        if ckey not in self.channels:
            self.channels[ckey] = self.w.register_channel(channel.topic, channel.message_encoding, sid,
                                                          dict(channel.metadata))
        self._ids[(index, channel.id)] = cid = self.channels[ckey]
        return cid


def merge_recordings(paths: list[str | os.PathLike], out: str | os.PathLike) -> dict[str, Any]:
    """Merge the finished recordings ``paths`` of one run into ``out`` (written to ``out.merging`` first, then
    renamed into place); see the module docstring. Returns ``{"files": [...], "messages": n, "channels": n,
    "schemas": n, "accounting_files": n (inputs with a ``/run/accounting``), "out": path}``. Raises ValueError
    (bad inputs, see :func:`_check_inputs`), FileNotFoundError or OSError."""
    from mcap.reader import make_reader  # lazy: heavy mcap
    from mcap.writer import CompressionType, Writer  # lazy: heavy mcap

    files = [Path(p) for p in paths]
    dst = Path(out)
    _check_inputs(files, dst)
    summed: dict[str, list[dict]] = {t: [] for t in _SUMMED_TOPICS}
    metadata: dict[tuple, dict] = {}
    for p in files:
        with open(p, "rb") as f:
            r = make_reader(f)
            for m in r.iter_metadata():
                metadata.setdefault((m.name, tuple(sorted(m.metadata.items()))), {"name": m.name, **m.metadata})
    tmp = dst.with_name(dst.name + ".merging")
    n, last_t = 0, 0
    with open(tmp, "wb") as o:
        w = Writer(o, compression=CompressionType.ZSTD)
        w.start(profile="", library=f"{LIBRARY} (merged)")
        reg = _Registry(w)
        for t, index, _, schema, channel, msg in heapq.merge(*(_messages(p, i) for i, p in enumerate(files))):
            if channel.topic in summed:
                summed[channel.topic].append(json.loads(msg.data))
                continue
            w.add_message(reg.channel(index, schema, channel), t, msg.data, msg.publish_time, msg.sequence)
            n, last_t = n + 1, max(last_t, t)
        n += _write_sums(w, reg, summed, last_t)
        for meta in metadata.values():
            name = meta.pop("name")
            w.add_metadata(name, meta)
        w.add_metadata(MERGED_METADATA, {"files": ",".join(p.name for p in files)})
        w.finish()
        o.flush()
        os.fsync(o.fileno())
    os.replace(tmp, dst)
    return {"files": [str(p) for p in files], "messages": n, "channels": len(reg.channels),
            "schemas": len(reg.schemas), "accounting_files": len(summed["/run/accounting"]), "out": str(dst)}


def _write_sums(w: Any, reg: _Registry, summed: dict[str, list[dict]], last_t: int) -> int:
    """Write the summed ``/run/recorder_drops`` and ``/run/accounting`` (the file's last messages, after every
    other one) on channels with the recorder's own JSON schemas; returns how many were written."""
    from aerodaas.recording.schemas import json_schema_for  # lazy: heavy pydantic

    n = 0
    for topic, schema_name, make in (("/run/recorder_drops", "aerodaas.RecorderDrops", _sum_drops),
                                     ("/run/accounting", "aerodaas.RunAccounting", _sum_accounting)):
        if not summed[topic]:
            continue
        body = make(summed[topic])
        schema = json.dumps(json_schema_for(schema_name, body) or {"type": "object"}, sort_keys=True).encode()
        skey = (schema_name, "jsonschema", schema)
        if skey not in reg.schemas:
            reg.schemas[skey] = w.register_schema(schema_name, "jsonschema", schema)
        ckey = (topic, "json", reg.schemas[skey])
        if ckey not in reg.channels:
            reg.channels[ckey] = w.register_channel(topic, "json", reg.schemas[skey])
        cid = reg.channels[ckey]
        t = last_t + 1
        w.add_message(cid, t, json.dumps(body, separators=(",", ":")).encode(), t, 0)
        n += 1
    return n
