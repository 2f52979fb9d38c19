"""Fault injection for ``python -m aerodaas.reliability`` and the ``faults`` tests: real ``aerodaas run`` processes
on the simulator (the farm survey), each given one fault, each checked for a clean end — the documented exit code,
a finished recording that mcap's own seeking reader accepts, a summary that says what happened, no traceback and no
abort. Also renders the report (``docs/reliability.md``)."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

from mcap.reader import make_reader

from aerodaas.clusters.reaper import descendants, start_time
from aerodaas.config.robot import sensor_class
from aerodaas.recording.writer import McapRecorder
from aerodaas.recording.reader import read_messages, summarize_mcap
from aerodaas.reliability.accounting_faults import ACCOUNTING_FAULTS, accounting_verdict
from aerodaas.reliability.input_report import render_input_rows, render_inputs
from aerodaas.reliability.procs import (REPO_APPS, actor_pids, argv0, mcap_reader_ok, no_crash, run_cli,
                                       summary_outcome, wait_size)
from aerodaas.tools.hitl_client import request

__all__ = ["FAULTS", "run_faults", "render", "mcap_reader_ok"]


FAILING_APP = '''
from aerodaas import *

class Flaky(MonitoringAnalytics):
    """Raises on every 10th odometry sample (an analytics bug)."""
    name = "flaky"
    on_error = ON_ERROR
    n = 0
    def process(self, odom, meta):
        self.n += 1
        if self.n % 10 == 0:
            raise RuntimeError(f"flaky analytics: bad sample {self.n}")
        return super().process(odom, meta)

env = Environment(ENV)
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
flaky = Flaky(["battery", "height"])
flaky.deploy(env.get_compute_resource_by_id("edge"))
flaky.analyse(drone.get_sensor_by_id("odom").get_data_stream())
wps = [Waypoint(id=f"wp{i}", x=x, y=y, z=1.5, hover_duration=1) for i, (x, y) in enumerate([(0, 0), (0, 4), (4, 4)])]
drone.navigate(scheduler.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.ORDERED)))
result = drone.start_mission()
'''


#: a run stopped by a signal or ``--timeout`` ends within this (s) of it, at any speedup the config allows
STOP_WITHIN_S = 60.0


def _signal_case(sig: int, min_size: int, group: bool = False, speedup: float = 1.0) -> Callable[[Path], dict]:
    def run(tmp: Path) -> dict:
        rec = tmp / "run.mcap"
        p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", f"{speedup:g}",
                  "--quiet"], start_new_session=True,
                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        reached = wait_size(rec, min_size, p)
        if group:
            os.killpg(p.pid, sig)
        else:
            p.send_signal(sig)
        t_sig = time.monotonic()
        out, _ = p.communicate(timeout=300)
        took = time.monotonic() - t_sig
        ok, n, why = mcap_reader_ok(rec)
        outcome = None
        if rec.exists():
            outcome = (summarize_mcap(rec).get("mission") or {}).get("outcome")
        want = 128 + sig
        clean = reached and p.returncode == want and ok and no_crash(out) and took <= STOP_WITHIN_S
        late = "" if reached else " (the run had not reached the phase to interrupt: machine too loaded)"
        return {"observed": f"exit {p.returncode} {took:.1f} s after the signal, recording "
                            f"{'finished' if ok else why} ({n} msgs), outcome {outcome}{late}", "clean": clean,
                "exit": p.returncode, "output": out[-3000:]}
    return run


def _timeout_case(speedup: float, timeout_s: float, in_app: bool = False) -> Callable[[Path], dict]:
    """``--timeout`` (``in_app``: ``start_mission(timeout=...)`` in a copy of the farm survey instead) at an extreme
    speedup: the run ends as ``timeout`` (exit 1) with a finished recording, within :data:`STOP_WITHIN_S` of the
    timeout, counted from when the recording file appears (the recorder opens it while the actors set up, before
    the mission starts: Ray's own start, 40 s and more on a loaded 2-core machine, is not the timeout's to bound)."""
    def run(tmp: Path) -> dict:
        rec, app = tmp / "run.mcap", tmp / "farm_survey.py"
        src = (REPO_APPS / "farm_survey.py").read_text()
        app.write_text(src.replace("start_mission()", f"start_mission(timeout={timeout_s!r})") if in_app else src)
        (tmp / "farm_survey.json").write_text((REPO_APPS / "farm_survey.json").read_text())
        flag = [] if in_app else ["--timeout", f"{timeout_s:g}"]
        p = run_cli(["run", str(app), "--record", str(rec), "--speedup", f"{speedup:g}", *flag, "--quiet"],
                 start_new_session=True)
        t0 = time.monotonic()
        if wait_size(rec, 1, p):
            t0 = time.monotonic()
        out, _ = p.communicate(timeout=timeout_s + 600)
        took = time.monotonic() - t0
        ok, n, why = mcap_reader_ok(rec)
        said = "mission outcome: timeout" in out
        clean = p.returncode == 1 and said and ok and no_crash(out) and took <= timeout_s + STOP_WITHIN_S
        return {"observed": f"exit {p.returncode} {took:.1f} s after the recording opened (timeout {timeout_s:g} s), "
                            f"outcome timeout {said}, recording {'finished' if ok else why} ({n} msgs)", "clean": clean,
                "exit": p.returncode, "output": out[-3000:]}
    return run


def _disk_case(kind: str, after_bytes: int) -> Callable[[Path], dict]:
    def run(tmp: Path) -> dict:
        rec = tmp / "run.mcap"
        p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "20", "--quiet"],
                 env={"AERODAAS_FAULT_RECORDER": f"{kind}:{after_bytes}"})
        out, _ = p.communicate(timeout=600)
        ok, n, why = mcap_reader_ok(rec)
        said = "recording: FAILED" in out and "not recorded" in out
        clean = p.returncode == 1 and ok and said and no_crash(out)
        line = next((ln.strip() for ln in out.splitlines() if "recording:" in ln), "(no recording line)")
        return {"observed": f"exit {p.returncode}, recording {'finished' if ok else why} ({n} msgs); summary: "
                            f"{line[:160]}", "clean": clean, "exit": p.returncode, "output": out[-3000:]}
    return run


def _analytics_case(on_error: str) -> Callable[[Path], dict]:
    def run(tmp: Path) -> dict:
        env = json.loads((REPO_APPS / "farm_survey.json").read_text())

        env["robots"][0]["sensors"] = [s for s in env["robots"][0]["sensors"]
                                       if not sensor_class(s["type"]).delivery.frames]
        (tmp / "env.json").write_text(json.dumps(env))
        app = tmp / "flaky_app.py"
        app.write_text(FAILING_APP.replace("ENV", repr(str(tmp / "env.json"))).replace("ON_ERROR", repr(on_error)))
        rec = tmp / "run.mcap"
        p = run_cli(["run", str(app), "--record", str(rec), "--speedup", "20", "--quiet"])
        out, _ = p.communicate(timeout=600)
        ok, n, why = mcap_reader_ok(rec)

        events = [m for _, _, _, m in read_messages(rec, ["/quadrotor_base/events"])
                  if m.get("event") == "analytics_error"] if rec.exists() else []
        outcome = (summarize_mcap(rec).get("mission") or {}).get("outcome") if rec.exists() else None
        with_tb = bool(events) and all("Traceback" in e.get("traceback", "") for e in events)
        counted = "FAILED items" in out
        logged = "RuntimeError: flaky analytics" in out
        if on_error == "continue":
            clean = p.returncode == 0 and outcome == "success"
        else:
            clean = p.returncode == 1 and outcome == "failed" and len(events) >= 1
        clean = clean and ok and with_tb and counted and logged
        return {"observed": f"exit {p.returncode}, outcome {outcome}, {len(events)} analytics_error events with "
                            f"traceback={with_tb}, counted in summary={counted}, logged={logged}, recording "
                            f"{'finished' if ok else why}", "clean": clean, "exit": p.returncode,
                "output": out[-3000:], "events": len(events)}
    return run


def _sigkill_recover(tmp: Path) -> dict:
    rec = tmp / "run.mcap"
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "1", "--quiet"],
             start_new_session=True)
    reached = wait_size(rec, 30000, p)
    os.killpg(p.pid, signal.SIGKILL)
    p.communicate(timeout=60)
    last, t0 = -1, time.monotonic()  # Ray's worker holding the recorder dies with its parent: wait for the file
    while rec.exists() and time.monotonic() - t0 < 120:  # to stop growing
        size = rec.stat().st_size
        if size == last:
            break
        last = size
        time.sleep(3.0)
    before_ok, _, before_why = mcap_reader_ok(rec)

    seen = summarize_mcap(rec)["message_count"] if rec.exists() else 0
    r = subprocess.run([sys.executable, "-m", "aerodaas.cli", "recover", str(rec)], capture_output=True, text=True,
                       timeout=300)
    ok, n, why = mcap_reader_ok(rec)
    clean = reached and not before_ok and r.returncode == 0 and ok and n == seen
    return {"observed": f"before: mcap reader says {before_why!r}; `aerodaas recover` exit {r.returncode}; after: "
                        f"{'finished' if ok else why}, {n} of the {seen} readable messages", "clean": clean}


def _kill_mid_run(args: list[str], rec: Path, min_size: int, targets: Callable[[int], list[int]],
                  timeout_s: float = 600.0) -> tuple[subprocess.Popen, str, bool, list[int]]:
    """``aerodaas run *args`` (its own session); once ``rec`` holds ``min_size`` bytes, SIGKILL the pids
    ``targets(driver pid)`` names, then wait for the run. Returns (process, output, reached, pids killed)."""
    p = run_cli(["run", *args, "--record", str(rec), "--quiet"], start_new_session=True)
    reached = wait_size(rec, min_size, p)
    pids = targets(p.pid) if reached else []
    for pid in pids:
        os.kill(pid, signal.SIGKILL)
    out, _ = p.communicate(timeout=timeout_s)
    return p, out, reached, pids


def _detector_kill_lockstep(tmp: Path) -> dict:
    """``apps/vehicle_tracking.py`` as shipped (lock-step on, YOLOX-Nano in its own analytics actor): SIGKILL of the
    detector's process mid-flight. Ray restarts it, the clock waits for it, the mission flies on; the summary says
    the detector's actor died and was restarted (never the drone's), and the recording's detections have one hole,
    at the kill (the frames in flight and the results not yet handed to the recorder). Those frames were offered to
    the detector and never answered: the recording's accounting counts them lost, so the run ends ``recording_lost``
    (exit 4) with the summary's lost count per channel equal to what the file lacks — never ``success`` with a
    hole (exit 0 only when nothing was in flight at the kill)."""
    model = Path(os.environ.get("AERODAAS_MODEL_DIR", "")) / "yolox_nano.onnx"
    imagery = Path(os.environ.get("AERODAAS_DATA_DIR", "")) / "imagery"
    if not model.is_file() or not imagery.is_dir():
        return {"observed": "not run: set AERODAAS_MODEL_DIR (yolox_nano.onnx) and AERODAAS_DATA_DIR (imagery)",
                "clean": False}
    rec = tmp / "run.mcap"
    p, out, reached, pids = _kill_mid_run([str(REPO_APPS / "vehicle_tracking.py")], rec, 1_500_000,
                                          lambda root: actor_pids(root, "AnalyticsActor"), 900.0)
    told = re.search(r"frames to detector#1: its actor died and was restarted \(1 reconnect\(s\)\); (\d+) frame",
                     out)
    hole = _frames_without_detections(rec)
    one_hole = bool(hole) and len(hole) <= 12 and hole == list(range(hole[0], hole[0] + len(hole)))
    said = (f"the summary says the detector's actor died and was restarted: {told is not None} "
            f"({told.group(1) if told else '?'} frame(s) in flight lost); frames without detections "
            f"{hole[:12]}{' (one hole, at the kill)' if one_hole else ''}")
    res = accounting_verdict(p, out, rec, reached and len(pids) == 1,
                             told is not None and "drone actor" not in out and (one_hole or not hole), said)
    res["clean"] = res["clean"] and (one_hole or not res["lost"])  # a loss is the hole at the kill, nothing else
    return res


def _frames_without_detections(rec: Path) -> list[int]:
    """Indices of the camera frames of ``rec`` (``/quadrotor_base/camera/cam1``) with no detections message of the
    same log time; [] when the file is unreadable."""
    ok, _, _ = mcap_reader_ok(rec)
    if not ok:
        return []

    times: dict[str, list[int]] = {}
    with open(rec, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages(log_time_order=True):
            times.setdefault(ch.topic, []).append(m.log_time)
    dets = set(times.get("/quadrotor_base/detector/detections", []))
    return [i for i, t in enumerate(times.get("/quadrotor_base/camera/cam1", [])) if t not in dets]


def _raylets(root: int) -> list[int]:
    """Pids of the raylet processes below ``root``."""
    return [pid for pid in descendants(root) if (argv0(pid) or "").rsplit("/", 1)[-1] == "raylet"]


def _raylet_kill(tmp: Path) -> dict:
    """SIGKILL of the raylet (the node's manager) mid-run: every actor of the local node dies with it, the recorder
    included. Exit 3 (a drone actor lost), the summary says the drone's time is unknown (not a flight of 0 s), and
    the driver itself finishes the recording, which mcap's reader then accepts."""
    rec = tmp / "run.mcap"
    p, out, reached, killed = _kill_mid_run([str(REPO_APPS / "farm_survey.py"), "--speedup", "4"], rec, 20000,
                                            _raylets)
    ok, n, why = mcap_reader_ok(rec)
    summary = out[out.find("mission outcome:"):] if "mission outcome:" in out else ""
    unknown = "sim time unknown" in summary and "sim time 0.0 s" not in summary
    said = "the driver finished it" in summary
    clean = reached and len(killed) == 1 and p.returncode == 3 and ok and n > 0 and unknown and said
    return {"observed": f"exit {p.returncode}; summary: sim time unknown {unknown}, 'the driver finished it' {said}; "
                        f"recording {'finished' if ok else why} ({n} msgs)", "clean": clean, "exit": p.returncode,
            "output": out[-3000:]}


#: how long a run's processes may outlive a SIGKILLed driver (s: none may live beyond 10 s), and the bound the
#: test allows on a loaded machine; Ray's agents alone stay 60-64 s (:mod:`aerodaas.clusters.reaper`)
GONE_WITHIN_S, GONE_WITHIN_LOADED_S = 10.0, 25.0


def _driver_sigkill(tmp: Path) -> dict:
    """SIGKILL of the driver alone (as the OOM killer does) mid-flight: every process below it -- Ray's GCS,
    raylet, dashboard and runtime-env agents, the workers -- must be gone soon after, the reaper included."""
    rec = tmp / "run.mcap"
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "2", "--quiet"],
             start_new_session=True)
    reached = wait_size(rec, 20000, p)
    procs = {}
    for pid in descendants(p.pid):
        t, cmd = start_time(pid), argv0(pid)
        if t is not None and cmd is not None:
            procs[pid] = (t, cmd)
    p.kill()
    p.communicate(timeout=60)
    t0 = time.monotonic()
    alive = dict(procs)
    while alive and time.monotonic() - t0 < 120:
        alive = {q: v for q, v in alive.items() if start_time(q) == v[0]}
        time.sleep(0.2)
    gone_s = time.monotonic() - t0
    names = sorted({v[1].split("/")[-1][:40] for v in procs.values()})
    agents = any("Agent" in n for n in names)
    clean = reached and agents and not alive and gone_s <= GONE_WITHIN_LOADED_S
    return {"observed": f"{len(procs)} processes below the driver ({', '.join(names)}): "
                        + (f"all gone {gone_s:.1f} s after the kill" if not alive else
                           f"{len(alive)} still alive after {gone_s:.0f} s: "
                           f"{sorted(v[1][:40] for v in alive.values())}"),
            "clean": clean, "gone_s": gone_s}


