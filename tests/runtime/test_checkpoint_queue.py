"""A drone's checkpoint as the recorder actor keeps it, its waypoint queue sent only when it changed otherwise than
by flying (:class:`~aerodaas.actors.drone.checkpoint.QueueBases`, :class:`~aerodaas.actors.recording.checkpoints.CheckpointStore`):
what a restarted drone actor opens is the whole checkpoint it would have had, after visits, after navigation added,
after the recorder restarted (it then asks for the queue again) and whatever order the checkpoints arrive in. A
drone actor's host built in this process (no Ray)."""
from __future__ import annotations

import pytest

from aerodaas import Environment
from aerodaas.actors.drone.checkpoint import QueueBases, drone_checkpoint, restore_drone
from aerodaas.actors.recording.checkpoints import CheckpointStore
from aerodaas.config import parse_environment_config
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.protocol.messages import QUEUE_KEYS, SealedCheckpoint
from aerodaas.schedulers import TrajectoryScheduler

from tests.runtime.test_dataplane import _fly, _host_for


def _drone_host():
    from aerodaas.bench.fleet import fleet_config

    env = Environment(parse_environment_config(fleet_config(1, camera=False)))
    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)
    wps = [Waypoint(id=f"w{k}", x=k % 5, y=k % 3, z=3.0, hover_duration=0.5) for k in range(40)]
    env.get_robot_by_id("d00").navigate(sched.generate_navigation(
        AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.ORDERED)))
    return _host_for(env)


@pytest.fixture
def drone():
    _host, rt, _plan = _drone_host()
    d = rt.drones[0]
    _fly(d)
    yield d
    rt.close()


def _queue_of(cp: dict) -> dict:
    """The checkpoint's queue keys, the missions as plain values (items dumped, segment tags by position)."""
    return {**{k: cp[k] for k in QUEUE_KEYS},
            "missions": [(m.priority, m.seq, m.name, m.distance_driven, [i.model_dump() for i in m.items],
                          m.segment_ids) for m in cp["missions"]]}


def _same(opened: dict, whole: dict) -> None:
    """``opened`` is ``whole``: the queue by value, every other key but the vehicle's (numpy state) equal."""
    assert set(opened) == set(whole)
    assert _queue_of(opened) == _queue_of(whole)
    assert {k: v for k, v in opened.items() if k not in QUEUE_KEYS + ("vehicle",)} == \
        {k: v for k, v in whole.items() if k not in QUEUE_KEYS + ("vehicle",)}


class _Sender:
    """The drone actor's side: checkpoint numbers and the queue it last sent."""

    def __init__(self, d) -> None:
        self.d, self.seq, self.bases = d, 0, QueueBases()

    def take(self) -> tuple[dict, SealedCheckpoint]:
        self.seq += 1
        cp = drone_checkpoint(self.d, self.seq)
        state, queue, qid = self.bases.split(cp)
        return cp, SealedCheckpoint.seal(state, queue, qid)


def _visit(d, n: int) -> None:
    for _ in range(n):
        head = d.queue.queued()[0]
        assert d.plan_log.complete(d.queue, head.id, 1.0)


def test_the_queue_travels_once_and_every_checkpoint_opens_whole(drone):
    sender, store = _Sender(drone), CheckpointStore()
    cp, sealed = sender.take()
    assert sealed.queue_blob is not None and store.keep("d00", sealed)
    _same(store.last("d00").open(), cp)
    first_size = len(sealed.blob) + len(sealed.queue_blob)
    for _ in range(3):  # flying: waypoints completed, nothing else changed
        _visit(drone, 2)
        cp, sealed = sender.take()
        assert sealed.queue_blob is None and sealed.queue_id == 1 and store.keep("d00", sealed)
        assert len(sealed.blob) < first_size / 4
        opened = store.last("d00").open()
        _same(opened, cp)
        assert len(opened["completed"]) == len(cp["completed"]) > 0
    # navigation added (another mission): the queue travels again
    drone.queue.enqueue("extra", [Waypoint(id="x1", x=1.0, y=1.0, z=3.0)], priority=0)
    cp, sealed = sender.take()
    assert sealed.queue_blob is not None and sealed.queue_id == 2 and store.keep("d00", sealed)
    _same(store.last("d00").open(), cp)
    _visit(drone, 1)  # the extra mission's waypoint first (priority 0)
    cp, sealed = sender.take()
    assert sealed.queue_blob is None and store.keep("d00", sealed)
    _same(store.last("d00").open(), cp)


def test_a_restarted_recorder_gets_the_queue_again(drone):
    sender = _Sender(drone)
    assert CheckpointStore().keep("d00", sender.take()[1])
    _visit(drone, 1)
    restarted = CheckpointStore()  # the recorder's new process knows no queue
    _cp, sealed = sender.take()
    assert restarted.keep("d00", sealed) is False and restarted.last("d00") is None
    sender.bases.forget("d00", sealed.queue_id)  # what the drone actor does with that answer
    _visit(drone, 1)
    cp, sealed = sender.take()
    assert sealed.queue_blob is not None and restarted.keep("d00", sealed)
    _same(restarted.last("d00").open(), cp)


def test_checkpoints_arriving_out_of_order_keep_the_newest_whole(drone):
    sender, store = _Sender(drone), CheckpointStore()
    cp1, s1 = sender.take()  # carries queue 1
    _visit(drone, 1)
    _cp2, s2 = sender.take()  # goes with queue 1
    drone.queue.enqueue("extra", [Waypoint(id="x1", x=1.0, y=1.0, z=3.0)], priority=5)
    cp3, s3 = sender.take()  # carries queue 2
    _visit(drone, 1)
    cp4, s4 = sender.take()  # goes with queue 2
    assert store.keep("d00", s2) is False  # before its queue
    assert store.keep("d00", s4) is False
    assert store.keep("d00", s1)
    _same(store.last("d00").open(), cp1)
    assert store.keep("d00", s3)
    _same(store.last("d00").open(), cp3)
    assert store.keep("d00", s2)  # older than the one kept: ignored
    assert store.keep("d00", s4)
    _same(store.last("d00").open(), cp4)
    assert store.last("d00").queue_id == 2


def test_a_drone_restored_from_a_kept_checkpoint_flies_on_from_the_same_queue(drone):
    sender, store = _Sender(drone), CheckpointStore()
    store.keep("d00", sender.take()[1])
    _visit(drone, 5)
    cp, sealed = sender.take()
    assert sealed.queue_blob is None and store.keep("d00", sealed)
    _host, rt, _plan = _drone_host()  # the restarted actor's drone, built afresh
    try:
        again = rt.drones[0]
        restore_drone(again, store.last("d00").open())
        assert [i.id for i in again.queue.queued()] == [i.id for i in drone.queue.queued()] == \
            [f"w{k}" for k in range(5, 40)]
        assert again.queue.completed == drone.queue.completed == [f"w{k}" for k in range(5)]
    finally:
        rt.close()


def test_a_checkpoint_without_its_queue_says_so():
    sealed = SealedCheckpoint.seal({"robot": "d1", "seq": 3, "queue_delta": {"missions": [], "completed": []}},
                                   None, 7)
    with pytest.raises(ValueError, match=r"checkpoint 3 of robot 'd1': its waypoint queue 7 is missing"):
        sealed.open()
