"""The run's MCAP writer, living in the edge actor process (no extra Ray worker, no copy of the frames).

Every component hands it messages with non-blocking calls; a writer thread JPEG-encodes frames and writes
everything through :class:`aerodaas.recording.writer.McapRecorder` (zstd chunks, flushed as chunks complete and at
least every ``flush_every_s`` seconds, so a crash loses at most the last couple of seconds). With a live view
(``aerodaas run --live``) the same writer also feeds a :class:`aerodaas.liveview.server.LiveServer`: every message is
serialized once and goes to the file and to the Foxglove WebSocket clients.

Components on other actors (analytics deployed on cloud compute) record through a
:class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder`, which batches their messages to the edge actor's recorder.

Frames of reference written for Foxglove's transform tree (on ``/tf``, with every odometry message, so a client
that joins late or seeks gets them too): ``enu`` -> ``<robot>/base_link`` (the vehicle's pose),
``<robot>/base_link`` -> ``<robot>/gps`` (the GPS antenna, at the body origin) and ``<robot>/base_link`` ->
``<robot>/<camera>`` (each camera's optical frame, pitched by its mount, see
:func:`aerodaas.recording.values.camera_mount_quaternion`). Each image is accompanied by a ``foxglove.CameraCalibration``
on ``<image topic>/calibration`` with the camera's intrinsics.

A failing disk (full, I/O error, gone) stops the recording cleanly instead of killing the writer thread: the file
is cut back to the last record boundary the OS accepted and finished if the disk still takes the summary (else it
stays unfinished, readable by ``aerodaas info`` and made whole by ``aerodaas recover``); the failure is reported
to ``on_failure`` callbacks (the drones record it as a ``recording_failed`` event) and in :meth:`report`, and every
message offered afterwards is counted as lost. ``AERODAAS_FAULT_RECORDER=enospc:N`` (or ``eio:N``) injects that
failure once N bytes have been written (the fault suite of :mod:`aerodaas.reliability.catalogue`).
"""
from __future__ import annotations

import errno
import os
import queue
import threading
import time
from typing import Any, Callable, NamedTuple

import numpy as np

from aerodaas.model.types import GeoPoint
from aerodaas.perception.track_records import write_tracks
from aerodaas.protocol.messages import (ProducerLedger, RecordCamera, RecordDetections, RecordImage, RecordItem,
                                       RecordJson, RecordOdometry, RecordTracks)
from aerodaas.recording.channel_accounts import ACCOUNTING_TOPIC, account_channels, accounting_message
from aerodaas.recording.reader import RUN_RESULT_TOPIC
from aerodaas.recording.recover import recover_mcap
from aerodaas.recording.task_tally import TASK_SCHEMA, TaskTally
from aerodaas.recording.writer import McapRecorder
from aerodaas.recording.values import camera_mount_quaternion
from aerodaas.actors.recording.remote_recorder import AnalyticsAccounting, AnalyticsCounts, FrameHold

TF_TOPIC = "/tf"


class _Newest(NamedTuple):
    """The newest odometry sample or frame written on one channel: its stamp (ns), sequence number and producer
    incarnation (:meth:`RecorderService._duplicate`)."""

    t_ns: int
    seq: int
    incarnation: int


class _Stop:
    """The writer thread's last queue item (:meth:`RecorderService.close`)."""


_STOP = _Stop()


