"""The end-of-run summary ``aerodaas run`` prints (:func:`format_summary`)."""
from __future__ import annotations

from typing import Any


def waypoint_count(visited: int, preplanned: int | None, reached: int | None = None) -> str:
    """``3/4``: pre-planned waypoints ``reached`` of those ``preplanned`` (``?`` when unknown); with waypoints added
    in flight (HITL or analytics) also visited: ``1/4 pre-planned + 8 added in flight``. ``reached`` None (a
    report that does not say): ``visited`` of ``preplanned``, and ``747 reached (1 pre-planned, at least 746 added
    in flight)`` when more were visited than pre-planned."""
    if preplanned is None:
        return f"{visited}/?"
    if reached is not None:
        extra = visited - reached
        return f"{reached}/{preplanned}" + (f" pre-planned + {extra} added in flight" if extra else "")
    if visited <= preplanned:
        return f"{visited}/{preplanned}"
    return f"{visited} reached ({preplanned} pre-planned, at least {visited - preplanned} added in flight)"


def format_summary(result: Any) -> str:
    """Human-readable end-of-run summary (what ``aerodaas run`` prints): the outcome, per robot its flight, cameras,
    sensors, analytics and latency, the analytics scheduler, then the recording and what it lost."""
    lines = [f"mission outcome: {result.outcome}   wall time {result.wall_s:.1f} s"]
    lines += degraded_lines(getattr(result, "degraded", None) or [])
    acc = getattr(result, "recording_accounting", None) or {}
    for rid, rep in result.robots.items():
        st = result.stats.get(rid, {})
        lines += _robot_lines(rid, rep)
        lines += _camera_lines(st, rep)
        for sid, ps in (rep.get("plugin_sensors") or {}).items():  # from each sensor plug-in's declaration
            lines.append(f"    sensor {sid} ({ps['type']}): {ps['readings']} readings on {ps['topic']} "
                         f"[{ps['schema']}]" + (f", {ps['errors']} failed" if ps.get("errors") else ""))
        lines += _analytics_lines(rid, st, acc)
        lat = result.latency.get(rid)
        if lat:
            lines.append(f"    per-frame latency over {lat['frames']} frames: end-to-end median "
                         f"{lat['e2e_ms']['median']:.1f} ms (p99 {lat['e2e_ms']['p99']:.1f}), inference median "
                         f"{lat['inference_ms']['median']:.1f} ms, framework overhead median "
                         f"{lat['overhead_ms']['median']:.1f} ms (p99 {lat['overhead_ms']['p99']:.1f})")
    lines += _scheduler_lines(result.stats.get("analytics_scheduler"), acc)
    lines += _recording_lines(result)
    lines += _accounting_lines(acc)
    if getattr(result, "analytics_lost", None):
        lines.append(f"  analytics LOST: {', '.join(result.analytics_lost)} (its actor died and did not answer again "
                     f"within actor_restart_timeout_s; the lock-step clock went on without it)")
    for what in getattr(result, "insecure", None) or []:
        lines.append(f"  INSECURE: {what} was served in clear text off loopback (--insecure / hitl.insecure): its "
                     f"token and data could be read by anyone on that network")
    if getattr(result, "recording_duplicates", 0) and any(r.get("actor_restarts") for r in result.robots.values()):
        lines.append(f"  recording: {result.recording_duplicates} samples sent again by a restarted drone actor (stamps "
                     f"already recorded) were recorded once")
    return "\n".join(lines)


def degraded_lines(failing: list) -> list[str]:
    """One line per component over its failure limit (:class:`~aerodaas.recording.health.FailureCount`): what it
    is, how many of its attempts failed, its limit and its first error."""
    lines = []
    for c in failing:
        what = "readings" if c.kind.value == "sensor" else "items"
        lines.append(f"  DEGRADED: {c.label}: {c.failures} of {c.attempts} {what} failed "
                     f"({100.0 * c.failures / max(c.attempts, 1):.0f} %, limit max_failure_fraction "
                     f"{c.limit:g}); first error: {c.first_error}")
    return lines


