"""The driver's side of a running mission: start the plan's actors, wait for the drone actors while showing
progress, and contain whatever dies.

Fault handling (each is a test in ``tests/runtime/test_runtime_actors.py`` and ``tests/runtime/test_faults.py``):

* a **drone actor** that dies (process killed, native crash) is restarted by Ray (``max_restarts``); the restarted
  actor restores its drones from their last checkpoints (:mod:`aerodaas.actors.drone.checkpoint`), and
  :func:`supervise` calls its ``run`` again with ``resume=True``. The drone's events say
  ``resumed_after_restart`` and its report counts ``actor_restarts``;
* a drone actor that cannot come back (restarts used up, its node lost with no other node to take it) ends its
  drones with outcome ``lost`` — the other drones fly on; the recorder actor records their ``/mission/result``;
* an **analytics or dispatcher actor** that dies is restarted by Ray and rebuilds itself; frames that were in
  flight are counted as failed by the senders (``failed`` in the outlets' stats), and navigation resumes with the
  next frame. Nothing in the driver waits for it;
* whatever happens, :func:`collect_stats` and the closing in :mod:`aerodaas.runtime.driver` take what they can get from
  the actors that are left and never raise.
"""
from __future__ import annotations

import sys
import time
from typing import TYPE_CHECKING, Any, Callable

from aerodaas.runtime.recorder_watch import RecorderWatch, recorder_specs
from aerodaas.runtime.report import pct, waypoint_count

if TYPE_CHECKING:
    from aerodaas.protocol.actor_classes import ActorClasses

__all__ = ["start_actors", "supervise", "collect_stats", "settle_actors", "progress_lines", "LOST"]

#: outcome of a drone whose actor died and could not be restarted
LOST = "lost"


def start_actors(plan: Any, placement: Any, max_restarts: int, classes: ActorClasses) -> dict:
    """Create every actor of ``plan`` from ``classes`` (the run's actor classes, handed by its entry point): the
    run's recorder first, on the driver's node (restarted as its class says, into a new segment file); the others
    (a node's recorder too) named, placed with their ``label_selector`` (and their ``num_gpus``,
    :meth:`~aerodaas.runtime.dataflow.ActorPlan.ray_options`) and restartable ``max_restarts`` times. Returns host
    id -> actor handle. Nothing is set up yet. Raises what Ray
    raises for an impossible placement option."""
    import ray  # lazy: heavy ray

    handles: dict[str, Any] = {}
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy  # lazy: heavy ray

    rec_plan = plan.actors["recorder"]
    # the recorder writes the driver's file: it runs on the driver's node, whatever other edge nodes exist (and
    # lives as long as the driver does, so losing another node never loses the recording)
    here = NodeAffinitySchedulingStrategy(node_id=ray.get_runtime_context().get_node_id(), soft=False)
    handles["recorder"] = classes.recorder.options(name=rec_plan.name, scheduling_strategy=here).remote(rec_plan.spec)
    # every other actor reads its spec (analytics, schedulers: possibly large) and the wiring from the recorder
    # actor, which lives as long as the run: a restarted actor reads the same again, and no constructor argument
    # sits in the object store (Ray cannot promise those across restarts, ray-project/ray#53727). Not waited for:
    # the other actors start while the recorder's process does (their spec_of waits for it), not after
    handles["recorder"].keep_specs.remote(*recorder_specs(plan))
    for hid, a in plan.actors.items():
        if hid == "recorder":
            continue
        if a.role == "recorder":  # a node's recorder (recording.per_node), placed on its compute's nodes
            handles[hid] = classes.recorder.options(**a.ray_options(placement, max_restarts)).remote(a.spec)
            continue
        handles[hid] = classes.for_role(a.role).options(**a.ray_options(placement, max_restarts)).remote(hid, a.tier)
    return handles


def _is_actor_death(e: BaseException) -> bool:
    import ray  # lazy: heavy ray

    return isinstance(e, (ray.exceptions.RayActorError, ray.exceptions.ActorUnavailableError))


def _await_restart(handle: Any, deadline_s: float) -> bool:
    """Wait (at most ``deadline_s``) for a dead actor to come back restarted; False when it is gone for good."""
    import ray  # lazy: heavy ray

    t_end = time.monotonic() + deadline_s
    while time.monotonic() < t_end:
        try:
            ray.get(handle.ping.remote(), timeout=max(1.0, min(10.0, t_end - time.monotonic())))
            return True
        except ray.exceptions.ActorDiedError:
            return False
        except Exception:  # noqa: BLE001 - restarting (unavailable) or slow: try again
            time.sleep(0.5)
    return False


