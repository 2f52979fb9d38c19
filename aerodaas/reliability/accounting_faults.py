"""Fault scenarios of the recording's end-to-end accounting: real ``aerodaas run`` processes of the farm
survey (camera, odometry, a monitoring analytics) whose recorder actor is stalled or killed mid-run. Each ends clean
when the outcome tells the truth: not ``success`` (exit 4, ``recording_lost``) exactly when the recording lacks a
message its producers numbered, and the summary's per-channel lost counts equal what the file lacks — read back
with the ``mcap`` package's own reader: per channel, the producers' count in ``/run/accounting`` less the messages
deliberately not recorded less the messages in every segment, and the sequence numbers there distinct."""
from __future__ import annotations

import base64
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from aerodaas.recording.segments import segment_path
from aerodaas.reliability.procs import (REPO_APPS, OutputTail, actor_pids, mcap_reader_ok, no_crash, run_cli,
                                        summary_outcome, wait_size)

__all__ = ["ACCOUNTING_FAULTS", "STREAM_STALL", "file_losses", "stream_shedding", "summary_losses"]

#: how long the recorder actor is stopped (s); at least this long where the clock is to wait for it
STALL_S = 20.0
#: the longest a recorder actor is kept stopped while waiting for the clock to be held (s)
STALL_LIMIT_S = 300.0


def file_losses(paths: list[Path]) -> tuple[dict[str, int], list[str]]:
    """(topic -> messages lost, problems) of a run recorded in ``paths`` (its segments in order), read with mcap's
    reader alone: the last ``/run/accounting`` gives what the producers numbered; a channel loses what it lacks of
    that. ``problems``: a sequence number recorded twice on a channel with one producer, or one not below the
    producers' count, or no accounting at all."""
    counts: dict[str, int] = {}
    seqs: dict[str, list[int]] = {}
    accounting = None
    for p in paths:
        with open(p, "rb") as f:
            for _, ch, m in make_reader(f).iter_messages(log_time_order=False):
                counts[ch.topic] = counts.get(ch.topic, 0) + 1
                seqs.setdefault(ch.topic, []).append(m.sequence)
                if ch.topic == "/run/accounting":
                    accounting = json.loads(m.data)
    if accounting is None:
        return {}, ["no /run/accounting in the recording"]
    lost, problems = {}, []
    expected = {t: c["produced"] - c["duplicates"] for t, c in accounting["channels"].items()}
    for prefix, a in accounting.get("analytics", {}).items():  # its outputs, against what it was offered
        topics = [prefix + "/detections", prefix + "/navigation", prefix]
        target = next((t for t in topics if t in expected or counts.get(t)), prefix)
        own = sum(expected.pop(t) for t in topics if t in expected)
        expected[target] = max(own, a["offered"] - a["no_output"]) - sum(counts.get(t, 0) for t in topics
                                                                          if t != target)
    for topic, n in expected.items():
        if n - counts.get(topic, 0):
            lost[topic] = n - counts.get(topic, 0)
    for topic, c in accounting["channels"].items():
        got = seqs.get(topic, [])
        if topic.endswith(("/odometry", "/monitor")) or "/camera/" in topic:  # one producer each
            if len(set(got)) != len(got):
                problems.append(f"{topic}: a sequence number recorded twice")
            if got and max(got) >= c["produced"]:
                problems.append(f"{topic}: sequence {max(got)} not below the producers' {c['produced']}")
    return lost, problems


def summary_losses(out: str) -> dict[str, int]:
    """Topic -> lost, as the run's summary printed it (``    /topic: N lost, R of P recorded``)."""
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^\s+(/\S+): (\d+) lost, \d+ of \d+ recorded$", out,
                                                              re.MULTILINE)}


def _segments(rec: Path) -> list[Path]:
    out, k = [rec], 1
    while segment_path(rec, k).exists():
        out.append(Path(segment_path(rec, k)))
        k += 1
    return out