def _robot_lines(rid: str, rep: dict) -> list[str]:
    """A robot's flight: time, waypoints, state, battery, how it ended, holds and targets it missed, the MAVLink
    link and failsafe, errors and drone actor restarts."""
    if "t" not in rep and rep.get("state") is None:  # no report from a drone actor: it never flew
        lines = [f"  robot {rid}: did not start"]
    else:
        t, total = rep.get("t", 0), rep.get("preplanned_total", 0)
        lines = [f"  robot {rid}: sim time " + ("unknown" if t is None else f"{t:.1f} s") +
                 f", waypoints {waypoint_count(rep.get('visited', 0), total, rep.get('preplanned_reached'))}, final state "
                 f"{rep.get('state')}, battery {pct(rep.get('battery_pct', 0))}"]
    if rep.get("ended"):
        lines.append(f"    ended: {rep['ended']}")
    for h in rep.get("hold_failed") or []:
        lines.append(f"    hold failed at {h['waypoint']}: {h['held_s']:g} of {h['needed_s']:g} s within "
                     f"{h['acceptance_radius']:g} m in {h['elapsed_s']:g} s (largest error {h['max_error_m']:g} m)")
    widened = [e for e in rep.get("events") or [] if e.get("event") == "waypoint_reached" and e.get("radius_widened")]
    if widened:
        lines.append("    holds widened to the vehicle's position accuracy (GPS_RAW_INT h_acc; hold.radius_from_vehicle): "
                     + ", ".join(f"{e['waypoint']} {e['radius_widened']['from_m']:g} -> {e['radius_widened']['to_m']:g} m"
                                 for e in widened))
    for h in rep.get("not_reached") or []:
        lines.append(f"    not reached: {h['waypoint']}: no progress towards it for {h['after_s']:g} s, "
                     f"{h['distance_m']:g} m from it (closest {h['closest_m']:g} m); the autopilot may have refused "
                     f"the target")
    lines += _speed_margin_lines(rep.get("events") or [])
    lines += _link_lines(rep.get("events") or [])
    waits = [e for e in rep.get("events") or [] if e.get("event") == "clock_held"]
    if rep.get("clock_held_s"):  # simulation.recorder_hold_s: simulated time waited instead of shedding frames
        held, budget = rep["clock_held_s"], rep.get("clock_hold_budget_s") or 0.0
        spent = budget and held >= budget - 0.05
        lines.append(f"    simulated clock held {held:.1f} s for the recorder ({len(waits)} wait(s), longest "
                     f"{max((e.get('held_s', 0.0) for e in waits), default=0.0):.1f} s, of {budget:g} s allowed by "
                     f"simulation.recorder_hold_s): " + ("the allowance is spent, later frames were dropped" if spent
                                                         else "frames waited instead of being dropped"))
    if rep.get("failsafe"):
        f = rep["failsafe"]
        lines.append(f"    autopilot failsafe: {f.get('mode')} at t={f.get('t', 0):.1f} s"
                     + (f" ({f['text']})" if f.get("text") else "") + f"; on_failsafe {f.get('action')}")
    if rep.get("error"):
        lines.append(f"    error: {rep['error']}")
    if rep.get("actor_restarts"):
        resumed = [e for e in rep.get("events", []) if e.get("event") == "resumed_after_restart"]
        at = "; ".join(f"resumed at t={e.get('checkpoint_t', 0):.1f} s heading to {e.get('heading_to')}"
                       for e in resumed)
        lines.append(f"    drone actor restarted {rep['actor_restarts']} time(s)" + (f": {at}" if at else ""))
    return lines


