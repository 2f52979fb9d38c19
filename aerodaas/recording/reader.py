"""Reading AeroDaaS recordings (MCAP), finished or cut short by a crash.

:func:`read_messages` decodes every message (JSON channels to dicts, Foxglove protobuf channels to message objects);
:func:`summarize_mcap` is what ``aerodaas info FILE.mcap`` prints. A finished file (summary and footer written by
``close()``) is read through its index with mcap's own reader; an unfinished one front to back with mcap's
``StreamReader``, up to the last complete chunk. The writer is :class:`aerodaas.recording.writer.McapRecorder`.
"""
from __future__ import annotations

import io
import json
import os
import struct
from collections.abc import Iterator
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_protobuf.decoder import DecoderFactory as _ProtobufDecoderFactory

from aerodaas.recording.channel_accounts import ACCOUNTING_TOPIC, account_channels, as_report

__all__ = ["read_messages", "summarize_mcap", "MISSION_STATE_TOPIC", "MISSION_RESULT_TOPIC", "METADATA_NAME"]

MISSION_STATE_TOPIC = "/mission/state"
"""JSON topic carrying ``{"state": <str>, ...}`` mission state changes."""
MISSION_RESULT_TOPIC = "/mission/result"
"""JSON topic carrying the final ``{"outcome": <str>, ...}`` of a mission (e.g. ``"success"``)."""
RUN_RESULT_TOPIC = "/run/result"
"""JSON topic carrying the run's own outcome where it differs from its missions' (``{"outcome": "recording_lost",
"losses": [...]}``: the recorder actor died and part of the run was not recorded)."""
METADATA_NAME = "aerodaas"
"""Name of the MCAP metadata record holding the recorder's ``metadata`` dict."""

_MAGIC = bytes((137, 77, 67, 65, 80, 48, 13, 10))
_FOOTER_OPCODE = 0x02
_FOOTER_RECORD_SIZE = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, summary_crc

# Errors a truncated (crashed) recording can raise while being read linearly.
_TRUNCATION_ERRORS = (McapError, EOFError, struct.error, ValueError, MemoryError, UnicodeDecodeError)
try:  # zstandard's own error type is not a ValueError subclass
    import zstandard as _zstd

    _TRUNCATION_ERRORS = _TRUNCATION_ERRORS + (_zstd.ZstdError,)
except ImportError:  # pragma: no cover - zstandard is a dependency of mcap
    pass


# --------------------------------------------------------------------------------------------------------------
def _is_finished(f: Any) -> bool:
    """True if the file ends with a footer record followed by the MCAP magic (i.e. ``close()`` ran)."""
    f.seek(0, io.SEEK_END)
    size = f.tell()
    if size < 2 * len(_MAGIC) + _FOOTER_RECORD_SIZE:
        return False
    f.seek(size - len(_MAGIC) - _FOOTER_RECORD_SIZE)
    tail = f.read(len(_MAGIC) + _FOOTER_RECORD_SIZE)
    return (tail[0] == _FOOTER_OPCODE and tail[-len(_MAGIC):] == _MAGIC
            and struct.unpack_from("<Q", tail, 1)[0] == _FOOTER_RECORD_SIZE - 9)


def _check_magic(f: Any, path: Any) -> None:
    f.seek(0)
    head = f.read(len(_MAGIC))
    if head != _MAGIC:
        raise ValueError(f"{str(path)!r} is not an MCAP file (bad magic bytes {head[:8]!r})")
    f.seek(0)


def _scan_linear(f: Any, on_metadata: Any = None, on_chunk: Any = None) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """Read records front to back, tolerating a truncated tail: yields ``(schema, channel, message)`` in file
    order and stops quietly at the first incomplete/corrupt record (the unfinished last chunk of a crash)."""
    f.seek(0)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    records = StreamReader(f, skip_magic=False, emit_chunks=True).records
    while True:
        try:
            record = next(records)
        except StopIteration:
            return
        except _TRUNCATION_ERRORS:
            return
        if isinstance(record, Chunk):
            try:
                inner = breakup_chunk(record, validate_crc=True)
            except _TRUNCATION_ERRORS:
                return
            if on_chunk is not None:
                on_chunk(record)
        else:
            inner = [record]
        for rec in inner:
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Message):
                channel = channels.get(rec.channel_id)
                if channel is None:  # corrupt file: message before its channel
                    return
                yield (schemas.get(channel.schema_id) if channel.schema_id else None), channel, rec
            elif isinstance(rec, Metadata) and on_metadata is not None:
                on_metadata(rec)


def _iter_raw(f: Any, topics: list[str] | None, finished: bool
              ) -> Iterator[tuple[Schema | None, Channel, Message]]:
    if finished:
        reader = make_reader(f)
        yield from reader.iter_messages(topics=topics, log_time_order=True)
        return
    wanted = None if topics is None else set(topics)
    for schema, channel, message in _scan_linear(f):
        if wanted is None or channel.topic in wanted:
            yield schema, channel, message