def accounting_verdict(p: Any, out: str, rec: Path, reached: bool, extra_ok: bool, what: str) -> dict:
    """Clean when the exit code and outcome match the file's truth and the summary's counts equal the file's."""
    segs = _segments(rec)
    readable = all(mcap_reader_ok(s)[0] for s in segs)
    lost, problems = file_losses(segs) if readable else ({}, ["a segment is not readable"])
    said = summary_losses(out)
    truthful = (p.returncode == 4 and "recording_lost" in summary_outcome(out)) if lost else \
        (p.returncode == 0 and "success" in summary_outcome(out))
    clean = reached and readable and not problems and truthful and said == lost and extra_ok and no_crash(out)
    return {"observed": f"{what}; exit {p.returncode}, {summary_outcome(out).strip() or 'no summary'}; "
                        f"{len(segs)} segment(s); the file lacks {sum(lost.values())} numbered messages "
                        f"({', '.join(f'{t} {n}' for t, n in lost.items()) or 'none'}), the summary says "
                        f"{sum(said.values())}" + (f"; {'; '.join(problems)}" if problems else ""),
            "clean": clean, "exit": p.returncode, "output": out[-3000:], "lost": lost}


def _stop_recorder(p: Any, rec: Path) -> tuple[bool, list[int]]:
    """Once ``rec`` holds 20 kB (the run ``p`` is flying): SIGSTOP of its recorder actor for :data:`STALL_S` s, then
    SIGCONT. Returns (the size was reached, the pids stopped)."""
    reached = wait_size(rec, 20000, p)
    pids = actor_pids(p.pid, "RecorderActor") if reached else []
    for pid in pids:
        os.kill(pid, signal.SIGSTOP)
    time.sleep(STALL_S if pids else 0)
    for pid in pids:
        os.kill(pid, signal.SIGCONT)
    return reached, pids


def _stop_recorder_until_held(p: Any, rec: Path, tail: OutputTail, need_s: float) -> tuple[bool, list[int], float]:
    """Once ``rec`` holds 20 kB: SIGSTOP of the run's recorder actor until its live progress (``tail``) shows the
    simulated clock held at least ``need_s`` wall s for the recorder, and :data:`STALL_S` s at least, then SIGCONT
    (also on an error). The clock waits only once the drone's recorder buffer is full, which a loaded machine reaches
    later than a quiet one: a fixed stall may end before any wait. It also ends when the run ends or after
    :data:`STALL_LIMIT_S` s. Returns (the size was reached, the pids stopped, the longest hold the progress showed
    while they were stopped: wall s, 0.0 when none)."""
    reached = wait_size(rec, 20000, p)
    pids = actor_pids(p.pid, "RecorderActor") if reached else []
    shown: list[float] = []
    for pid in pids:
        os.kill(pid, signal.SIGSTOP)
    try:
        t0 = time.monotonic()
        while pids and p.poll() is None and time.monotonic() - t0 < STALL_LIMIT_S:
            shown = [float(x) for x in re.findall(r"clock held ([\d.]+) s for the recorder$", "".join(tail.lines()),
                                                  re.MULTILINE)]
            if time.monotonic() - t0 >= STALL_S and shown and max(shown) >= need_s:
                break
            time.sleep(0.2)
    finally:
        for pid in pids:
            os.kill(pid, signal.SIGCONT)
    return reached, pids, max(shown, default=0.0)


def _recorder_stall(tmp: Path, hold_s: float | None = None) -> dict:
    """SIGSTOP of the recorder actor mid-flight until the clock has waited for it (:func:`_stop_recorder_until_held`),
    then SIGCONT. ``hold_s``: the run's ``--recorder-hold`` (None: the default, longer than the stall: the simulated
    clock waits and nothing is lost; shorter: the recorder stays stopped until it is spent, frames are shed past it
    and the run ends ``recording_lost``). Clean when the live progress showed the hold while the recorder was
    stopped, the outcome tells the file's truth and the summary says how long the clock was held exactly when it
    was."""
    rec = tmp / "run.mcap"
    hold = [] if hold_s is None else ["--recorder-hold", f"{hold_s:g}"]
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "2", *hold],
                start_new_session=True)
    tail = OutputTail(p)
    need = 1.5 if hold_s is None else hold_s
    reached, pids, shown = _stop_recorder_until_held(p, rec, tail, need)
    out = tail.finish(900)
    said_held = re.findall(r"simulated clock held ([\d.]+) s for the recorder", out)
    res = accounting_verdict(p, out, rec, reached and len(pids) == 1 and shown >= need, bool(said_held),
                             (f"recorder actor stopped until the live progress showed the clock held {shown:g} s"
                              if pids else "recorder actor not found")
                             + f"; the summary says the clock was held {', '.join(said_held) or 'never'} s")
    res["held_s"] = [float(x) for x in said_held]
    return res