def _lost_report(rid: str, why: str, checkpoint: dict | None) -> dict:
    """The report of robot ``rid`` whose drone actor is gone, from its last ``checkpoint`` (None: nothing known,
    e.g. the recorder holding the checkpoints died too; then ``t`` and ``preplanned_total`` are None, shown as
    unknown, never as a flight of 0 s)."""
    cp = checkpoint or {}
    return {"robot": rid, "outcome": LOST, "error": why, "t": cp.get("t"), "state": cp.get("state", "unknown"),
            "visited": len(cp.get("visited", [])), "visited_waypoints": cp.get("visited", []),
            "preplanned_total": cp.get("preplanned_total"), "events": cp.get("events", []),
            "preplanned_reached": sum(1 for v in cp.get("visited", []) if v.get("preplanned")) if cp else None,
            "battery_pct": None, "position": [0.0, 0.0, 0.0]}


def supervise(plan: Any, actors: dict, handles: dict, timeout: float | None, progress: bool,
              stop_requested: Callable[[], bool], restart_wait_s: float = 90.0) -> dict:
    """Run every drone actor to the end of its missions and return robot id -> report (see the module docstring
    for what happens when actors die). ``handles``: robot id -> the driver's component handles (progress and
    Ctrl-C). Ctrl-C (KeyboardInterrupt) ends every mission as ``interrupted``, waits for the reports and
    re-raises nothing: the outcome says so."""
    import ray  # lazy: heavy ray

    drones = {hid: a for hid, a in plan.actors.items() if a.role == "drone"}
    robots_of = {hid: [r.robot_id for r in a.spec.robots] for hid, a in drones.items()}
    t0 = time.monotonic()

    def remaining() -> float | None:
        return None if timeout is None else max(1.0, timeout - (time.monotonic() - t0))

    watch = RecorderWatch(actors.get("recorder"), plan)
    refs = {actors[hid].run.remote(remaining()): hid for hid in drones}
    restarts = {hid: 0 for hid in drones}
    reports: dict[str, dict] = {}
    live = None
    if progress and sys.stdout.isatty():
        from rich.live import Live  # lazy: rich (0.1 s of every run's start), only for a terminal's progress display

        live = Live(refresh_per_second=4, transient=False)
        live.start()
    last_print = 0.0
    interrupted = False
    try:
        if stop_requested():
            raise KeyboardInterrupt("stop requested while the actors started")
        while refs:
            watch.poll()
            ready, _ = ray.wait(list(refs), num_returns=1, timeout=0.5)
            for ref in ready:
                _collect(ref, refs, reports, restarts, plan, actors, robots_of, remaining, restart_wait_s)
            if progress and refs:
                lines = progress_lines(handles, t0)
                if live is not None:
                    from rich.text import Text  # lazy: rich, only for the progress display of a terminal

                    live.update(Text("\n".join(lines)))
                elif time.monotonic() - last_print > 5.0:
                    print("\n".join(lines), flush=True)
                    last_print = time.monotonic()
        watch.settle()  # a recorder restarted in the watch's last period: seen before the run's end
    except KeyboardInterrupt:
        interrupted = True
        _interrupt(handles, refs, reports, robots_of)
    finally:
        if live is not None:
            live.stop()
    for hid, n in restarts.items():
        for rid in robots_of[hid]:
            if rid in reports:
                reports[rid]["actor_restarts"] = n
    if interrupted:
        for rep in reports.values():
            rep["outcome"] = "interrupted"
    for rep in reports.values():
        rep["recorder_restarts"] = watch.restarts
    return reports


def _collect(ref: Any, refs: dict, reports: dict, restarts: dict, plan: Any, actors: dict, robots_of: dict,
             remaining: Callable[[], float | None], restart_wait_s: float) -> None:
    """A drone actor's run call ``ref`` (one of ``refs``, ref -> actor id) returned: its reports; or the actor died
    and Ray restarted it within ``restart_wait_s`` (its run resumed, counted in ``restarts``); or its robots end
    ``lost`` (``failed`` for another error) with their last checkpoint, recorded as their result."""
    import ray  # lazy: heavy ray

    hid = refs.pop(ref)
    try:
        reports.update(ray.get(ref))
        return
    except Exception as e:  # noqa: BLE001 - contained here: every drone ends with a defined outcome
        err = e
    if _is_actor_death(err) and _await_restart(actors[hid], restart_wait_s):
        restarts[hid] += 1
        print(f"aerodaas: drone actor {plan.actors[hid].name} died and was restarted; resuming "
              f"its mission", file=sys.stderr, flush=True)
        refs[actors[hid].run.remote(remaining(), resume=True)] = hid
        return
    why = (f"drone actor {plan.actors[hid].name} lost: {type(err).__name__}: {_first_line(err)}"
           if _is_actor_death(err) else error_cause(err))
    print(f"aerodaas: {why}", file=sys.stderr, flush=True)
    for rid in robots_of[hid]:
        cp = _last_checkpoint(actors.get("recorder"), rid)
        reports[rid] = _lost_report(rid, why, cp) if _is_actor_death(err) else \
            {**_lost_report(rid, why, cp), "outcome": "failed"}
        _record_result(actors.get("recorder"), plan, rid, reports[rid])


