"""The recorder's duplicate rule is keyed by producer incarnation, so a restarted producer (a
drone actor Ray restarted from its checkpoint) never writes a sample older than one already written on that
channel. A restart test saw an odometry stamp 1 s older than its predecessor: the restarted process asked the
recorder actor for its earlier counts (``ledger_of``) while the dead process's last batch was still on its way,
so its sequence numbers overlapped the dead one's; its re-flown samples then had smaller numbers than the newest
written one and passed as late arrivals. Each process now gets its own incarnation number from the recorder actor;
the file is read back with the ``mcap`` package's own reader."""
from __future__ import annotations

import pytest
from mcap.reader import make_reader

from aerodaas.actors.recording.recorder import RecorderService, deliver
from aerodaas.protocol.messages import ProducerLedger, RecordImage, RecordOdometry
from aerodaas.recording.reader import summarize_mcap

S = 1_000_000_000


def _odom(t: float) -> dict:
    return {"t": t, "position": [t, 0.0, 3.0], "geodetic": {"lat": 47.0, "lon": 8.0, "alt": 500.0},
            "attitude": {"roll": 0.0, "pitch": 0.0, "yaw": 0.0}}


def _batch(incarnation: int, samples: list[tuple[int, float]]) -> list:
    """What one producer process sends: an odometry sample and a frame per (sequence number, stamp in s)."""
    out = []
    for seq, t in samples:
        out.append(RecordOdometry("d1", int(t * S), _odom(t), seq).of_incarnation(incarnation))
        out.append(RecordImage("/d1/camera/c", int(t * S), b"\xff\xd8jpeg", "d1/c", seq).of_incarnation(incarnation))
    return out


def _written(path, topic: str) -> list[int]:
    """The log times of ``topic`` in the order they were written."""
    with open(path, "rb") as f:
        return [m.log_time for _, _, m in make_reader(f).iter_messages(topics=[topic], log_time_order=False)]


def test_a_restarted_producer_whose_numbers_overlap_never_writes_an_older_sample(tmp_path):
    """Incarnation 1 sent samples 0-9 (t = 1..10 s); its last batch (8, 9) was still on its way when incarnation 2
    asked for its ledger, which said 8, so incarnation 2 numbers on from 8 and flies again from its checkpoint at
    t = 8 s. The late batch arrives, then incarnation 2's samples: those at t <= 10 s (numbers 8-10, smaller than or
    equal to the newest written, 9) are dropped as duplicates; a late batch of incarnation 1 after incarnation 2
    wrote newer samples is dropped too; a late sample of one incarnation (its own batches out of order) is still
    written."""
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), flush_every_s=0.0, max_pending_frames=1000)  # no frame refused for want of room
    deliver(svc, _batch(1, [(k, k + 1.0) for k in range(6)]))      # t = 1..6
    deliver(svc, _batch(1, [(7, 8.0)]))                             # 6 (t = 7) is late: comes after 7
    deliver(svc, _batch(1, [(6, 7.0)]))                             # ... written (same incarnation)
    deliver(svc, _batch(1, [(8, 9.0), (9, 10.0)]))                  # the dead process's last batch
    deliver(svc, _batch(2, [(8, 8.0), (9, 9.0), (10, 10.0), (11, 11.0), (12, 12.0)]))  # re-flown from t = 8
    deliver(svc, _batch(1, [(10, 10.5)]))                           # a straggler of the dead process
    deliver(svc, _batch(2, [(13, 13.0)]))
    svc.close(ledgers=[ProducerLedger("d1", {"/d1/odometry": 14, "/d1/camera/c": 14}, incarnation=2)])
    want = [int(t * S) for t in (1, 2, 3, 4, 5, 6, 8, 7, 9, 10, 11, 12, 13)]
    for topic in ("/d1/odometry", "/d1/camera/c"):
        got = _written(path, topic)
        assert got == want, (topic, got)
        # past the one late sample of incarnation 1, each stamp is newer than the one written before it
        assert all(b > a for a, b in zip(got[8:], got[9:])), got
    assert svc.report()["duplicates"] == 2 * 4  # 8, 9, 10 of incarnation 2 and 10.5 of incarnation 1, per channel
    acc = summarize_mcap(path)["accounting"]
    assert acc["channels"]["/d1/odometry"]["duplicates"] == 4 and acc["lost_total"] == 0, acc


def test_within_one_incarnation_the_sequence_rule_is_unchanged(tmp_path):
    """A producer that sends a stamp again with a larger number (numbered in this process, incarnation 0) is
    still a duplicate; a smaller number is a late arrival, written."""
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), flush_every_s=0.0)
    for t in (1, 2, 3, 2, 3, 4):
        svc.odometry("d1", t * S, _odom(t))
    svc.close()
    assert _written(path, "/d1/odometry") == [t * S for t in (1, 2, 3, 4)]
    assert svc.report()["duplicates"] == 2


def test_ledgers_merge_to_the_newest_incarnation():
    a = ProducerLedger("d", {"/d/odometry": 5}, incarnation=1)
    b = ProducerLedger("d", {"/d/odometry": 3}, incarnation=2)
    assert a.merged(b).incarnation == b.merged(a).incarnation == 2
    assert a.plus({"/d/odometry": 2}, {}, {}, {}).incarnation == 1


@pytest.mark.e2e
def test_the_recorder_actor_hands_each_producer_process_a_new_incarnation(ray_session, tmp_path):
    """The recorder actor itself (on Ray): the first process of a producer is incarnation 1; a restarted one asks
    again and is 2, also while the dead one's last batch, carrying incarnation 1, has not arrived (the race of the
    restart test); a recorder that already saw incarnation 3 in a batch hands out 4. The file it writes holds no
    odometry stamp older than its predecessor."""
    import ray

    from aerodaas.actors.recording.actor import RecorderActor
    from aerodaas.protocol.specs import ActorSpec, RecordSpec

    path = tmp_path / "inc.mcap"
    rec = RecorderActor.options(name=f"aerodaas/inc-test-{tmp_path.name}/recorder").remote(
        ActorSpec(role="recorder", record=RecordSpec(str(path))))
    try:
        ray.get(rec.setup.remote(), timeout=120)
        first = ray.get(rec.ledger_of.remote("drone/d1"), timeout=30)
        assert first.incarnation == 1 and first.produced == {}
        ray.get(rec.record.remote(_batch(1, [(k, k + 1.0) for k in range(8)]),
                                  ProducerLedger("drone/d1", {"/d1/odometry": 8, "/d1/camera/c": 8}, incarnation=1)))
        second = ray.get(rec.ledger_of.remote("drone/d1"), timeout=30)  # the restarted process
        assert second.incarnation == 2 and second.produced["/d1/odometry"] == 8
        ray.get(rec.record.remote(_batch(1, [(8, 9.0), (9, 10.0)]),  # the dead process's last batch, late
                                  ProducerLedger("drone/d1", {"/d1/odometry": 10, "/d1/camera/c": 10}, incarnation=1)))
        ray.get(rec.record.remote(_batch(2, [(8, 8.0), (9, 9.0), (10, 10.0), (11, 11.0)]),
                                  second.plus({"/d1/odometry": 4, "/d1/camera/c": 4}, {}, {}, {})))
        ray.get(rec.keep_ledger.remote(ProducerLedger("drone/d9", {}, incarnation=3)))
        assert ray.get(rec.ledger_of.remote("drone/d9"), timeout=30).incarnation == 4
        ray.get(rec.close.remote(), timeout=120)
    finally:
        ray.kill(rec)
    got = _written(path, "/d1/odometry")
    assert got == [int(t * S) for t in (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11)], got