def _recorder_kill(tmp: Path) -> dict:
    """SIGKILL of the recorder actor's process mid-run: the run must say "recording lost at t = ...", exit 4, the
    recorder go on in ``run.1.mcap``, and ``aerodaas recover run.mcap`` join both into one readable file."""
    rec = tmp / "run.mcap"
    p, out, reached, pids = _kill_mid_run([str(REPO_APPS / "farm_survey.py"), "--speedup", "4"], rec, 20000,
                                          lambda root: actor_pids(root, "RecorderActor"))
    seg1 = tmp / "run.1.mcap"
    ok0, n0, why0 = mcap_reader_ok(rec)
    ok1, n1, why1 = mcap_reader_ok(seg1) if seg1.exists() else (False, 0, "no segment run.1.mcap")
    said = "recording lost at t = " in out
    m = re.search(r"in 2 segments \(.*\): (\d+) messages \((\d+) \+ (\d+)\)", out)
    summed = (int(m.group(1)), int(m.group(2)), int(m.group(3))) if m else None  # the summary's own counts
    r = subprocess.run([sys.executable, "-m", "aerodaas.cli", "recover", str(rec)], capture_output=True, text=True,
                       timeout=300)
    ok, n, why = mcap_reader_ok(rec)
    outcome = None
    if ok:
        outcome = (summarize_mcap(rec).get("mission") or {}).get("outcome")
    clean = (reached and len(pids) == 1 and p.returncode == 4 and said and "success" not in summary_outcome(out)
             and ok0 and ok1 and r.returncode == 0 and ok and n == n0 + n1 and not seg1.exists() and no_crash(out)
             and summed == (n0 + n1, n0, n1) and outcome == "recording_lost")
    return {"observed": f"exit {p.returncode}, says 'recording lost at t = ...' {said}; segments: run.mcap "
                        f"{'finished' if ok0 else why0} ({n0} msgs), run.1.mcap {'finished' if ok1 else why1} ({n1} "
                        f"msgs); `aerodaas recover` exit {r.returncode}: joined {'finished' if ok else why} ({n} "
                        f"msgs, outcome {outcome}); the summary counts {summed[0] if summed else '?'} messages "
                        f"({' + '.join(map(str, summed[1:])) if summed else 'not summed'})", "clean": clean,
            "exit": p.returncode, "output": out[-3000:]}