#: the scenario of :func:`_recorder_stall_on_stream`
STREAM_STALL = f"SIGSTOP of the recorder actor for {STALL_S:g} s mid-run while the camera reads a live video stream"
#: the camera of the farm survey, and the live stream it reads in :func:`_recorder_stall_on_stream`: MPEG-TS on
#: loopback UDP at the camera's size (px) and rate (frames/s)
STREAM_CAMERA = "/quadrotor_base/camera/cam1"
STREAM_SIZE, STREAM_FPS = (640, 480), 15.0


#: the stream scenario's flight limits (m/s, m/s, m/s^2): the survey at 2 m/s instead of the app's 0.5 flies
#: about 45 s in real time, still twice the stall; at 0.5 m/s it flew 90 s
STREAM_LIMITS = {"max_speed": 2.0, "max_vertical_speed": 1.0, "max_acceleration": 2.0}


def _stream_env(tmp: Path, url: str) -> Path:
    """``apps/farm_survey.json`` with its camera reading the live stream ``url``, at speed-up 1 without lock-step
    (what a stream camera needs) and :data:`STREAM_LIMITS`; written into ``tmp``."""
    env = json.loads((REPO_APPS / "farm_survey.json").read_text())
    env["robots"][0]["sensors"][0]["properties"]["source"] = url
    env["robots"][0]["limits"].update(STREAM_LIMITS)
    env["simulation"] = {**env["simulation"], "speedup": 1, "lockstep": False}
    path = tmp / "farm_survey_stream.json"
    path.write_text(json.dumps(env))
    return path


def stream_shedding(rec: Path, topic: str = STREAM_CAMERA) -> dict:
    """What a stream camera's recording says of frames shed, read with mcap's reader alone: ``{"shed": frames refused
    by the recorder actor's full queue (``/run/recorder_drops``) plus those the camera did not hand to the recorder
    (``not_recorded`` of its ``video_stats``), "frames": frames of ``topic`` in the file, "taken": frames the camera
    took from the stream, "clock_held": the drones' ``clock_held`` events}``; None values when not recorded."""
    got: dict[str, Any] = {"shed": None, "frames": 0, "taken": None, "clock_held": 0}
    drops, stats = None, None
    with open(rec, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages(log_time_order=False):
            if ch.topic == topic:
                got["frames"] += 1
            elif ch.topic == "/run/recorder_drops":
                drops = json.loads(m.data)
            elif ch.topic == topic + "/video_stats":
                stats = json.loads(m.data)
            elif ch.topic.endswith("/events"):
                got["clock_held"] += json.loads(m.data).get("event") == "clock_held"
    if drops is not None and stats is not None:
        got["shed"] = drops["frames_dropped"].get(topic, 0) + stats["not_recorded"]
        got["taken"] = stats["taken"]
    return got


def _recorder_stall_on_stream(tmp: Path) -> dict:
    """The farm survey with its camera reading a live video stream (a sender process, :func:`aerodaas.bench.video.send`,
    encodes MPEG-TS onto loopback UDP in real time and goes on while the recorder is stopped, as a camera does), its
    recorder actor stopped for :data:`STALL_S` s. A stream runs on the wall clock, so its clock must not wait (the
    run's hold is 0, :func:`aerodaas.runtime.preflight.simulation_for`): clean when frames were shed and counted
    (the camera's channel lacks exactly the frames ``/run/recorder_drops`` and its ``not_recorded`` count), the run
    ends exit 4 ``recording_lost`` with the summary's lost counts equal to what the file lacks, and no ``clock_held``
    event nor "simulated clock held" line says the clock waited."""
    from aerodaas.emulators import free_udp_port  # lazy: only this scenario streams

    url = f"udp://127.0.0.1:{free_udp_port()}"
    sender = subprocess.Popen([sys.executable, "-c", "import sys; from aerodaas.bench.video import send; send("
                               "sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), sys.argv[5])",
                               url, *map(str, STREAM_SIZE), str(STREAM_FPS), str(tmp / "sent.log")],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rec = tmp / "run.mcap"
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--env", str(_stream_env(tmp, url)), "--record", str(rec),
                 "--quiet"], start_new_session=True)
    try:
        reached, pids = _stop_recorder(p, rec)
        out, _ = p.communicate(timeout=900)
    finally:
        streaming = sender.poll() is None  # the stream never paused for the recorder
        sender.kill()
        sender.wait(timeout=30)
        if p.poll() is None:
            p.kill()
    said_held = re.findall(r"simulated clock held ([\d.]+) s for the recorder", out)
    shed = stream_shedding(rec) if mcap_reader_ok(rec)[0] else {"shed": None, "clock_held": None}
    res = accounting_verdict(p, out, rec, reached and len(pids) == 1 and streaming, not said_held,
                             (f"recorder actor stopped for {STALL_S:g} s" if pids else "recorder actor not found")
                             + f" while its camera read a live stream (sender still streaming at the end: "
                             f"{streaming}); {shed['shed']} frames shed and counted, {shed['clock_held']} clock_held "
                             f"events, the summary says the clock was held {', '.join(said_held) or 'never'}")
    res["clean"] = (res["clean"] and res["exit"] == 4 and bool(shed["shed"]) and shed["clock_held"] == 0
                    and res["lost"].get(STREAM_CAMERA) == shed["shed"])
    res.update(held_s=[float(x) for x in said_held], **shed)
    return res