def _interrupt(handles: dict, refs: dict, reports: dict, robots_of: dict) -> None:
    """Ctrl-C: end every mission as ``interrupted`` and wait (bounded) for the reports of the runs in ``refs``."""
    import ray  # lazy: heavy ray

    for h in handles.values():
        try:
            ray.get(h["drone"].end_mission.remote("interrupted"), timeout=5)
        except Exception:  # noqa: BLE001 - an actor that is gone has nothing to end
            pass
    for ref, hid in list(refs.items()):
        try:
            reports.update(ray.get(ref, timeout=20))
        except Exception as e:  # noqa: BLE001
            for rid in robots_of[hid]:
                reports[rid] = {"robot": rid, "outcome": "interrupted", "error": _first_line(e)}


def error_cause(e: BaseException) -> str:
    """``Type: message`` of the exception an actor call failed with, without Ray's RayTaskError wrapping (whose
    first line names only the actor method and pid): the cause's type and the last line of its message."""
    cause = getattr(e, "cause", None)
    if isinstance(cause, BaseException):
        e = cause
    lines = str(e).strip().splitlines()
    return f"{type(e).__name__}: {lines[-1] if lines else ''}".rstrip(": ")


def _first_line(e: BaseException) -> str:
    s = str(e).strip().splitlines()
    return s[0] if s else type(e).__name__


def _last_checkpoint(recorder: Any, rid: str) -> dict | None:
    import ray  # lazy: heavy ray

    if recorder is None:
        return None
    try:
        sealed = ray.get(recorder.last_checkpoint.remote(rid), timeout=10)
        return None if sealed is None else sealed.open()
    except Exception:  # noqa: BLE001
        return None


def _record_result(recorder: Any, plan: Any, rid: str, rep: dict) -> None:
    import ray  # lazy: heavy ray

    if recorder is None:
        return
    epoch_ns = plan.actors["recorder"].spec.epoch_ns
    try:
        ray.get(recorder.mission_result.remote(rid, epoch_ns + int((rep.get("t") or 0.0) * 1e9), {
            "outcome": rep["outcome"], "visited": rep.get("visited", 0), "preplanned_total":
            rep.get("preplanned_total") or 0, "preplanned_reached": rep.get("preplanned_reached"),
            "t": rep.get("t") or 0.0, "error": rep.get("error")}), timeout=10)
    except Exception:  # noqa: BLE001 - reported in the summary anyway
        pass


def progress_lines(handles: dict, t0: float) -> list[str]:
    """One line per flying drone: time, state, waypoints, position, battery, camera FPS (a drone with a camera),
    detections, link, and the wall seconds its clock has waited for the recorder so far (a simulated run)."""
    import ray  # lazy: heavy ray

    lines = []
    for rid, h in handles.items():
        try:
            st = ray.get(h["drone"].status.remote(), timeout=2)
        except Exception:  # noqa: BLE001 - an actor restarting: no line this time
            continue
        if st.get("outcome"):
            continue
        rendered = st["frames"] - st["frames_dropped_at_camera"]  # frames actually captured, not skipped ticks
        fps = rendered / max(time.monotonic() - t0, 1e-6)
        dets = ""
        for a in h["analytics"].values():
            try:
                s = ray.get(a.stats.remote(), timeout=2)
            except Exception:  # noqa: BLE001
                continue
            if "frames_with_detections" in s:
                dets = f" detections {s['frames_with_detections']}/{s['frames']}"
                cloud = (s.get("frames_by_tier") or {}).get("cloud")
                if cloud:  # frames the analytics scheduler sent to the cloud (counted above too)
                    dets += f" (cloud {cloud})"
        x, y, z = st["position"]
        link = "" if st.get("link_ok", True) else " LINK LOST"
        # a simulated run's clock has waited for its recorder (recorder_hold_s), in all so far (wall s)
        held = f" clock held {st['clock_held_s']:.1f} s for the recorder" if st.get("clock_held_s", 0) >= 0.05 else ""
        cam = f" camera {fps:5.1f} FPS dropped {st['frames_dropped_at_camera']}" if st.get("cameras", 1) else ""
        lines.append(f"[{rid}] t={st['t']:6.1f}s {st['state']:<13} waypoint "
                     f"{waypoint_count(st['visited'], st['preplanned_total'], st.get('preplanned_reached'))} "
                     f"pos=({x:6.1f},{y:6.1f},{z:5.1f}) battery {pct(st['battery_pct'])}{cam}{dets}{link}{held}")
    return lines