class RecorderService(AnalyticsAccounting):
    """Asynchronous recorder. ``max_pending_frames`` bounds the frames waiting to be encoded: beyond it new frames
    are dropped and counted (``frames_dropped``) instead of growing memory or slowing the camera (in a simulated run,
    :meth:`image` first waits for room up to ``hold_s`` wall seconds in all, :class:`~aerodaas.actors.recording.remote_recorder.FrameHold`); JSON and
    telemetry messages are never dropped. Each frame written is JPEG-encoded exactly once, counted as
    ``recorder_jpeg_encoded`` in ``copies`` (the actor's :class:`~aerodaas.actors.data.plane.FrameCopies`) when given. All methods are
    thread-safe and return at once, but :meth:`image` with a hold, which may wait for room.

    ``homes``: robot id -> its home (a :class:`~aerodaas.model.types.GeoPoint` or its dict), for the lat/lon of
    recorded tracks. ``declare``: ``[(topic, schema)]`` of protobuf channels known from the plan (the track channels,
    :func:`aerodaas.perception.track_records.declared_track_channels`), registered in the file and advertised by the
    live view before the first message. ``json_schemas``: the plug-ins' message schemas (schema name -> JSON
    Schema, :class:`~aerodaas.recording.writer.McapRecorder`)."""

    def __init__(self, path: str | None, metadata: dict[str, str] | None = None, jpeg_quality: int = 80,
                 max_pending_frames: int = 8, flush_every_s: float = 2.0, copies: Any = None,
                 live: str | None = None, homes: dict[str, Any] | None = None,
                 declare: list[tuple[str, str]] | None = None, live_access: Any = None,
                 json_schemas: dict[str, dict] | None = None, hold_s: float = 0.0) -> None:
        self.homes = {r: GeoPoint.model_validate(h) for r, h in (homes or {}).items()}
        self.rec = McapRecorder(path, metadata=metadata, jpeg_quality=jpeg_quality, json_schemas=json_schemas)
        self.path = path
        #: the live Foxglove WebSocket server (``live`` = its HOST:PORT), fed by the same writer
        self.live = None
        self.live_access = live_access  # its TLS files and token (aerodaas.clusters.tls.ServeAccess), None: plain
        self._declared = [(topic, self.rec.declare_proto(topic, schema)) for topic, schema in declare or ()]
        if live is not None:
            try:
                self.attach_live(live)
            except BaseException:
                self.rec.close()
                raise
        self._cameras: dict[str, list[tuple[str, tuple]]] = {}  # robot -> [(camera frame, mount quaternion)]
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._pending_frames = 0
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)  # notified when the writer thread takes a frame
        self.hold = FrameHold(hold_s)
        self.max_pending_frames = max_pending_frames
        self.flush_every_s = flush_every_s
        self.copies = copies
        self.frames_dropped = 0
        self.dropped_by_topic: dict[str, int] = {}  # frames refused here (queue full / closed), per image topic offered
        self.write_errors: list[str] = []
        self.closed = False
        self._intrinsics: dict[str, dict] = {}  # camera frame -> intrinsics (writer thread only)
        self.failure: dict[str, Any] | None = None
        self.lost = 0  # messages offered after a failure (not recorded)
        self.last_t_ns: int | None = None  # log time of the last message written
        self.first_t_ns: int | None = None  # log time of the first message written
        #: (kind, robot or topic) -> the newest odometry sample / frame written: a drone actor restarted from its
        #: checkpoint flies again from the checkpoint's time and sends samples whose stamps were recorded already;
        #: those are dropped here (:meth:`_duplicate`) and counted in ``duplicates``
        self._last_stamp: dict[tuple[str, str], _Newest] = {}
        self.duplicates = 0
        self.duplicates_by_topic: dict[str, int] = {}
        #: messages numbered here, per stream (producers in this process; the other actors' come with their ledgers)
        self.produced_here: dict[str, int] = {}
        self.analytics_counts = AnalyticsCounts()  # analytics inputs and items without output of this process
        #: the analytics scheduler's task records written here, per scheduler (writer thread only): in the accounting
        self.task_tally = TaskTally()
        self.on_failure: list[Callable[[dict], None]] = []
        _inject_fault(self.rec)
        self._thread = threading.Thread(target=self._writer, name="aerodaas-recorder", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ producers

    def attach_live(self, address: str) -> str:
        """Start the live view on ``address`` (HOST:PORT) and feed it every message from now on, the declared track
        channels advertised first; returns its URL (the current one if a live view already runs). Raises
        ``ValueError`` for a bad address and ``RuntimeError`` when it cannot bind."""
        if self.live is not None:
            return self.live.url
        # only here: a run without --live never imports the server (0.06 s of CPU)
        from aerodaas.liveview.server import LiveServer  # lazy: start-up cost

        live = LiveServer(address, name="aerodaas run", access=self.live_access)
        for topic, record in self._declared:
            live.advertise(topic, *record, "protobuf")
        self.live = live
        self.rec.add_sink(live.publish)
        return live.url

    def image(self, topic: str, t_ns: int, frame: np.ndarray | bytes, frame_id: str, seq: int = -1,
              incarnation: int = 0) -> bool:
        """Queue a (H, W, 3) uint8 BGR frame (shared, not copied: frames are read-only), or its JPEG bytes already
        encoded by the sending actor. False if dropped. ``seq``: the producer's sequence number on ``topic`` (-1:
        numbered here, see :meth:`_numbered`); ``incarnation``: the producer's (see :meth:`_duplicate`)."""
        with self._lock:
            if self.failure is not None:
                self.lost += 1
                return False
            item = self._numbered(RecordImage(topic, t_ns, frame, frame_id, seq, incarnation)) \
                if not self.closed else None
            self.dropped_by_topic.setdefault(topic, 0)  # every image topic offered: its count (0 too) is recorded
            if item is not None:
                self.hold.wait(self._room, lambda: self.closed or self.failure is not None
                               or self._pending_frames < self.max_pending_frames)
                item = None if self.closed else item
            if item is None or self._pending_frames >= self.max_pending_frames:
                self.frames_dropped += 1
                self.dropped_by_topic[topic] += 1
                return False
            self._pending_frames += 1
            self._q.put(item)  # under the lock: see _put
        return True

    def camera(self, robot: str, sensor: str, intrinsics: dict, pitch_deg: float) -> None:
        """Register a camera: its frame ``<robot>/<sensor>`` joins the transform tree under ``<robot>/base_link``
        (optical frame, pitched ``pitch_deg`` below the horizon, 90 = nadir) and each of its images on
        ``/<robot>/camera/<sensor>`` is followed by a ``foxglove.CameraCalibration`` built from ``intrinsics``
        (``width``, ``height`` in pixels, ``fx``, ``fy``, ``cx``, ``cy`` in pixels)."""
        self._put(RecordCamera(robot, sensor, dict(intrinsics), float(pitch_deg)))

    def detections(self, topic: str, t_ns: int, dets: list, image_size: tuple[int, int] | None = None,
                   seq: int = -1) -> None:
        self._put(RecordDetections(topic, t_ns, dets, image_size, seq))

    def odometry(self, robot: str, t_ns: int, odom: dict, seq: int = -1, incarnation: int = 0) -> None:
        """Queue one odometry sample of ``robot`` at ``t_ns`` (``seq``, ``incarnation``: as :meth:`image`)."""
        self._put(RecordOdometry(robot, t_ns, odom, seq, incarnation))

    def tracks(self, prefix: str, t_ns: int, robot: str, rows: list, image_size: tuple[int, int] | None = None) -> None:
        """One frame's geo-located tracks (:func:`aerodaas.perception.track_records.write_tracks`)."""
        self._put(RecordTracks(prefix, t_ns, robot, list(rows), image_size))

    def json(self, topic: str, t_ns: int, obj: dict, schema_name: str, seq: int = -1) -> None:
        self._put(RecordJson(topic, t_ns, obj, schema_name, seq))

    def _put(self, item: RecordItem) -> None:
        if self.failure is not None:
            self.lost += 1
            return
        with self._lock:  # numbered and queued at once: never behind close()'s stop mark with a number taken
            if self.closed:
                return
            self._q.put(self._numbered(item))

    def _numbered(self, item: RecordItem) -> RecordItem:
        """``item`` with a sequence number: a producer in this process (``seq`` -1) is numbered here, per stream, and
        counted in ``produced_here``. Caller holds ``_lock``."""
        stream = item.stream()
        if stream is None or getattr(item, "seq", 0) >= 0:
            return item
        n = self.produced_here.get(stream, 0)
        self.produced_here[stream] = n + 1
        return item.numbered(n)

    # ------------------------------------------------------------------ writer thread
    def _writer(self) -> None:
        last_flush = time.monotonic()
        while True:
            try:
                item = self._q.get(timeout=0.5)
            except queue.Empty:
                item = None
            if item is _STOP:
                return
            try:
                if item is not None:
                    try:
                        self._write(item)
                        t_ns = getattr(item, "t_ns", None)
                        if t_ns is not None:
                            self.last_t_ns = max(self.last_t_ns or t_ns, t_ns)
                            self.first_t_ns = min(self.first_t_ns or t_ns, t_ns)
                    except OSError:
                        raise
                    except Exception as e:  # a bad message must not stop the recording
                        self.write_errors.append(f"{type(item).__name__} {_what(item)}: {type(e).__name__}: {e}")
                    finally:
                        if isinstance(item, RecordImage):
                            with self._lock:
                                self._pending_frames -= 1
                                self._room.notify_all()
                if time.monotonic() - last_flush > self.flush_every_s:
                    self.rec.flush()
                    last_flush = time.monotonic()
            except OSError as e:  # the disk: full, I/O error, gone. Stop cleanly, say what was lost.
                self._fail(e)
                return

    def _duplicate(self, item: RecordItem) -> bool:
        """True for an odometry sample or a frame not to write because its stamp is not newer than the newest one
        written for the same robot / image topic and:

        * another incarnation of its producer (:attr:`~aerodaas.protocol.messages.ProducerLedger.incarnation`)
          wrote that one: a restarted drone actor flies again from its checkpoint's time, and the dead process's
          last batch may reach the recorder after the restarted one asked for its ledger, so sequence numbers of
          two incarnations overlap and cannot tell a re-sent sample from a late one (a restart test saw an odometry
          stamp 1 s older than its predecessor written); a late batch of the dead process after the restarted one
          wrote newer samples is dropped the same way. A restarted producer never writes a sample older than one
          already written on that channel;
        * or the same incarnation wrote it with a smaller sequence number (sent again).

        A sample of the same incarnation with a smaller number is one that arrived late (batches of one producer
        may be handed on out of order, e.g. after the recorder actor stalled): it is written, never taken for a
        duplicate."""
        if isinstance(item, RecordOdometry):
            key = ("odometry", item.robot)
        elif isinstance(item, RecordImage):
            key = ("image", item.topic)
        else:
            return False
        t_ns, seq, inc = int(item.t_ns), int(item.seq), int(item.incarnation)
        last = self._last_stamp.get(key)
        if last is not None and t_ns <= last.t_ns:
            if inc != last.incarnation or seq > last.seq:
                self.duplicates += 1
                stream = item.stream() or ""
                self.duplicates_by_topic[stream] = self.duplicates_by_topic.get(stream, 0) + 1
                return True
            return False
        self._last_stamp[key] = _Newest(t_ns, seq, inc)
        return False

    def _write(self, item: RecordItem) -> None:
        r = self.rec
        if self._duplicate(item):
            return
        r.set_sequence(getattr(item, "seq", None))
        try:
            self._write_item(item)
        finally:
            r.set_sequence(None)

    def _write_item(self, item: RecordItem) -> None:
        r = self.rec
        if isinstance(item, RecordImage):
            topic, t_ns, frame, frame_id = item.topic, item.t_ns, item.frame, item.frame_id
            if isinstance(frame, (bytes, bytearray)):  # encoded by the sending actor (RemoteRecorder)
                r.write_image(topic, t_ns, jpeg=bytes(frame), frame_id=frame_id)
            else:
                r.write_image(topic, t_ns, frame, frame_id=frame_id)  # the one JPEG encode of this frame
                if self.copies is not None:
                    self.copies.count("recorder_jpeg_encoded")
            k = self._intrinsics.get(frame_id)
            if k is not None:
                r.write_camera_calibration(f"{topic}/calibration", t_ns, frame_id=frame_id, **k)
        elif isinstance(item, RecordCamera):
            k, robot = item.intrinsics, item.robot
            frame = f"{robot}/{item.sensor}"
            self._intrinsics[frame] = {n: k[n] for n in ("width", "height", "fx", "fy", "cx", "cy")}
            self._cameras.setdefault(robot, []).append((frame, camera_mount_quaternion(item.pitch_deg)))
        elif isinstance(item, RecordDetections):
            r.write_detections(item.topic, item.t_ns, item.detections, image_size=item.image_size)
        elif isinstance(item, RecordJson):
            r.write_json(item.topic, item.t_ns, item.obj, schema_name=item.schema_name)
            if item.schema_name == TASK_SCHEMA:
                self.task_tally.add(item.obj)
        elif isinstance(item, RecordTracks):
            write_tracks(r, item.prefix, item.t_ns, item.robot, item.rows, self.homes.get(item.robot), item.image_size)
        elif isinstance(item, RecordOdometry):
            robot, t_ns, odom = item.robot, item.t_ns, item.odometry
            g = odom["geodetic"]
            r.write_location(f"/{robot}/gps", t_ns, g["lat"], g["lon"], g["alt"], frame_id=f"{robot}/gps")
            att = odom["attitude"]
            r.write_pose(f"/{robot}/pose", t_ns, odom["position"], att["yaw"], frame_id="enu",
                         roll_deg=att["roll"], pitch_deg=att["pitch"])
            base = f"{robot}/base_link"
            r.write_transform(TF_TOPIC, t_ns, "enu", base, odom["position"], att["yaw"],
                              roll_deg=att["roll"], pitch_deg=att["pitch"])
            r.write_transform(TF_TOPIC, t_ns, base, f"{robot}/gps", (0.0, 0.0, 0.0))
            for frame, q in self._cameras.get(robot, ()):
                r.write_transform(TF_TOPIC, t_ns, base, frame, (0.0, 0.0, 0.0), quaternion=q)
            r.write_json(f"/{robot}/odometry", t_ns, odom, schema_name="aerodaas.Odometry")
        else:
            raise TypeError(f"the recorder cannot write a {type(item).__name__}")

    def _fail(self, e: OSError) -> None:
        """The writer hit ``e``: cut the file back to the last record boundary the OS took, try to finish it, count
        what is lost, tell the callbacks. Runs in the writer thread, which then ends."""
        rec = self.rec
        info: dict[str, Any] = {"error": f"{type(e).__name__}: {e}", "errno": e.errno,
                                "last_recorded_ns": self.last_t_ns, "path": self.path}
        with self._lock:
            self.failure = info
        lost = 0
        while True:  # what was queued is lost too
            try:
                item = self._q.get_nowait()
            except queue.Empty:
                break
            if item is not _STOP:
                lost += 1
        self.lost += lost
        durable = rec.abandon()  # its pending buffer cannot be written: the descriptor is closed anyway
        finished = False
        try:
            os.truncate(rec.path, durable)  # the file ends at a complete record: an unfinished but valid MCAP
            info["messages_in_file"] = recover_mcap(rec.path)["messages"]  # finished and indexed, if the disk
            finished = True  # still takes it
        except OSError as e2:
            info["finish_error"] = f"{type(e2).__name__}: {e2}"
        info["finished"] = finished
        for cb in list(self.on_failure):
            try:
                cb(dict(info))
            except Exception:  # noqa: BLE001 - a reporting callback must not hide the failure
                pass

    # ------------------------------------------------------------------ end
    def close(self, timeout_s: float = 30.0, ledgers: list[ProducerLedger] | None = None,
              recorded_before: dict[str, int] | None = None, run_losses: list[dict] | None = None,
              tasks_before: TaskTally | None = None) -> dict[str, Any]:
        """Write what is queued and ``/run/recorder_drops`` (the frames refused here, per image topic; when any
        image was offered), then the run's accounting (:meth:`_write_accounting`), finish the file (summary and
        footer) and return the per-topic message counts. ``ledgers``: the other actors' counts
        (:class:`~aerodaas.protocol.messages.ProducerLedger`); ``recorded_before``: topic -> messages in the earlier
        segments of this run; ``run_losses``: the recorder actor's deaths (its ``losses``); ``tasks_before``: the
        task records in the earlier segments, tallied (:func:`aerodaas.recording.task_tally.tally_recordings`)."""
        if not self.closed:
            with self._lock:
                self.closed = True
                drops = dict(self.dropped_by_topic)
            # the frames this recorder refused, per topic, as the file's last message: a reader can account for
            # every frame a camera took (its own not_recorded counts the ones refused before they left its actor)
            if drops:  # a run that recorded images (a file without any stays as it was)
                self._q.put(RecordJson("/run/recorder_drops", self.last_t_ns or 0,
                                       {"frames_dropped": drops, "total": sum(drops.values())}, "aerodaas.RecorderDrops"))
            self._q.put(_STOP)
            self._thread.join(timeout_s)
            try:
                if self.failure is None:
                    try:
                        self._write_accounting(ledgers or [], recorded_before or {}, run_losses or [],
                                               tasks_before or TaskTally())
                        self.rec.close()
                    except OSError as e:  # the summary itself does not fit: the same clean failure
                        self._fail(e)
            finally:
                if self.live is not None:  # after the last message: a client sees the whole run
                    self.live.stop()
        return dict(self.rec.message_counts)

    # ------------------------------------------------------------------ accounting (producers in this process)
    def _write_accounting(self, ledgers: list[ProducerLedger], recorded_before: dict[str, int],
                          run_losses: list[dict], tasks_before: TaskTally) -> None:
        """The file's last messages (the writer thread has ended): ``/run/accounting``
        (:func:`aerodaas.recording.accounting.accounting_message`: per stream what its producers numbered and what
        was dropped here as sent again by a restarted drone actor; per analytics what it was offered and took
        without an output; per analytics scheduler its task records in every segment, ``tasks``:
        :class:`~aerodaas.recording.task_tally.TaskTally`, when there were any), then, when the run lost anything
        — a recorder death (``run_losses``) or a message numbered but in none of the run's segments — ``/run/result``
        ``{"outcome": "recording_lost", "losses": [...], "lost": {topic: n}}``, so that no reader takes the drones'
        own ``success`` for the run's."""
        if self.live is not None:
            for peer, at in list(self.live.dropped_clients):
                self.rec.write_json("/run/events", self.last_t_ns or 0, {
                    "event": "live_client_dropped", "client": peer, "wall_time": at,
                    "after_s": self.live.client_send_timeout_s}, schema_name="aerodaas.LiveClientDropped")
        here = ProducerLedger("recorder", dict(self.produced_here), *self.analytics_counts.snapshot())
        msg = accounting_message([*ledgers, here], dict(self.duplicates_by_topic))
        tasks = tasks_before.merged(self.task_tally).as_dict()
        if tasks:
            msg["tasks"] = tasks
        if not msg["channels"] and not msg["analytics"] and not tasks:
            return
        t_ns = (self.last_t_ns or 0) + 1
        counts = dict(recorded_before)
        for topic, n in self.rec.message_counts.items():
            counts[topic] = counts.get(topic, 0) + n
        lost = {t: c.lost for t, c in (account_channels(msg, counts) or {}).items() if c.lost}
        if run_losses or lost:
            losses = [{k: x.get(k) for k in ("segment", "recorded_until_ns", "resumed_at_ns")} for x in run_losses]
            self.rec.write_json(RUN_RESULT_TOPIC, t_ns, {"outcome": "recording_lost", "losses": losses, "lost": lost},
                                schema_name="aerodaas.RunResult")
        self.rec.write_json(ACCOUNTING_TOPIC, t_ns, msg, schema_name="aerodaas.RunAccounting")

    def report(self) -> dict[str, Any]:
        """``{"failure": None | {error, errno, last_recorded_ns, path, finished, finish_error?}, "lost": n,
        "frames_dropped": n, "duplicates": n, "write_errors": [...]}`` (``duplicates``: samples dropped as already
        recorded, see :meth:`_duplicate`)."""
        return {"failure": self.failure, "lost": self.lost, "frames_dropped": self.frames_dropped,
                "duplicates": self.duplicates, "write_errors": self.write_errors[-10:]}

    def counts(self) -> dict[str, int]:
        return dict(self.rec.message_counts)


def _what(item: RecordItem) -> str:
    """The topic (or robot) an item is for, for error messages."""
    return str(getattr(item, "topic", None) or getattr(item, "robot", ""))


def deliver(recorder: Any, batch: list[RecordItem]) -> int:
    """Hand a :class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder` batch to ``recorder`` (the run's :class:`RecorderService`);
    returns the number of items. Raises TypeError for anything that is not a :class:`~aerodaas.protocol.messages.RecordItem`."""
    for item in batch:
        if not isinstance(item, RecordItem):
            raise TypeError(f"remote recorder: {type(item).__name__} is not a RecordItem")
        item.apply(recorder)
    return len(batch)


def _inject_fault(rec: McapRecorder) -> None:
    """``AERODAAS_FAULT_RECORDER=enospc:N`` / ``eio:N``: the recording's file fails with ENOSPC / EIO once N bytes
    were written (fault injection; unset in normal runs)."""
    spec = os.environ.get("AERODAAS_FAULT_RECORDER")
    if not spec:
        return
    kind, _, n = spec.partition(":")
    code = {"enospc": errno.ENOSPC, "eio": errno.EIO}[kind.strip().lower()]
    rec.inject_write_fault(int(n), code)