def _camera_lines(st: dict, rep: dict) -> list[str]:
    """A robot's cameras: frames, those never made because nothing took them (``record_fps``), drops, frames the
    recorder did not take at its rate, a video stream's decoding and outages, consumers whose actor died."""
    lines = []
    for sid, c in st.get("cameras", {}).items():
        if not c:
            continue
        dropped = sum(a.get("dropped", 0) for a in st.get("analytics", []) if a)
        if c.get("video"):
            lines.append(f"    camera {sid}: {c['frames']} frames from its video stream, {dropped} dropped by "
                         f"busy consumers")
        else:
            shed, not_made, skipped = c.get("shed_late", 0), c.get("frames_not_made", 0), c.get("record_skipped", 0)
            lines.append(f"    camera {sid}: {c['frames']} frames rendered ({c['render_ms_median']:.1f} ms median), "
                         + (f"{not_made} not made (nothing took them: record_fps {c.get('record_fps', 0):g}), "
                            if not_made else "")
                         + f"{rep.get('frames_dropped_at_camera', 0)} dropped at the camera"
                         + (f" ({shed} while the clock was late)" if shed else "")
                         + f", {dropped} dropped by busy consumers"
                         + (f", {skipped} not recorded (record_fps {c.get('record_fps', 0):g})" if skipped else ""))
        v = c.get("video")
        if v:  # a video stream: what was decoded, what newest-wins replaced, outages, capture-to-hand-off time
            lines.append(f"      video {v['source']}: {v['decoded']} decoded, {v['overwritten']} replaced by a newer "
                         f"frame before use, {v.get('not_recorded', 0)} not recorded (the drone's recorder "
                         f"queue full; the recorder actor's own refusals are in 'recording LOST'), "
                         f"{v['decode_errors']} damaged packets; {v['lost']} outage(s) "
                         f"({v['outage_s']:.1f} s without video, {v['restored']} restored); capture to "
                         f"hand-off {v['latency_ms_median']:.0f} ms median, {v['latency_ms_p99']:.0f} ms p99")
            if v.get("discovered"):  # source "mavlink": where the URL came from
                lines.append(f"      {v['source']} {v['discovered']}")
        for o in c.get("outlets") or []:  # a consumer whose actor died (and came back, or not)
            if o.get("reconnects") or o.get("held") or o.get("lost"):
                back = "did NOT come back" if o.get("lost") else \
                    f"was restarted ({o.get('reconnects', 0)} reconnect(s))"
                lines.append(f"      frames to {str(o.get('to'))}: its actor died and {back}; {o.get('failed', 0)} "
                             f"frame(s) in flight lost" + (f", {o['held']} held (lock-step) until it answered "
                                                           f"again" if o.get("held") else ""))
    return lines


def _analytics_lines(rid: str, st: dict, acc: dict) -> list[str]:
    """A robot's analytics: items processed, detections, commands, failures (their actor's own counts, which
    restart with it), and what the recording holds of each (counted from the file: it survives restarts)."""
    lines = []
    chans = acc.get("channels") or {}
    for a in st.get("analytics", []):
        if not a:
            continue
        extra = ""
        if "frames_with_detections" in a:
            extra = f", detections in {a['frames_with_detections']}/{a['frames']} frames"
        if "commands" in a:
            extra = f", {a['commands']} navigation commands"
        if a.get("failures"):
            extra += (f", {a['failures']} FAILED items (on_error={a.get('on_error')}; last: "
                      f"{a.get('last_failure')})")
        if a.get("named_outputs"):  # the analytics' declared outputs (aerodaas.analytics.contract)
            extra += ", outputs " + ", ".join(f"{k} {v}" for k, v in a["named_outputs"].items())
        if a.get("providers"):  # a detector with onnxruntime providers set (aerodaas.perception.providers)
            extra += f", on {'+'.join(a['providers'])} at {a.get('host')}"
            if a.get("provider_fallback"):
                extra += f" (asked {'+'.join(a.get('providers_requested') or [])}: not available there, CPU fallback)"
        if a.get("events"):  # what it recorded with emit_event, by kind
            extra += ", events " + ", ".join(f"{k} x{v}" for k, v in sorted(a["events"].items()))
        recorded = sum(c["recorded"] for t, c in chans.items() if t == f"/{rid}/{a['name']}"
                       or t.startswith(f"/{rid}/{a['name']}/"))
        extra += f"; {recorded} outputs in the recording" if chans else ""
        lines.append(f"    analytics {a['name']}: {a['processed']} items, {a['process_ms_median']:.1f} ms median{extra}")
    missing = sum(1 for a in st.get("analytics", []) if not a)
    if missing:
        lines.append(f"    {missing} analytics without a report (its actor died or is gone; see the recording's "
                     f"accounting below)")
    return lines