def settle_actors(actors: dict, budget_s: float = 20.0, rounds: int = 6) -> bool:
    """Once the drones stopped: let every actor finish what it has in flight (see ``ActorBase.settle``), in rounds,
    until a round in which no actor had anything to wait for (a message handed on in one round may give another
    actor work) — at most ``rounds`` rounds and ``budget_s`` seconds in all. Returns True when the actors were
    found idle; an actor that is gone or does not answer counts as settled (its loss is reported elsewhere)."""
    import ray  # lazy: heavy ray

    deadline = time.monotonic() + budget_s
    for _ in range(rounds):
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        refs = [h.settle.remote(left) for h in actors.values()]
        done, _ = ray.wait(refs, num_returns=len(refs), timeout=left + 5)  # one bound for all of them
        waited = False
        for ref in done:
            try:
                waited = ray.get(ref, timeout=0).waited or waited
            except Exception:  # noqa: BLE001 - a dead or lost actor: nothing of it to wait for
                continue
        if not waited:
            return True
    return False


def collect_stats(handles: dict, actors: dict, plan: Any) -> tuple[dict, dict]:
    """Per-robot stats (scheduler, cameras, analytics) and per-frame latency from every actor still alive; an
    actor that is gone contributes ``{"error": ...}`` under ``_hosts``. Never raises."""
    import ray  # lazy: heavy ray

    flow = {hid: h for hid, h in actors.items() if plan.actors[hid].role != "recorder"}  # the data plane's actors
    t0 = time.monotonic()
    settled = settle_actors(flow)  # messages on their way between actors when the drones stopped: counted at both ends
    drains = [h.drain.remote() for hid, h in actors.items() if plan.actors[hid].role == "dispatcher"]
    for ref in drains:  # the analytics schedulers finish their tasks in flight before they report
        try:
            ray.get(ref, timeout=60)
        except Exception:  # noqa: BLE001 - a dispatcher that is gone reports what it can below
            pass
    if drains:
        settled = settle_actors(flow) and settled  # the tasks' results, handed on
    refs = {hid: h.stats.remote() for hid, h in actors.items()}
    host_stats: dict[str, dict] = {}
    for hid, ref in refs.items():
        try:
            host_stats[hid] = ray.get(ref, timeout=30)
        except Exception as e:  # noqa: BLE001 - a lost node, a dead actor: what is left is still reported
            host_stats[hid] = {"_host": {"error": f"{type(e).__name__}: {_first_line(e)}"}}
    every = {cid: s for hs in host_stats.values() for cid, s in hs.items() if not cid.startswith("_")}
    stats: dict[str, Any] = {"_hosts": {h: hs.get("_host", {}) for h, hs in host_stats.items()},
                             #: False: something was still in flight between actors when the counts were taken
                             "_settle": {"idle": settled, "s": round(time.monotonic() - t0, 3)}}
    scheds = [hs["_analytics_scheduler"] for hs in host_stats.values() if hs.get("_analytics_scheduler")]
    if len(scheds) == 1:
        stats["analytics_scheduler"] = scheds[0]
    elif scheds:
        stats["analytics_scheduler"] = _merge_scheduler_reports(scheds)
        stats["analytics_schedulers"] = scheds
    latency: dict[str, Any] = {}
    for rid, h in handles.items():
        s: dict[str, Any] = {"scheduler": every.get(h["scheduler"].cid, {})}
        s["cameras"] = {sid: every.get(c.cid, {}) for sid, c in h["cameras"].items()}
        s["analytics"] = [every.get(cid, {}) for cid in h["analytics"]]
        stats[rid] = s
        sch = s["scheduler"]
        if "e2e_ms" in sch:
            latency[rid] = {k: sch[k] for k in ("e2e_ms", "overhead_ms", "inference_ms")}
            latency[rid]["frames"] = sch["frames_with_latency"]
    return stats, latency


def _merge_scheduler_reports(reps: list[dict]) -> dict:
    """One summary of several dispatchers' reports (counts summed; rates recomputed from the sums)."""
    out: dict[str, Any] = {"scheduler": reps[0].get("scheduler"), "dispatchers": len(reps)}
    for key in ("submitted", "utility", "cloud_cost"):
        out[key] = sum(r.get(key, 0) or 0 for r in reps)
    for key in ("states", "tiers"):
        agg: dict[str, int] = {}
        for r in reps:
            for k, v in (r.get(key) or {}).items():
                agg[k] = agg.get(k, 0) + v
        out[key] = agg
    on_time = sum((r.get("on_time_rate", 0) or 0) * (r.get("submitted", 0) or 0) for r in reps)
    out["on_time_rate"] = on_time / out["submitted"] if out["submitted"] else 0.0
    return out
