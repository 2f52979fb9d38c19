"""Checkpoints of a drone, so that a restarted drone actor goes on with the mission instead of starting it again.

A checkpoint (a picklable dict) holds the vehicle's state when the backend keeps one for us (the simulator:
:meth:`~aerodaas.backends.base.VehicleBackend.checkpoint`; a real vehicle keeps flying on its own), the mission
state machine's state, the waypoints visited, the last 50 events (the recording has them all), the drone's waypoint queue (queued missions
and completed items), the clocks of the control loop and the drone's counters (its plug-in sensors' failures too). :func:`restore_drone` puts them back into a freshly built
:class:`~aerodaas.actors.drone.component.DroneComponent`: the waypoint that was being flown to (or held) is flown to again, from where the
vehicle is, and the events say ``resumed_after_restart``.
"""
from __future__ import annotations

import itertools
import threading
from typing import Any

from aerodaas.navigation.fsm import MissionState as S
from aerodaas.protocol.messages import QUEUE_KEYS


class CheckpointNumbers:
    """The sequence numbers of an actor's checkpoints (1, 2, ... in the order taken, across every drone of the
    actor and every ``run`` of it): the recorder actor keeps a robot's checkpoint with the largest one
    (:meth:`aerodaas.actors.recording.actor.RecorderActor.checkpoint`). Owned by the actor's
    :class:`~aerodaas.actors.host.assembly.ActorAssembly`; ``itertools.count`` is thread-safe (the clock thread takes
    checkpoints, the actor's ``checkpoint`` call too)."""

    def __init__(self) -> None:
        self._count = itertools.count(1)

    def take(self, d: Any) -> dict:
        """:func:`drone_checkpoint` of DroneComponent ``d`` with the next number."""
        return drone_checkpoint(d, next(self._count))


def drone_checkpoint(d: Any, seq: int) -> dict:
    """A checkpoint of DroneComponent ``d`` numbered ``seq`` (newer is larger, :class:`CheckpointNumbers`), taken
    under its lock, so it is consistent with one control step."""
    with d.lock:
        q = d.queue.state()  # the items themselves are never changed in place: list copies suffice
        f = d.flight
        return {"seq": seq, "robot": d.cfg.id, "t": d.backend.t, "vehicle": d.backend.checkpoint(),
                "state": d.fsm.state.value, "history": list(d.fsm.history), "visited": list(f.visited),
                "events": list(d.events[-50:]), "preplanned_left": f.preplanned_left,
                "preplanned_total": f.preplanned_total, "takeoff_altitude": d.takeoff_altitude,
                "flew_something": f.flew_something, "idle_since": f.idle_since, "outcome": f.outcome,
                "error": d.error, "ticks": d.ticks, "missed_ticks": d.missed_ticks, "next_tick": d.next_tick,
                "next_odom": d.next_odom, "rejected": list(f.rejected), "hold_failed": list(f.hold_failed),
                "not_reached": list(d.progress.not_reached), "missions": q["missions"],
                "completed": q["completed"], "segments_issued": q["segments_issued"], "seq_missions": q["seq"],
                "last_tick": [float(d.last_tick[0]), [float(c) for c in d.last_tick[1]]], "discarded": list(d.plan_log.discarded),
                "cleared_preplanned": list(d.plan_log.cleared_preplanned),
                "cameras": [c["next_t"] for c in d.cameras],
                "sensor_health": {ps.sensor_id: ps.health.state() for ps in d.plugin_sensors},
                # which queued waypoints are pre-planned, by position (object ids do not survive pickling)
                "preplanned_flags": [[id(i) in f.preplanned_items for i in m.items] for m in q["missions"]]}