def _signal_after_summary(sig: int) -> Callable[[Path], dict]:
    """``sig`` sent right after the summary is printed (the app ending, Ray shutting down): no traceback, and the
    exit code stays the mission's (0 for the survey)."""
    def run(tmp: Path) -> dict:
        rec = tmp / "run.mcap"
        p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "20", "--quiet"],
                 start_new_session=True)
        lines, sent = [], 0
        assert p.stdout is not None
        for line in p.stdout:
            lines.append(line)
            if line.startswith("mission outcome:"):
                break
        if p.poll() is None:  # one signal, as a user's Ctrl-C or a `kill` right after the summary
            p.send_signal(sig)
            sent += 1
        rest, _ = p.communicate(timeout=300)
        out = "".join(lines) + rest
        ok, n, why = mcap_reader_ok(rec)
        success = "mission outcome: success" in out
        clean = sent >= 1 and success and p.returncode == 0 and ok and no_crash(out) and \
            "KeyboardInterrupt" not in out
        return {"observed": f"{sent} signal(s) after the summary; exit {p.returncode}, outcome success {success}, "
                            f"KeyboardInterrupt {'KeyboardInterrupt' in out}, recording "
                            f"{'finished' if ok else why} ({n} msgs)", "clean": clean, "exit": p.returncode,
                "output": out[-3000:]}
    return run


