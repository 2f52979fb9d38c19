"""Injected faults end cleanly: signals at any phase, a disk that fills up or fails, analytics that raise, a killed
run's recording recovered, a closed output pipe. The scenarios are the reliability catalogue's
(:mod:`aerodaas.reliability.faults`, which also writes ``docs/reliability.md``); the recorder and recovery are also
tested in-process."""
from __future__ import annotations

import io
import os
import subprocess
import sys
import time

import pytest

from aerodaas.reliability.accounting_faults import ACCOUNTING_FAULTS, STREAM_CAMERA, STREAM_STALL
from aerodaas.reliability.faults import run_fault
from aerodaas.reliability.procs import mcap_reader_ok

from tests.conftest import needs_data

pytestmark = pytest.mark.faults


@pytest.mark.e2e
@pytest.mark.parametrize("name", [
    "SIGTERM while the actors start",
    "SIGTERM at the slowest speedup (0.01)",
    "--timeout 8 at the slowest speedup (0.01)",
    "disk full (ENOSPC) mid-run",
    "analytics raising every 10th item, on_error=continue",
    "analytics raising, on_error=abort",
    "SIGKILL mid-run, then `aerodaas recover`",
    "SIGKILL of the driver alone mid-run",
    "SIGKILL of the raylet mid-run",
    "SIGKILL of the recorder actor mid-run",
    "SIGTERM right after the summary",
    "SIGINT right after the summary",
    "HITL clear of the pre-planned survey mid-flight",
])
def test_fault_ends_clean(name):
    r = run_fault(name)
    assert r["clean"], f"{name}: expected {r['expected']}; observed {r['observed']}\n{r.get('output', '')}"


@pytest.mark.e2e
@pytest.mark.parametrize("name", [n for n, _, _ in ACCOUNTING_FAULTS if n != STREAM_STALL])
def test_stalls_deaths_and_slow_clients_end_with_the_files_truth(name):
    """A recorder stalled until the simulated clock has waited for it ends success with nothing lost (the summary
    says how long); stalled past ``--recorder-hold``, killed twice, or an analytics killed twice, each ends
    not-success (exit 4, recording_lost) with the summary's lost count per channel equal to what the file lacks,
    read with mcap's reader (the producers' counts in /run/accounting less the messages in every segment); a live
    client that stops reading is dropped and the run's end tells the same truth."""
    r = run_fault(name)
    assert r["clean"], f"{name}: expected {r['expected']}; observed {r['observed']}\n{r.get('output', '')}"
    if "SIGSTOP" in name and "--recorder-hold" not in name:  # the simulated clock waited: nothing lost
        assert r["exit"] == 0 and not r["lost"] and r["held_s"] and r["held_s"][0] > 1.0, r["observed"]
    elif "live-view" not in name:  # past the hold, and a kill, lose what was in flight
        assert r["exit"] == 4 and r["lost"], r["observed"]


@pytest.mark.e2e
def test_recorder_stalled_on_a_live_stream_sheds_and_says_so():
    """The simulated run's hold does not reach a live stream: the farm survey's camera reads MPEG-TS from a sender
    on loopback that keeps streaming while the recorder actor is stopped 20 s. The clock never waits (no clock_held
    event, no "simulated clock held" line), frames are shed and counted (what the camera's channel lacks in the
    file, read with mcap's reader, is /run/recorder_drops plus the camera's not_recorded), and the run ends exit 4,
    recording_lost, the summary's lost count per channel equal to what the file lacks."""
    r = run_fault(STREAM_STALL)
    assert r["clean"], f"expected {r['expected']}; observed {r['observed']}\n{r.get('output', '')}"
    assert r["exit"] == 4 and r["shed"] > 0 and r["lost"][STREAM_CAMERA] == r["shed"], r["observed"]
    assert r["clock_held"] == 0 and not r["held_s"], r["observed"]
    assert r["frames"] == r["taken"] - r["shed"] > 0, r["observed"]  # every frame taken is recorded or shed


@pytest.mark.e2e
@needs_data
def test_yolox_detector_killed_under_lockstep_ends_clean(data_env):
    name = "SIGKILL of the YOLOX detector actor under lock-step (apps/vehicle_tracking.py)"
    r = run_fault(name)
    assert r["clean"], f"{name}: expected {r['expected']}; observed {r['observed']}\n{r.get('output', '')}"


def test_info_into_a_closed_pipe_ends_quietly():
    r = run_fault("`aerodaas info FILE | head` (reader gone)")
    assert r["clean"], r["observed"]


def test_info_broken_pipe_in_process(tmp_path, monkeypatch):
    from aerodaas import cli
    from aerodaas.recording.writer import McapRecorder

    rec = tmp_path / "a.mcap"
    with McapRecorder(rec) as r:
        r.write_json("/x", 1, {"a": 1}, schema_name="t.T")

    class Closed(io.StringIO):
        def write(self, s):
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(sys, "stdout", Closed())
    assert cli.main(["info", str(rec)]) == 141