class _Decoder:
    """Decodes message bytes per channel: JSON -> dict, protobuf -> message object, anything else -> bytes."""

    def __init__(self) -> None:
        self._pb = _ProtobufDecoderFactory()
        self._cache: dict[int, Any] = {}

    def __call__(self, schema: Schema | None, channel: Channel, message: Message) -> Any:
        dec = self._cache.get(channel.id)
        if dec is None:
            if channel.message_encoding == "json":
                dec = json.loads
            else:
                dec = self._pb.decoder_for(channel.message_encoding, schema) or bytes
            self._cache[channel.id] = dec
        return dec(message.data)


def _open_mcap(path: Any) -> Any:
    f = open(path, "rb")  # noqa: SIM115 - caller closes
    try:
        _check_magic(f, path)
        finished = _is_finished(f)
        f.seek(0)
    except BaseException:
        f.close()
        raise
    return f, finished


def read_messages(path: str | os.PathLike, topics: list[str] | None = None
                  ) -> Iterator[tuple[str, str, int, Any]]:
    """Iterate ``(topic, schema_name, log_time_ns, decoded)`` over an MCAP file.

    ``decoded`` is a ``dict`` (or other JSON value) for JSON channels, a protobuf message object for protobuf
    channels (e.g. ``foxglove.LocationFix`` with ``.latitude``), and the raw ``bytes`` for other encodings.
    ``topics`` restricts to those topics (``None`` = all). ``schema_name`` is ``""`` for schemaless channels.

    Finished files are read through their index in log-time order. Unfinished files (the recorder crashed
    before ``close()``) are read front to back in write order, up to the last complete chunk.

    Raises ``FileNotFoundError`` if ``path`` does not exist and ``ValueError`` if it is not an MCAP file.
    """
    f, finished = _open_mcap(path)
    decode = _Decoder()
    with f:
        for schema, channel, message in _iter_raw(f, topics, finished):
            yield (channel.topic, schema.name if schema is not None else "", message.log_time,
                   decode(schema, channel, message))


def summarize_mcap(path: str | os.PathLike) -> dict[str, Any]:
    """Summarize a recording (what ``aerodaas info FILE.mcap`` shows).

    Returns a dict::

        {"path": str, "finished": bool,            # finished: summary/footer present (close() ran)
         "start_ns": int | None, "end_ns": int | None,   # first/last message log time (None if no messages)
         "duration_s": float,                      # (end_ns - start_ns) / 1e9, 0.0 without messages
         "message_count": int,
         "channels": [{"topic", "schema", "encoding", "count", "rate_hz"}, ...],  # sorted by topic
         "metadata": {str: str},                   # the "aerodaas" metadata record (others merged, prefixed
                                                   #  "<record name>." if not "aerodaas")
         "mission": {"outcome": str | None, "final_state": str | None} | None}

    ``rate_hz`` is ``count / duration_s`` over the whole recording (0.0 when the duration is 0). ``mission``
    comes from the last JSON message on ``"/run/result"`` if there is one (the run's own outcome, e.g.
    ``recording_lost``), else on ``"/mission/result"`` (key ``"outcome"``), and on ``"/mission/state"``
    (key ``"state"``); it is ``None`` when neither topic has messages.

    Finished files are summarized from their summary section; unfinished (crashed) files are scanned front to
    back up to the last complete chunk and reported with ``finished=False``.

    ``accounting`` is the recording's per-channel accounting (:mod:`aerodaas.recording.accounting`: produced,
    duplicates, recorded, lost, from ``/run/accounting`` and the file's own counts; ``lost``: the channels that
    lost any; None for a file without ``/run/accounting``); ``accounting_message`` the raw message.

    Raises ``FileNotFoundError`` if ``path`` does not exist and ``ValueError`` if it is not an MCAP file.
    """
    f, finished = _open_mcap(path)
    with f:
        scan = _ScanResult()
        if finished:
            finished = _scan_summary(f, scan)
        if not finished:
            _scan_records(f, scan)
    return _summary_dict(path, scan, finished)


#: topics whose last JSON message the summary reads (the run's and its missions' outcome, the accounting)
_SUMMARY_TOPICS = (RUN_RESULT_TOPIC, MISSION_RESULT_TOPIC, MISSION_STATE_TOPIC, "/run/accounting")