def _hitl_clear_all(tmp: Path) -> dict:
    """The farm survey with the HITL API: once the drone has reached its first waypoint, a ``clear`` with a null
    body (refused, 422) and then ``{"scope": "all"}``: the pre-planned survey is gone, so the run must not report
    success (outcome incomplete, exit 1), and the summary says how many of the 4 waypoints were flown."""
    rec = tmp / "run.mcap"
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "4", "--quiet", "--hitl",
              "--hitl-port", "0"], env={"AERODAAS_STATE_DIR": str(tmp / "state")})
    assert p.stdout is not None
    lines, url, token = [], None, None
    for line in p.stdout:
        lines.append(line)
        m = re.search(r"human-in-the-loop API at (\S+)\s+\(bearer token .*: in (\S+), owner only\)", line)
        if m:  # the token is never printed: it is in the owner-only state file
            url, token = m.group(1), json.loads(Path(m.group(2)).read_text())["token"]
            break
    null_status = clear_status = None
    visited = 0
    t0 = time.monotonic()
    while url and p.poll() is None and time.monotonic() - t0 < 300:
        try:
            _, st = request("GET", "/drones/quadrotor_base", url=url, token=token, timeout=30)
            visited = st.get("visited", 0) if isinstance(st, dict) else 0
        except RuntimeError:
            break
        if visited >= 1:
            null_status, _ = request("POST", "/drones/quadrotor_base/clear", None, url=url, token=token, timeout=30)
            clear_status, _ = request("POST", "/drones/quadrotor_base/clear", {"scope": "all"}, url=url, token=token,
                                      timeout=30)
            break
        time.sleep(0.5)
    rest, _ = p.communicate(timeout=600)
    out = "".join(lines) + rest
    outcome = summary_outcome(out)
    m = re.search(r"waypoints (\d+)/(\d+)", out)
    flown = f"{m.group(1)}/{m.group(2)}" if m else "?"
    clean = (null_status == 422 and clear_status == 200 and p.returncode == 1 and "incomplete" in outcome and
             m is not None and int(m.group(1)) < int(m.group(2)) and no_crash(out))
    return {"observed": f"clear null body {null_status}, clear scope all {clear_status} after {visited} waypoint(s); "
                        f"exit {p.returncode}, {outcome.strip() or 'no summary'}, waypoints {flown}", "clean": clean,
            "exit": p.returncode, "output": out[-3000:]}