def _recorder_killed_twice(tmp: Path) -> dict:
    """SIGKILL of the recorder actor, and again once its restart records into ``run.1.mcap``: both deaths are
    reported (only the second one was before) and the three segments account for every numbered message."""
    rec = tmp / "run.mcap"
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "2", "--quiet"],
             start_new_session=True)
    reached = wait_size(rec, 20000, p)
    killed = []
    for seg in (rec.with_name("run.1.mcap"), None):
        pids = actor_pids(p.pid, "RecorderActor") if reached else []
        for pid in pids:
            os.kill(pid, signal.SIGKILL)
        killed += pids
        if seg is not None:
            reached = reached and wait_size(seg, 20000, p)
    out, _ = p.communicate(timeout=900)
    deaths = len(re.findall(r"^  recording lost at t = .*: the recorder actor died", out, re.MULTILINE))
    return accounting_verdict(p, out, rec, reached and len(killed) == 2, deaths == 2,
                    f"{len(killed)} recorder deaths, {deaths} reported")


def _ws_frame(sock: Any) -> tuple[int, bytes]:
    """One WebSocket frame from the server (RFC 6455 §5.2: unmasked): (opcode, payload)."""
    def exact(n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            got = sock.recv(n - len(buf))
            if not got:
                raise ConnectionError("closed")
            buf += got
        return buf

    b0, b1 = exact(2)
    n = b1 & 0x7F
    if n == 126:
        n = int.from_bytes(exact(2), "big")
    elif n == 127:
        n = int.from_bytes(exact(8), "big")
    return b0 & 0x0F, exact(n)


def _ws_send_text(sock: Any, text: str) -> None:
    """A masked text frame from the client (RFC 6455 §5.3)."""
    data, key = text.encode(), os.urandom(4)
    head = bytes([0x81]) + (bytes([0x80 | len(data)]) if len(data) < 126 else
                            bytes([0x80 | 126]) + len(data).to_bytes(2, "big"))
    sock.sendall(head + key + bytes(b ^ key[i % 4] for i, b in enumerate(data)))


def _stalled_client(port: int, proc: Any, want: str, limit_s: float = 300.0) -> tuple[bool, Any]:
    """Connect to the live view on ``port``, subscribe to every channel advertised until ``want`` is, then stop
    reading (its receive buffer 4 KiB). Returns (subscribed to ``want``, the socket, left open: the caller closes
    it once the run ended; None when it could not connect)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit_s and proc.poll() is None:
        try:
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.connect(("127.0.0.1", port))
            break
        except OSError:
            sock.close()
            time.sleep(0.5)
    else:
        return False, None
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                  f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                  f"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)
    sub = 0
    while time.monotonic() - t0 < limit_s:
        op, payload = _ws_frame(sock)
        if op != 1:
            continue
        msg = json.loads(payload)
        if msg.get("op") == "advertise":
            chans = msg.get("channels", [])
            subs = [{"id": sub + i, "channelId": c["id"]} for i, c in enumerate(chans)]
            sub += len(subs)
            _ws_send_text(sock, json.dumps({"op": "subscribe", "subscriptions": subs}))
            if any(c.get("topic") == want for c in chans):
                return True, sock
    return False, sock


def _live_client_stalled(tmp: Path) -> dict:
    """``aerodaas run --live``: a client subscribes to every channel (the camera's too) and then stops reading. It is
    dropped (a ``live_client_dropped`` event in the recording) and never holds the run: the run ends with the
    summary's message count equal to the file's (it said "0 messages" after ~120 s before)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    rec = tmp / "run.mcap"
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "2", "--quiet",
              "--live", f"127.0.0.1:{port}"], start_new_session=True)
    sock = None
    try:
        subscribed, sock = _stalled_client(port, p, "/quadrotor_base/camera/cam1")
    except (OSError, ValueError):
        subscribed = False
    out, _ = p.communicate(timeout=900)
    if sock is not None:
        sock.close()
    ok, n, _ = mcap_reader_ok(rec)
    dropped = 0
    if ok:
        with open(rec, "rb") as f:
            dropped = sum(json.loads(m.data).get("event") == "live_client_dropped"
                          for _, _, m in make_reader(f).iter_messages(topics=["/run/events"]))
    m = re.search(r"recording: \S+ \((\d+) messages", out)
    counted = m is not None and int(m.group(1)) == n
    return accounting_verdict(p, out, rec, subscribed, dropped == 1 and counted,
                    f"client subscribed to every channel then stopped reading: {subscribed}; dropped events "
                    f"{dropped}; the summary counts {m.group(1) if m else '?'} of the file's {n} messages")