#: the order in which the summary lists the tasks' terminal states
_STATE_ORDER = ("done_on_time", "done_late", "dropped_time", "dropped_cost", "expired_edge", "failed")


def _scheduler_lines(sr: dict | None, acc: dict) -> list[str]:
    """The analytics scheduler's headline (tasks, on-time rate, tiers, utility, cloud cost, states) and its cloud
    executors lost. With a recording whose accounting tallies the task records (``acc["tasks"]``,
    :mod:`aerodaas.recording.task_tally`) the headline is the recording's, which survives dispatcher restarts, and
    the dispatchers' own count (``sr``, which restarts with their actor) is shown only where it differs; without
    one it is the dispatchers' own counts, with the task records in the recording when there is one."""
    tally = acc.get("tasks") if isinstance(acc.get("tasks"), dict) else None
    lines = []
    if tally is None:
        if sr:
            chans = acc.get("channels") or {}
            recorded = sum(c["recorded"] for t, c in chans.items() if t.endswith("/tasks"))
            lines.append(_headline(sr.get("scheduler"), f"{sr.get('submitted', 0)} tasks", sr.get("on_time_rate", 0),
                                   sr.get("tiers") or {}, sr.get("utility", 0), sr.get("cloud_cost", 0),
                                   sr.get("states") or {})
                         + (f"; {recorded} task records in the recording" if chans else ""))
    else:
        names = list(tally) or ([sr.get("scheduler")] if sr and sr.get("submitted") else [])
        for name in names:
            lines.append(_recorded_headline(name, tally.get(name) or {}, sr, len(names)))
    for ev in ((sr or {}).get("cloud") or {}).get("losses", []):
        lines.append(f"    cloud executor {ev.get('name')} lost at {ev.get('at_s', 0):.1f} s ({ev.get('error')}): "
                     f"{ev.get('in_flight', 0)} tasks in flight, {ev.get('retried', 0)} retried, "
                     f"{ev.get('failed', 0)} failed")
    return lines


def _recorded_headline(name: str, t: dict, sr: dict | None, schedulers: int) -> str:
    """The headline of scheduler ``name`` from the recording's tally ``t`` (``TaskCounts.as_dict``), with its
    dispatchers' own count from ``sr`` when it differs (a dispatcher actor restarted: its counts began at 0 again;
    or task records were lost). ``schedulers``: how many schedulers the tally has (more than one: ``sr``, a merged
    report, cannot be told apart and is not compared)."""
    n = int(t.get("tasks", 0))
    line = _headline(name, f"{n} tasks (from the recording)", (t.get("on_time", 0) / n) if n else 0.0,
                     t.get("tiers") or {}, t.get("utility", 0), (t.get("cost_by_tier") or {}).get("cloud", 0),
                     t.get("states") or {})
    own = sr.get("submitted") if sr and schedulers == 1 and sr.get("scheduler") == name else None
    if own is None and sr is None:
        return line + "; its dispatchers did not report"
    if own is not None and own != n:
        why = "since their last restart" if own < n else f"{own - n} more than the recording holds: task records lost"
        line += f"; its dispatchers counted {own} ({why})"
    return line