def _broken_pipe(tmp: Path) -> dict:
    rec = tmp / "small.mcap"
    with McapRecorder(rec) as r:
        for i in range(50):
            r.write_json(f"/topic/{i}", 1_000 + i, {"i": i}, schema_name="t.T")
    rd, wr = os.pipe()
    os.close(rd)  # the reader (`head`) is gone before anything is written
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "info", str(rec)], stdout=wr, stderr=subprocess.PIPE,
                       text=True, timeout=120)
    os.close(wr)
    clean = p.returncode == 141 and "Traceback" not in p.stderr and "BrokenPipe" not in p.stderr
    return {"observed": f"exit {p.returncode}, stderr {p.stderr.strip()[:80]!r}", "clean": clean}


#: (name, expected end, scenario(tmp folder) -> {"observed", "clean", ...})
FAULTS: list[tuple[str, str, Callable[[Path], dict]]] = [
    ("SIGTERM during the flight", "exit 143, recording finished, outcome interrupted", _signal_case(signal.SIGTERM, 20000)),
    ("SIGTERM while the actors start", "exit 143, recording finished", _signal_case(signal.SIGTERM, 1)),
    ("SIGTERM at the slowest speedup (0.01)", f"exit 143 within {STOP_WITHIN_S:g} s, recording finished",
     _signal_case(signal.SIGTERM, 5000, speedup=0.01)),
    ("--timeout 8 at the slowest speedup (0.01)", f"exit 1, outcome timeout, within {STOP_WITHIN_S:g} s of the "
     "timeout, recording finished", _timeout_case(0.01, 8.0)),
    ("start_mission(timeout=8) in the app at the slowest speedup (0.01)", f"exit 1, outcome timeout, within "
     f"{STOP_WITHIN_S:g} s of the timeout, recording finished", _timeout_case(0.01, 8.0, in_app=True)),
    ("Ctrl-C (SIGINT to the process group) during the flight", "exit 130, recording finished",
     _signal_case(signal.SIGINT, 20000, group=True)),
    ("disk full (ENOSPC) mid-run", "exit 1, summary says what was lost, recording finished up to the failure",
     _disk_case("enospc", 150_000)),
    ("I/O error (EIO) mid-run", "exit 1, summary says what was lost, recording finished up to the failure",
     _disk_case("eio", 60_000)),
    ("analytics raising every 10th item, on_error=continue", "exit 0, errors logged with traceback, recorded as "
     "events, counted in the summary", _analytics_case("continue")),
    ("analytics raising, on_error=abort", "exit 1, outcome failed, recording finished", _analytics_case("abort")),
    ("SIGKILL mid-run, then `aerodaas recover`", "recover exit 0; mcap's seeking reader accepts the file",
     _sigkill_recover),
    ("`aerodaas info FILE | head` (reader gone)", "exit 141, no BrokenPipeError", _broken_pipe),
    ("SIGTERM right after the summary", "exit 0 (the mission's), no KeyboardInterrupt traceback",
     _signal_after_summary(signal.SIGTERM)),
    ("SIGINT right after the summary", "exit 0 (the mission's), no KeyboardInterrupt traceback",
     _signal_after_summary(signal.SIGINT)),
    ("HITL clear of the pre-planned survey mid-flight", "null body 422; scope all 200; outcome incomplete, exit 1 "
     "(never success with 1 of 4 waypoints)", _hitl_clear_all),
    ("SIGKILL of the driver alone mid-run", f"every process of the run (Ray's agents included) gone within "
     f"{GONE_WITHIN_S:g} s (the test allows {GONE_WITHIN_LOADED_S:g} s on a loaded machine)", _driver_sigkill),
    ("SIGKILL of the YOLOX detector actor under lock-step (apps/vehicle_tracking.py)", "exit 4, recording_lost "
     "(the frames in flight at the kill were never answered; exit 0 only if none was); the summary names the "
     "detector's actor as died and restarted and its lost counts per channel equal what the file lacks; one hole in "
     "the recorded detections, at the kill",
     _detector_kill_lockstep),
    ("SIGKILL of the raylet mid-run", "exit 3, the summary says the drone's time is unknown (not 0 s), the "
     "driver finishes the recording", _raylet_kill),
    ("SIGKILL of the recorder actor mid-run", "exit 4, 'recording lost at t = ...', recording goes on in "
     "run.1.mcap, the summary counts the messages of both segments, `aerodaas recover` joins them, the joined "
     "recording's outcome is recording_lost (/run/result), never success", _recorder_kill),
    *ACCOUNTING_FAULTS,  # the recording's end-to-end accounting under stalls and deaths
]