def _analytics_killed_twice(tmp: Path) -> dict:
    """SIGKILL of the monitoring analytics' actor, and again once Ray restarted it (its one restart used up): the
    issue's run said success with 163 of 880 outputs recorded and no line for the analytics; now its output channel
    loses what its senders offered it and it never recorded."""
    rec = tmp / "run.mcap"
    p = run_cli(["run", str(REPO_APPS / "farm_survey.py"), "--record", str(rec), "--speedup", "2", "--quiet"],
             start_new_session=True)
    reached = wait_size(rec, 20000, p)
    killed: list[int] = []
    for _ in range(2):
        t0 = time.monotonic()  # the next victim: an analytics actor process not killed yet (Ray's restart)
        pids: list[int] = []
        while reached and not pids and p.poll() is None and time.monotonic() - t0 < 300:
            pids = [q for q in actor_pids(p.pid, "AnalyticsActor") if q not in killed]
            time.sleep(0.2)
        for pid in pids[:1]:
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
        time.sleep(3.0 if pids else 0)  # the restarted actor records a little before its second death
    out, _ = p.communicate(timeout=900)
    res = accounting_verdict(p, out, rec, reached and len(killed) == 2, True, f"{len(killed)} analytics actor deaths")
    res["clean"] = res["clean"] and bool(res["lost"].get("/quadrotor_base/monitor"))
    return res


#: (name, expected end, scenario(tmp folder) -> {"observed", "clean", ...}), joined to the fault catalogue
ACCOUNTING_FAULTS = [
    (f"SIGSTOP of the recorder actor mid-run until the clock waits for it (at least {STALL_S:g} s), then SIGCONT",
     "the simulated clock waits for the "
     "recorder (the summary says how long): exit 0, success, and the file lacks no numbered message (mcap's reader: "
     "/run/accounting against the messages)", _recorder_stall),
    (f"SIGSTOP of the recorder actor mid-run with --recorder-hold 2, until that hold is spent (at least {STALL_S:g} s)",
     "the clock waits 2 s, then "
     "frames are shed: exit 4 and recording_lost, the summary's lost counts per channel equal what the file lacks",
     lambda tmp: _recorder_stall(tmp, hold_s=2.0)),
    (STREAM_STALL, "a live stream cannot wait: the clock is never held (no clock_held event, no \"simulated clock "
     "held\" line), frames are shed and counted (the camera's channel lacks exactly /run/recorder_drops plus its "
     "not_recorded), exit 4 and recording_lost, the summary's lost counts per channel equal what the file lacks",
     _recorder_stall_on_stream),
    ("SIGKILL of the recorder actor twice mid-run", "exit 4, recording_lost, both deaths reported; the summary's lost "
     "counts per channel equal what the three segments lack (mcap's reader)", _recorder_killed_twice),
    ("SIGKILL of the monitoring analytics actor twice mid-run", "exit 4, recording_lost; the monitor's output channel "
     "loses what it was offered and never recorded, the summary's lost counts per channel equal what the file lacks "
     "(mcap's reader)", _analytics_killed_twice),
    ("a live-view client that stops reading mid-run (--live)", "the client is dropped (a live_client_dropped event "
     "in the recording), the run ends with the summary counting the file's messages; exit code and outcome as the "
     "file's accounting says", _live_client_stalled),
]