class _ScanResult:
    """What :func:`summarize_mcap` gathers from a file: channel id -> {topic, schema, encoding} and count, the
    message count and time range, the metadata, and the last JSON message of each of :data:`_SUMMARY_TOPICS`."""

    def __init__(self) -> None:
        self.channels: dict[int, dict[str, Any]] = {}
        self.counts: dict[int, int] = {}
        self.message_count = 0
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.metadata: dict[str, str] = {}
        self.last_json: dict[str, Any] = {}

    def add_metadata(self, rec: Metadata) -> None:
        for k, v in rec.metadata.items():
            self.metadata[k if rec.name == METADATA_NAME else f"{rec.name}.{k}"] = v

    def add_channel(self, cid: int, ch: Channel, schema: Schema | None) -> None:
        self.channels[cid] = {"topic": ch.topic, "schema": schema.name if schema else "",
                              "encoding": ch.message_encoding}


def _scan_summary(f: Any, scan: _ScanResult) -> bool:
    """Fill ``scan`` from a finished file's summary section (and the last message of each summary topic through
    the index); False when the summary cannot be read (then the file is scanned as unfinished)."""
    try:
        reader = make_reader(f)
        summary = reader.get_summary()
    except _TRUNCATION_ERRORS:
        return False
    if summary is None or summary.statistics is None:
        return False
    stats = summary.statistics
    scan.message_count = stats.message_count
    if stats.message_count:
        scan.start_ns, scan.end_ns = stats.message_start_time, stats.message_end_time
    for cid, ch in summary.channels.items():
        scan.add_channel(cid, ch, summary.schemas.get(ch.schema_id))
    scan.counts = dict(stats.channel_message_counts)
    for rec in reader.iter_metadata():
        scan.add_metadata(rec)
    present = [t for t in _SUMMARY_TOPICS if any(c["topic"] == t and scan.counts.get(cid)
                                                 for cid, c in scan.channels.items())]
    for topic in present:
        for _schema, ch, msg in reader.iter_messages(topics=[topic], log_time_order=True, reverse=True):
            if ch.message_encoding == "json":
                scan.last_json[topic] = _safe_json(msg.data)
            break
    return True


def _scan_records(f: Any, scan: _ScanResult) -> None:
    """Fill ``scan`` reading an unfinished (crashed) file front to back, up to its last complete chunk."""
    last_time: dict[str, int] = {}
    for schema, ch, msg in _scan_linear(f, on_metadata=scan.add_metadata):
        if ch.id not in scan.channels:
            scan.add_channel(ch.id, ch, schema)
        scan.counts[ch.id] = scan.counts.get(ch.id, 0) + 1
        scan.message_count += 1
        t = msg.log_time
        scan.start_ns = t if scan.start_ns is None else min(scan.start_ns, t)
        scan.end_ns = t if scan.end_ns is None else max(scan.end_ns, t)
        if ch.topic in _SUMMARY_TOPICS and ch.message_encoding == "json" and t >= last_time.get(ch.topic, -1):
            last_time[ch.topic] = t
            scan.last_json[ch.topic] = _safe_json(msg.data)


def _summary_dict(path: Any, scan: _ScanResult, finished: bool) -> dict[str, Any]:
    """The dict :func:`summarize_mcap` returns, from what was scanned."""
    start_ns, end_ns = scan.start_ns, scan.end_ns
    duration_s = (end_ns - start_ns) / 1e9 if start_ns is not None and end_ns is not None else 0.0
    channels = []
    for cid, info in scan.channels.items():
        n = int(scan.counts.get(cid, 0))
        channels.append({**info, "count": n, "rate_hz": (n / duration_s) if duration_s > 0 else 0.0})
    channels.sort(key=lambda c: (c["topic"], c["schema"]))
    last_json = scan.last_json
    mission = None
    if any(t in last_json for t in (RUN_RESULT_TOPIC, MISSION_RESULT_TOPIC, MISSION_STATE_TOPIC)):
        result = last_json.get(RUN_RESULT_TOPIC) or last_json.get(MISSION_RESULT_TOPIC)  # the run's outcome wins
        state = last_json.get(MISSION_STATE_TOPIC)
        mission = {"outcome": result.get("outcome") if isinstance(result, dict) else None,
                   "final_state": state.get("state") if isinstance(state, dict) else None}
    counts: dict[str, int] = {}
    for c in channels:
        counts[c["topic"]] = counts.get(c["topic"], 0) + c["count"]
    acc = account_channels(last_json.get(ACCOUNTING_TOPIC), counts)
    return {"path": str(path), "duration_s": duration_s, "start_ns": start_ns, "end_ns": end_ns,
            "message_count": int(scan.message_count), "channels": channels, "metadata": scan.metadata,
            "mission": mission, "finished": bool(finished), "accounting": None if acc is None else as_report(acc),
            "accounting_message": last_json.get(ACCOUNTING_TOPIC)}


def _safe_json(data: bytes) -> Any:
    try:
        return json.loads(data)
    except (ValueError, UnicodeDecodeError):
        return None