def run_fault(name: str) -> dict:
    """Run one fault scenario by name in a scratch folder."""
    for n, expected, fn in FAULTS:
        if n == name:
            with tempfile.TemporaryDirectory() as td:
                out = fn(Path(td))
            return {"name": n, "expected": expected, **out}
    raise KeyError(name)


def run_faults() -> dict[str, Any]:
    return {"rows": [run_fault(n) for n, _, _ in FAULTS]}


def render(inputs: dict[str, Any], faults: dict[str, Any] | None, extra: dict[str, Any] | None = None) -> str:
    """The Markdown of ``docs/reliability.md``."""
    lines = ["# Reliability: bad inputs and injected faults", "",
             "Regenerated by `python -m aerodaas.reliability --out docs/reliability.md` (the same cases run as "
             "tests: `python -m pytest -m faults tests`).", "",
             "Exit codes of `aerodaas run`: 0 success; 1 mission not successful (including `analytics_lost`: under "
             "lock-step an analytics actor did not answer again within `actor_restart_timeout_s`), the recording "
             "failed (disk) or Ray "
             "could not start; 1 also for an exception raised by the application's own code (its traceback is "
             "printed); 2 bad input (named, before Ray starts); 3 a drone actor lost for good; 4 the recorder actor "
             "died mid-run: \"recording lost at t = ...\", outcome `recording_lost`, the recording goes on in a new "
             "segment (`RUN.1.mcap`), `aerodaas recover RUN.mcap` joins the segments; 4 also when a message its "
             "producer numbered is in no segment (the summary lists the lost count per channel, from the file's "
             "sequence numbers and `/run/accounting`); 130 / 143 Ctrl-C / SIGTERM.", "",
             *render_inputs(inputs)]
    if faults is not None:
        rows = faults["rows"]
        lines += ["| faults injected | ended clean |", "|---|---|",
                  f"| {len(rows)} | {sum(1 for r in rows if r['clean'])} |", ""]
    if extra:
        e = extra
        lines += ["| randomized command sequences (simulator) | odometry samples checked | commands accepted / "
                  "refused | flown outside limits | max outside inclusion fence | max inside exclusion zone | max "
                  "above max_altitude |", "|---|---|---|---|---|---|---|",
                  f"| {e['sequences']} | {e['samples']} | {e['accepted']} / {e['refused']} | "
                  f"{e['flown_outside_limits']} | {e['outside_inclusion_m']:.3f} m | {e['inside_exclusion_m']:.3f} m | "
                  f"{e['above_max_altitude_m']:.3f} m (tolerance 1e-6 m) |", ""]
    lines += ["## Inputs", "", "Command-line rows are refused before Ray (exit 2); app-level rows of kind `application "
              "error` are the app's own exceptions, reported as the app's (exit 1 with its traceback, never \"bad "
              "input\"), the others values the app gave AeroDaaS (exit 2 naming the field, before Ray); HITL API "
              "rows are the documented answers (a drone actor that does not answer is 503 within 2 s: "
              "`tests/safety/test_hitl_unreachable.py`, needs Ray). A traceback is an exception other than the documented "
              "refusal, a hang a case without an answer within its time limit.", "",
              *render_input_rows(inputs)]
    if faults is not None:
        lines += ["", "## Faults", "", "| fault | expected end | observed | clean |", "|---|---|---|---|"]
        for r in faults["rows"]:
            lines.append(f"| {r['name']} | {r['expected']} | {r['observed'].replace('|', '/')} | "
                         f"{'yes' if r['clean'] else '**NO**'} |")
    return "\n".join(lines) + "\n"