def _headline(name: Any, tasks: str, on_time: float, tiers: dict, utility: float, cloud_cost: float,
              states: dict) -> str:
    """``  analytics scheduler DEMS: <tasks>, on time x% (edge e, cloud c), utility U, cloud cost C; <states>``
    (``on_time``: a fraction; the states with a count, in :data:`_STATE_ORDER`, then any other)."""
    order = [k for k in _STATE_ORDER if k in states] + sorted(k for k in states if k not in _STATE_ORDER)
    return (f"  analytics scheduler {name}: {tasks}, on time {100 * (on_time or 0):.1f}% (edge {tiers.get('edge', 0)}, "
            f"cloud {tiers.get('cloud', 0)}), utility {utility or 0:.0f}, cloud cost {cloud_cost or 0:.0f}; "
            + ", ".join(f"{k} {states[k]}" for k in order if states[k]))


def _recording_lines(result: Any) -> list[str]:
    """The recording: its file or segments and message counts, a disk failure, each recorder actor death."""
    lines = []
    if result.recording:
        total = sum(result.recording_counts.values())
        fail = result.recording_failure
        if fail is None:
            segs = getattr(result, "recording_segments", None) or []
            if len(segs) > 1:
                # the earlier segments' counts (None: unreadable or not reported), then the last one's
                before = (list(getattr(result, "recording_segment_messages", None) or []) + [None] * len(segs))[
                    :len(segs) - 1]
                per = ["?" if n is None else str(n) for n in before] + [str(total)]
                whole = f"{sum(before) + total} messages" if None not in before else \
                    "? messages (a segment could not be read)"
                lines.append(f"  recording: {result.recording} in {len(segs)} segments ({', '.join(segs)}): {whole} "
                             f"({' + '.join(per)}), the last one on {len(result.recording_counts)} channels")
            else:
                lines.append(f"  recording: {result.recording} ({total} messages on {len(result.recording_counts)} "
                             f"channels)")
        else:
            at = fail.get("last_recorded_ns")
            held = f"up to {(at - result.recording_start_ns) / 1e9:.1f} s" if at and result.recording_start_ns else \
                "nothing"
            state = "finished" if fail.get("finished") else ("UNFINISHED (" + str(fail.get("finish_error")) +
                                                              "; run `aerodaas recover FILE` when there is room)")
            lines.append(f"  recording: FAILED: {fail.get('error')}; {result.recording} holds {held} "
                         f"({fail.get('messages_in_file', '?')} messages, {state}); "
                         f"{result.recording_lost} later messages were not recorded")
    nodes = getattr(result, "recording_nodes", None) or []
    if nodes:  # recording.per_node: the rest of the run is in the node recorders' files
        lines.append(f"  recording: and one file per node: {', '.join(nodes)} (one file: aerodaas merge "
                     f"{result.recording} {' '.join(nodes)} --out ALL.mcap)")
    for loss in getattr(result, "recording_losses", None) or []:
        lines.append(_loss_line(loss, result))
    return lines


def _loss_line(loss: dict, result: Any) -> str:
    """One death of the recorder actor: where its segment ends, where the recording went on."""
    until = loss.get("recorded_until_ns")
    start = result.recording_start_ns
    at = f"t = {(until - start) / 1e9:.1f} s" if until and start else "t = ? (the segment could not be read)"
    resumed = loss.get("resumed_at_ns")
    back = f", recording again from t = {(resumed - start) / 1e9:.1f} s" if resumed and start else ""
    if loss.get("next_segment"):
        return (f"  recording lost at {at}: the recorder actor died; {loss.get('segment')} ends there"
                f"{back} in {loss['next_segment']} (join the segments: `aerodaas recover "
                f"{result.recording}`)" + (f"; {loss['error']}" if loss.get("error") else "")
                + (f"; the live view was NOT served again ({loss['live_error']})" if loss.get("live_error") else ""))
    # it died at the end (with its node): nothing recorded after, the driver finished the file if it could
    done = "the driver finished it" if loss.get("previous_finished") else \
        f"UNFINISHED: run `aerodaas recover {loss.get('segment')}`"
    return (f"  recording lost at {at}: the recorder actor died; {loss.get('segment')} ends there "
            f"({done})" + (f"; {_first(loss['error'])}" if loss.get("error") else ""))


