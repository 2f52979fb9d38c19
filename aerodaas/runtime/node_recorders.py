"""One recorder per node (``recording.per_node: true`` in the environment).

A run records through one recorder actor on the driver's node (:mod:`aerodaas.actors.recording.actor`); every frame
of every drone crosses to it. ``aerodaas bench recorder`` measures where that one actor stops keeping up
(``docs/results/recorder.md``). With ``per_node`` the plan (:func:`add_node_recorders`) adds a recorder actor per edge
compute that has actors of the run, host id ``recorder/<compute>``, placed like that compute's other actors (its
``label_selector``: ``tier=edge`` and the compute's labels), writing ``RUN.node-<compute>.mcap``
(:func:`aerodaas.recording.merge.node_recording_path`) next to the driver's ``RUN.mcap``; the drone, analytics and
dispatcher actors of that compute send what they record to it (their spec's ``record_remote``), so a drone's frames
stay on its node. The driver's recorder keeps its other duties (specs, checkpoints, ``/mission/result`` of lost
drones, the live view) and records the actors on no edge compute (cloud analytics).

Every node recorder writes the same accounting as the driver's (``/run/accounting`` of the producers that sent to
it), so each file is complete by itself; the run's accounting is their sum (:func:`run_accounting`), and
``aerodaas merge RUN.mcap RUN.node-*.mcap --out ALL.mcap`` writes the run as one file
(:mod:`aerodaas.recording.merge`). With a live view (``--live``), each node recorder forwards what it wrote to
the driver's recorder, whose live view then shows every node's channels (the frames cross to the driver's node
for it; without ``--live`` nothing does).
"""
from __future__ import annotations

import sys
from dataclasses import replace
from typing import Any

from aerodaas.recording.merge import node_recording_path

__all__ = ["NODE_RECORDER_PREFIX", "add_node_recorders", "node_recorder_ids", "close_node_recorders",
           "run_accounting"]

#: host id prefix of a node's recorder actor: ``recorder/<compute>``
NODE_RECORDER_PREFIX = "recorder/"


def add_node_recorders(actors: dict[str, Any], main: Any, run_id: str) -> list[str]:
    """Add a recorder actor (:class:`~aerodaas.runtime.dataflow.ActorPlan`, role ``recorder``) to ``actors`` for
    every edge compute that places actors, and point those actors' ``record_remote`` at it. ``main`` is the
    driver's recorder plan (its ``spec.record`` has the file: the node files are named after it); each node's plan
    is a copy of it (``dataclasses.replace``: the plan's class is the caller's, :mod:`aerodaas.runtime.dataflow`,
    which imports this module). Returns the new host ids. A run without a file (live view only) gets none
    (nothing to split)."""
    rec = main.spec.record
    if rec is None or not rec.path:
        return []
    by_compute: dict[str, list[Any]] = {}
    for a in actors.values():
        if a.role != "recorder" and a.tier == "edge" and a.compute and a.spec.record_remote:
            by_compute.setdefault(a.compute, []).append(a)
    added = []
    for compute, group in sorted(by_compute.items()):
        hid = f"{NODE_RECORDER_PREFIX}{compute}"
        spec = replace(main.spec, record=replace(rec, path=str(node_recording_path(rec.path, compute)),
                                                 live=None, meta={**rec.meta, "node": compute}, declare=None),
                       record_remote="recorder" if rec.live else None)
        plan = replace(main, actor_id=hid, role="recorder", name=f"aerodaas/{run_id}/{hid}", tier="edge",
                       compute=compute, labels=dict(group[0].labels), components=[], spec=spec, num_gpus=0.0)
        actors[hid] = plan
        for a in group:
            a.spec.record_remote = hid
        added.append(hid)
    return added


def node_recorder_ids(actors: dict[str, Any]) -> list[str]:
    """The host ids of the node recorders among ``actors`` (a plan's or the started handles', by host id)."""
    return sorted(h for h in actors if h.startswith(NODE_RECORDER_PREFIX))


def close_node_recorders(actors: dict[str, Any], timeout_s: float = 120.0) -> dict[str, dict]:
    """Close every node recorder (after the actors that record to them, before the driver's recorder); returns host
    id -> its :meth:`~aerodaas.actors.recording.actor.RecorderActor.recording_report` (``{"error": ...}`` for one
    that could not be closed: its file is then unfinished, ``aerodaas recover`` finishes it). Never raises."""
    import ray  # lazy: heavy ray

    ids = node_recorder_ids(actors)
    refs = {h: actors[h].close.remote() for h in ids}
    out: dict[str, dict] = {}
    for h, ref in refs.items():
        try:
            ray.get(ref, timeout=timeout_s)
            out[h] = ray.get(actors[h].recording_report.remote(), timeout=60)
        except Exception as e:  # noqa: BLE001 - reported, the run then does not read as a success
            out[h] = {"error": f"{type(e).__name__}: {e}"}
            print(f"aerodaas: warning: the node recorder {h!r} could not be closed: {out[h]['error']}",
                  file=sys.stderr)
    return out


def run_accounting(main_paths: list[str], nodes: list[list[str]]) -> dict[str, Any] | None:
    """The run's accounting over the driver's recording (``main_paths``: its segments) and each node's recording
    (``nodes``: the segments of each): every recording accounted by itself
    (:func:`aerodaas.recording.accounting.account_recording`) and the results summed (``channels``, ``lost``,
    ``lost_total``; ``tasks`` of the first that has any). A node recording without accounting (cut short) is
    listed in ``unaccounted`` and counts one lost message: the run cannot say nothing was lost (the driver's file
    may have none: with every producer on a node, nothing numbered was sent to it). None when the driver's file
    has no accounting and there are no node recordings."""
    from aerodaas.recording.accounting import account_recording  # lazy: heavy mcap

    main = account_recording(main_paths) if main_paths else None
    if not nodes:
        return main
    out: dict[str, Any] = {"channels": {}, "lost": {}, "lost_total": 0, "tasks": {}, "unaccounted": []}
    accs = [main]
    for paths in nodes:
        acc = account_recording(paths) if paths else None
        if acc is None:
            out["unaccounted"].append(paths[0] if paths else None)
        accs.append(acc)
    for acc in accs:
        if acc is None:
            continue
        out["channels"].update(acc["channels"])
        for t, n in acc["lost"].items():
            out["lost"][t] = out["lost"].get(t, 0) + n
        out["tasks"] = out["tasks"] or acc.get("tasks") or {}
    out["lost_total"] = sum(out["lost"].values()) + len(out["unaccounted"])
    return out