class QueueBases:
    """What a drone actor last sent of each drone's waypoint queue to the recorder actor, so that a checkpoint
    carries the queue (:data:`~aerodaas.protocol.messages.QUEUE_KEYS`, hundreds of pickled waypoints) only when it
    changed otherwise than by flying, and else only what was flown since: the items taken off the head of each
    mission and the waypoints completed (:class:`~aerodaas.protocol.messages.SealedCheckpoint`). :meth:`split` runs
    on the data plane's pool, :meth:`forget` on whichever thread learns that the recorder lacks a queue (one lock)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._ids = itertools.count(1)
        #: robot id -> (queue id, {mission seq: (its items, segment tags, pre-planned flags, priority, name,
        #: distance driven)}, completed ids, seq_missions, segments_issued) of the queue last sent (the items kept:
        #: compared by identity, their ids must not be reused while they are)
        self._sent: dict[str, tuple] = {}

    def forget(self, robot: str, queue_id: int) -> None:
        """The recorder does not hold queue ``queue_id`` of ``robot`` (it restarted, or a newer one overtook it):
        the next checkpoint carries the whole queue again."""
        with self._lock:
            if robot in self._sent and self._sent[robot][0] == queue_id:
                del self._sent[robot]

    def split(self, cp: dict) -> tuple[dict, dict | None, int]:
        """Checkpoint ``cp`` (:func:`drone_checkpoint`) -> ``(state, queue, queue_id)``: the state without the queue
        keys but with ``queue_delta`` (what was flown since queue ``queue_id``), and the queue itself when it must
        be sent (None: the recorder has queue ``queue_id``)."""
        robot = cp["robot"]
        state = {k: v for k, v in cp.items() if k not in QUEUE_KEYS}
        with self._lock:
            sent = self._sent.get(robot)
            delta = _flown_since(sent, cp) if sent is not None else None
            if delta is not None:
                state["queue_delta"] = delta
                return state, None, sent[0]
            qid = next(self._ids)
            self._sent[robot] = (qid, {m.seq: (list(m.items), dict(m.segment_of), list(flags), m.priority,
                                               m.name, m.distance_driven)
                                       for m, flags in zip(cp["missions"], cp["preplanned_flags"])},
                                 list(cp["completed"]), cp["seq_missions"], cp["segments_issued"])
        state["queue_delta"] = {"missions": [[m.seq, 0] for m in cp["missions"]], "completed": []}
        return state, {k: cp[k] for k in QUEUE_KEYS}, qid


def _flown_since(sent: tuple, cp: dict) -> dict | None:
    """The ``queue_delta`` from the queue ``sent`` (:class:`QueueBases`) to checkpoint ``cp``'s, or None when the
    queue changed otherwise than by items taken off the heads of its missions and waypoints completed (a mission
    added, an item inserted or revised, a segment tag or pre-planned flag changed)."""
    _qid, missions, completed, seq_missions, segments = sent
    done = cp["completed"]
    if cp["seq_missions"] != seq_missions or cp["segments_issued"] != segments or done[:len(completed)] != completed:
        return None
    out = []
    for m, flags in zip(cp["missions"], cp["preplanned_flags"]):
        was = missions.get(m.seq)
        if was is None:
            return None
        items, tags, was_flags, priority, name, distance_driven = was
        taken = len(items) - len(m.items)
        if (taken < 0 or (m.priority, m.name, m.distance_driven) != (priority, name, distance_driven)
                or list(map(id, m.items)) != list(map(id, items[taken:])) or flags != was_flags[taken:]
                or m.segment_of != tags):
            return None
        out.append([m.seq, taken])
    return {"missions": out, "completed": done[len(completed):]}


def restore_drone(d: Any, cp: dict) -> None:
    """Put checkpoint ``cp`` back into DroneComponent ``d`` (built and connected, not started). A drone that was
    holding at a waypoint flies to it again (acceptance and hold are redone); one that was tracking hovers until
    its analytics send the next command."""
    with d.lock:
        if cp.get("vehicle") is not None:
            d.backend.restore(cp["vehicle"])
        d.queue.restore(cp["missions"], cp["completed"], cp.get("seq_missions"), cp.get("segments_issued"))
        d.flight.preplanned_items = {id(i) for m, flags in zip(cp["missions"], cp.get("preplanned_flags") or [])
                                     for i, pre in zip(m.items, flags) if pre}
        state = S(cp["state"])
        if state == S.WAYPOINT_HOLD:
            state = S.NAVIGATING
        d.fsm.restore(state, list(cp.get("history") or []) + [(cp["t"], state)])
        for k in ("events", "takeoff_altitude", "error", "ticks", "missed_ticks", "next_tick", "next_odom"):
            if k in cp:
                setattr(d, k, cp[k])
        for k in ("visited", "preplanned_left", "flew_something", "idle_since", "outcome", "rejected", "hold_failed"):
            if k in cp:  # the flight state the drone shares with its flights (:mod:`aerodaas.actors.drone.flight`)
                setattr(d.flight, k, cp[k])
        if "not_reached" in cp:
            d.progress.not_reached = list(cp["not_reached"])
        if cp.get("last_tick") is not None:  # where navigation arriving before the first tick is planned from
            d.last_tick = (float(cp["last_tick"][0]), tuple(cp["last_tick"][1]))
        # a run whose pre-planned waypoints were cleared through the HITL API stays never a success
        d.plan_log.discarded = list(cp.get("discarded") or [])
        d.plan_log.cleared_preplanned = list(cp.get("cleared_preplanned") or [])
        d.flight.active_wp, d.flight.hold_until = None, None
        for c, t in zip(d.cameras, cp.get("cameras", [])):
            c["next_t"] = t
        health = cp.get("sensor_health") or {}
        for ps in d.plugin_sensors:  # its readings' failures go on counting (aerodaas.recording.health)
            if ps.sensor_id in health:
                ps.health.restore(health[ps.sensor_id])
        d.restored_from = cp
        d.record_event("resumed_after_restart", state=state.value, checkpoint_t=cp["t"],
                       visited=len(d.visited), heading_to=_head(d))


def _head(d: Any) -> str | None:
    """The id of the item the drone flies to next (None: nothing queued)."""
    items = d.queue.queued()
    return getattr(items[0], "id", None) if items else None