def _json_burst(svc, n: int, start: int = 0) -> None:
    for i in range(start, start + n):
        svc.json("/x", 1_000_000_000 + i * 10_000_000, {"i": i, "pad": os.urandom(200).hex()}, "t.X")


def _wait(pred, limit_s: float = 60.0) -> None:
    t0 = time.monotonic()
    while not pred():
        assert time.monotonic() - t0 < limit_s
        time.sleep(0.02)


@pytest.mark.parametrize("kind", ["enospc", "eio"])
def test_recorder_failure_is_reported_and_the_file_is_finished(tmp_path, monkeypatch, kind):
    from aerodaas.actors.recording.recorder import RecorderService

    monkeypatch.setenv("AERODAAS_FAULT_RECORDER", f"{kind}:60000")
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), {"run": "x"}, flush_every_s=0.0)
    seen = []
    svc.on_failure.append(seen.append)
    _json_burst(svc, 600)
    _wait(lambda: svc.failure is not None)
    _json_burst(svc, 5, start=600)  # after the failure: counted as lost, never queued
    svc.close()
    rep = svc.report()
    assert rep["failure"]["errno"] == {"enospc": 28, "eio": 5}[kind] and rep["failure"]["finished"]
    assert seen and seen[0]["error"].startswith("OSError")
    assert rep["lost"] >= 5
    ok, n, why = mcap_reader_ok(path)
    assert ok, why
    assert n == rep["failure"]["messages_in_file"] > 0


def test_recorder_failure_when_the_disk_stays_full_leaves_a_recoverable_file(tmp_path, monkeypatch):
    """The summary cannot be written either: the file is cut at the last record boundary (valid, unfinished), the
    failure says so, and `aerodaas recover` finishes it once there is room."""
    import aerodaas.actors.recording.recorder as recorder
    from aerodaas import cli
    from aerodaas.actors.recording.recorder import RecorderService

    monkeypatch.setenv("AERODAAS_FAULT_RECORDER", "enospc:60000")

    def full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(recorder, "recover_mcap", full)  # the recorder's own finish (aerodaas recover: below)
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), flush_every_s=0.0)
    _json_burst(svc, 600)
    _wait(lambda: svc.failure is not None)
    svc.close()
    fail = svc.report()["failure"]
    assert fail["finished"] is False and "No space" in fail["finish_error"]
    assert not mcap_reader_ok(path)[0]
    from aerodaas.recording.reader import summarize_mcap

    readable = summarize_mcap(path)["message_count"]
    assert readable > 0
    monkeypatch.undo()
    assert cli.main(["recover", str(path)]) == 0
    ok, n, why = mcap_reader_ok(path)
    assert ok and n == readable, why


def test_recover_a_sigkilled_writer(tmp_path):
    """A process writing a recording is SIGKILLed: mcap's seeking reader rejects the file; after `aerodaas recover`
    it accepts it, with every message the tolerant scan could read, and its metadata."""
    path = tmp_path / "killed.mcap"
    code = f"""
import os, sys, time
from aerodaas.recording.writer import McapRecorder
r = McapRecorder({str(path)!r}, chunk_size=4096, metadata={{"run": "killed"}})
for i in range(400):
    r.write_json(f"/t/{{i % 3}}", 1_000_000 + i, {{"i": i, "pad": os.urandom(100).hex()}}, schema_name="t.T")
r.flush()
print("ready", flush=True)
time.sleep(600)
"""
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "ready"
    p.kill()
    p.wait()
    assert not mcap_reader_ok(path)[0]
    from aerodaas import cli
    from aerodaas.recording.reader import summarize_mcap

    assert summarize_mcap(path)["message_count"] == 400
    assert cli.main(["recover", str(path)]) == 0
    ok, n, why = mcap_reader_ok(path)
    assert ok and n == 400, why
    s = summarize_mcap(path)
    assert s["finished"] and s["metadata"].get("run") == "killed"
    assert cli.main(["recover", str(path)]) == 0  # already finished: left alone
    assert cli.main(["recover", str(tmp_path / "missing.mcap")]) == 2


def test_analytics_on_error_is_checked_before_ray(tmp_path):
    from aerodaas import AeroNavigation, Environment, MonitoringAnalytics, Waypoint
    from aerodaas.config import ConfigError, parse_environment_config

    env = Environment(parse_environment_config({"robots": [{"id": "d1", "sensors": [{"id": "o", "type": "odometry"}]}]}))
    d = env.get_robot_by_id("d1")
    m = MonitoringAnalytics(["battery"])
    m.on_error = "ignore"
    m.analyse(d.get_sensor_by_id("o").get_data_stream())
    d.navigate(AeroNavigation(waypoints=[Waypoint(id="a", x=1, y=0, z=2)]))
    with pytest.raises(ConfigError, match="on_error"):
        d.start_mission()
