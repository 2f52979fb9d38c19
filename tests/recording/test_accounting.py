"""End-to-end accounting in process: every recorded message carries its producer's sequence number as
the MCAP message's ``sequence``; the recording's ``/run/accounting`` and its own messages give each channel's loss,
whatever the cause. Read back with the ``mcap`` package's own reader."""
from __future__ import annotations

import threading

import numpy as np
from mcap.reader import make_reader

from aerodaas.actors.recording.recorder import RecorderService
from aerodaas.recording.accounting import account_recording
from aerodaas.recording.reader import summarize_mcap
from aerodaas.protocol.messages import ProducerLedger


def _sequences(path, topic: str) -> list[int]:
    with open(path, "rb") as f:
        return sorted(m.sequence for _, _, m in make_reader(f).iter_messages(topics=[topic]))


def test_producer_numbers_are_the_mcap_sequence_and_gaps_are_the_loss(tmp_path):
    """A remote producer's numbers arrive with gaps (messages it dropped, a batch that never came) and out of
    order (a stalled recorder handing batches on late): the file holds every number delivered once, the rest is
    the channel's loss, and a late sample is recorded, never taken for a duplicate."""
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), flush_every_s=0.0)
    delivered = [0, 1, 2, 5, 6, 4, 9]  # 3, 7, 8 never arrive; 4 arrives after 5 and 6
    for k in delivered:
        svc.odometry("d1", 1_000_000 * (k + 1), {"geodetic": {"lat": 0.0, "lon": 0.0, "alt": 0.0},
                                                 "attitude": {"roll": 0.0, "pitch": 0.0, "yaw": 0.0},
                                                 "position": [0.0, 0.0, float(k)]}, seq=k)
    svc.close(ledgers=[ProducerLedger("d1", {"/d1/odometry": 10})])
    assert _sequences(path, "/d1/odometry") == sorted(delivered)
    assert _sequences(path, "/d1/pose") == sorted(delivered)  # a sample's derived messages share its number
    acc = summarize_mcap(path)["accounting"]
    assert acc["lost"] == {"/d1/odometry": 3} and acc["lost_total"] == 3
    assert acc["channels"]["/d1/odometry"] == {"produced": 10, "duplicates": 0, "recorded": 7, "lost": 3}
    assert summarize_mcap(path)["mission"]["outcome"] == "recording_lost"


def test_a_restarted_producer_sending_again_is_a_duplicate_not_a_loss(tmp_path):
    """A drone actor restarted from its checkpoint numbers on from its ledger but flies the same stamps again:
    those samples are dropped as duplicates and not counted as lost."""
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), flush_every_s=0.0)
    for seq, t in [(0, 1), (1, 2), (2, 3), (3, 2), (4, 3), (5, 4)]:  # 3 and 4: t = 2, 3 sent again
        svc.json("/d1/x", t, {"t": t}, "t.X", seq=seq)
        svc.image("/d1/camera/c", t * 1_000_000, b"\xff\xd8jpeg", "d1/c", seq=seq)
    svc.close(ledgers=[ProducerLedger("d1", {"/d1/x": 6, "/d1/camera/c": 6})])
    acc = summarize_mcap(path)["accounting"]
    assert acc["channels"]["/d1/camera/c"] == {"produced": 6, "duplicates": 2, "recorded": 4, "lost": 0}
    assert acc["channels"]["/d1/x"] == {"produced": 6, "duplicates": 0, "recorded": 6, "lost": 0}  # JSON: kept
    assert acc["lost_total"] == 0 and summarize_mcap(path)["mission"] is None


def test_frames_refused_by_a_full_queue_are_lost_on_their_channel(tmp_path):
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), max_pending_frames=2, flush_every_s=0.0)
    gate = threading.Event()
    write = svc._write

    def busy_write(item):
        gate.wait(30)
        write(item)

    svc._write = busy_write
    refused = sum(not svc.image("/d1/camera/a", 1_000_000 * (k + 1), np.zeros((8, 8, 3), np.uint8), "d1/a")
                  for k in range(20))
    gate.set()
    svc.close()
    seqs = _sequences(path, "/d1/camera/a")
    assert len(seqs) == 20 - refused and len(set(seqs)) == len(seqs) and max(seqs) < 20
    acc = account_recording([path])
    assert acc["lost"] == {"/d1/camera/a": refused} and refused == 18


def test_segments_are_counted_together(tmp_path):
    """A run in two segments (the recorder actor died once): the loss is the producers' count against the
    messages of both files."""
    a, b = tmp_path / "run.mcap", tmp_path / "run.1.mcap"
    first = RecorderService(str(a), flush_every_s=0.0)
    for k in range(3):
        first.json("/d1/x", k + 1, {"k": k}, "t.X", seq=k)
    first.close()
    second = RecorderService(str(b), flush_every_s=0.0)
    for k in range(5, 8):
        second.json("/d1/x", k + 1, {"k": k}, "t.X", seq=k)
    second.close(ledgers=[ProducerLedger("d1", {"/d1/x": 9})], recorded_before={"/d1/x": 3},
                 run_losses=[{"segment": str(a), "recorded_until_ns": 3, "resumed_at_ns": 6}])
    acc = account_recording([a, b])
    assert acc["channels"]["/d1/x"]["recorded"] == 6 and acc["lost"] == {"/d1/x": 3}
    assert summarize_mcap(b)["mission"]["outcome"] == "recording_lost"


def test_an_analytics_output_channel_is_accounted_against_its_inputs(tmp_path):
    """Senders offered a monitor 10 items of d1; it took 2 without an output (None, a shed item) and recorded 5 (its
    actor died with 3 in flight): the output channel lost 3, whatever the analytics numbered itself."""
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), flush_every_s=0.0)
    for k in range(5):
        svc.json("/d1/monitor", k + 1, {"k": k}, "aerodaas.AnalyticsOutput", seq=k)
    drone = ProducerLedger("drone", {}, offered_to={"monitor#1": {"d1": 10}})
    monitor = ProducerLedger("analytics", {"/d1/monitor": 5}, no_output={"monitor#1": {"d1": 1}},
                             analytics={"monitor#1": "monitor"})
    shed = ProducerLedger("drone2", {}, no_output={"monitor#1": {"d1": 1}})  # the sender's outlet shed one
    svc.close(ledgers=[drone, monitor, shed])
    acc = account_recording([path])
    assert acc["channels"]["/d1/monitor"] == {"produced": 8, "duplicates": 0, "recorded": 5, "lost": 3}
    assert acc["lost"] == {"/d1/monitor": 3}