def _accounting_lines(acc: dict) -> list[str]:
    """What the recording lacks per channel (:mod:`aerodaas.recording.accounting`: the producers' sequence
    numbers against the messages in the file), or that it lacks nothing."""
    chans = acc.get("channels") or {}
    if not chans:
        return []
    lost = acc.get("lost") or {}
    produced = sum(c["produced"] - c["duplicates"] for c in chans.values())
    if not lost:
        return [f"  recording accounting: all {produced} numbered messages of {len(chans)} channels are recorded"]
    lines = [f"  recording LOST {acc.get('lost_total', 0)} of {produced} numbered messages on {len(lost)} channel(s) "
             f"(their producers' sequence numbers against the file):"]
    for topic, n in lost.items():
        c = chans[topic]
        lines.append(f"    {topic}: {n} lost, {c['recorded']} of {c['produced'] - c['duplicates']} recorded")
    return lines


def pct(v: float | None) -> str:
    """A battery percentage for humans; None (a log without battery data) is "unknown"."""
    return "unknown" if v is None else f"{v:5.1f}%"


def _first(text: str, limit: int = 160) -> str:
    """The first line of ``text``, at most ``limit`` characters."""
    line = str(text).splitlines()[0] if str(text) else ""
    return line if len(line) <= limit else line[:limit - 3] + "..."


def _speed_margin_lines(events: list[dict]) -> list[str]:
    """What the MAVLink backend's speed margin did (aerodaas/backends/mavlink/speed_margin.py): the vehicle's own
    limit lowered for its estimator (the last time), or a ``max_speed`` no limit could hold."""
    out = []
    e = _last(events, "speed_margin")
    if e is not None:
        out.append(f"    speed limit lowered to {e.get('cap_mps')} m/s: the vehicle flew up to {e.get('margin_mps')} m/s "
                   f"faster than its estimate (GNSS, p99 of {e.get('samples')} samples)")
    for e in events:
        if e.get("event") == "speed_limit_unholdable":
            out.append(f"    speed limit NOT holdable: the vehicle flies up to {e.get('margin_mps')} m/s faster than its "
                       f"estimate (GNSS, p99 of {e.get('samples')} samples), more than max_speed {e.get('max_speed')} "
                       f"m/s leaves room for (the vehicle's own limit: {e.get('cap_mps')} m/s)")
    return out


def _link_lines(events: list[dict]) -> list[str]:
    """What the MAVLink backend counted of its link (aerodaas/backends/mavlink/shared_link.py
    ``PortLosses.report``): the vehicle's messages lost before this process by their sequence numbers, and those its shared link's queue
    dropped, from the last report of each (reports come at most every 5 s: the counts are lower bounds)."""
    out = []
    e = _last(events, "link_messages_lost")
    if e is not None:
        out.append(f"    MAVLink link: at least {e.get('total')} of {e.get('total', 0) + e.get('received', 0)} messages "
                   f"from the vehicle lost on the way ({e.get('lost_pct')} %, by their sequence numbers)")
    e = _last(events, "link_messages_dropped")
    if e is not None:
        out.append(f"    MAVLink link: {e.get('total')} messages of the vehicle dropped here (this process fell behind)")
    e = _last(events, "link_not_signed")  # aerodaas/backends/mavlink/signing.py NoSigning.announce
    if e is not None:
        out.append(f"    MAVLink link NOT SIGNED ({e.get('connection')}): anyone who could put a packet on it could "
                   f"command the vehicle or send telemetry in its name (set mavlink.signing_key_file; "
                   f"docs/security.md)")
    for name, what in (("link_unsigned", "unsigned"), ("link_bad_signature", "wrongly signed or replayed")):
        e = _last(events, name)  # MAVLink 2 signing (aerodaas/backends/mavlink/signing.py RejectReport)
        if e is not None:
            out.append(f"    MAVLink signing: at least {e.get('total')} {what} messages in the vehicle's name dropped")
    return out


def _last(events: list[dict], name: str) -> dict | None:
    """The last event called ``name``, or None."""
    return next((e for e in reversed(events) if e.get("event") == name), None)
