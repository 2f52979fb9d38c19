"""The dora-rs peers of ``aerodaas bench overhead``: the same pipeline (see :mod:`aerodaas.bench.pipeline`) on dora-rs
1.1 (``pip install 'aerodaas[bench]'``), wired by a ``dataflow.yml`` generated into a temporary directory and run
with ``dora run`` (local mode, no coordinator), in two shapes:

* ``per_component`` (``dora_rs``): one Python node process per component, 5 processes, 4 crossings;
* ``grouped`` (``dora_rs_grouped``): grouped as the AeroDaaS ``actors`` layout is — camera, follow, scheduler and
  drone in one node process, the detector in another: 2 processes, 2 crossings (frame out, detections back), so the
  two runtimes are compared on the same topology.
 On one machine dora
moves every message of at least 4096 bytes (``ZERO_COPY_THRESHOLD`` in dora's node API) through shared memory, so
a frame is written once into a shared-memory sample and read zero-copy by the detector; small messages (pickled
detections, navigation, setpoint) are inline.

    per_component: camera --frame (uint8 Arrow array + JSON metadata)--> detector --dets--> follow --nav-->
                   scheduler --item--> drone
    grouped:       group(camera) --frame--> detector --dets--> group(follow -> scheduler -> drone, in-process)

Control from the benchmark process goes through files in that directory (so the nodes need no extra ports): each
node writes ``ready_<node>`` once set up; the camera produces frames while the monotonic deadline in ``window``
is in the future; the drone appends one JSON row per applied command to ``rows.jsonl``. ``dora run`` is stopped
with SIGINT (its Ctrl-C: a STOP event to every node). Node processes run ``python -m aerodaas.bench.peers_dora
NODE DIR`` with this interpreter.
"""
from __future__ import annotations

import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from aerodaas.bench import pipeline as pl
from aerodaas.bench.pipeline import FPS, HOVER_M, CameraStage, Pacer
from aerodaas.model.types import CameraIntrinsics, FrameMeta, FramePose

#: per shape: node ids, node -> (input port, source), node -> output
SHAPES = {
    "per_component": (("camera", "detector", "follow", "scheduler", "drone"),
                      {"detector": ("frame", "camera/frame"), "follow": ("dets", "detector/dets"),
                       "scheduler": ("nav", "follow/nav"), "drone": ("item", "scheduler/item")},
                      {"camera": "frame", "detector": "dets", "follow": "nav", "scheduler": "item"}),
    "grouped": (("group", "detector"),
                {"detector": ("frame", "group/frame"), "group": ("dets", "detector/dets")},
                {"group": "frame", "detector": "dets"}),
}
NODES = SHAPES["per_component"][0]


def dora_cli() -> str | None:
    """Path of the ``dora`` CLI (next to this interpreter first, then ``$PATH``), or None."""
    local = Path(sys.executable).parent / "dora"
    return str(local) if local.exists() else shutil.which("dora")


def unavailable_reason() -> str | None:
    """Why the dora-rs column cannot be measured here (None when it can)."""
    try:
        import dora  # noqa: F401  # lazy: optional dependency (dora-rs)
    except ImportError:
        return "dora-rs is not installed (pip install 'aerodaas[bench]': dora-rs and dora-rs-cli >= 1.1)"
    if dora_cli() is None:
        return "the dora CLI is not installed (pip install 'dora-rs-cli>=1.1')"
    return None


def dataflow_yaml(workdir: str, shape: str = "per_component") -> str:
    """The dataflow descriptor of ``shape`` (see :data:`SHAPES`): custom Python nodes (dora's YAML spec:
    ``nodes[].path``, ``args``, ``inputs`` ``<node>/<output>``, ``outputs``). Raises KeyError for an unknown
    shape."""
    nodes, edges, outputs = SHAPES[shape]
    lines = ["nodes:"]
    for node in nodes:
        lines += [f"  - id: {node}", f"    path: {sys.executable}",
                  f"    args: -u -m aerodaas.bench.peers_dora {node} {workdir}"]
        if node in edges:
            port, src = edges[node]
            lines += ["    inputs:", f"      {port}:", f"        source: {src}", "        queue_size: 10"]
        if node in outputs:
            lines += ["    outputs:", f"      - {outputs[node]}"]
    return "\n".join(lines) + "\n"


class DoraPipeline:
    """Starts ``dora run`` on the generated dataflow of ``shape`` (``per_component`` or ``grouped``, see the module
    docstring) and waits for every node to be set up (``timeout_s``); :meth:`window` runs the camera for a while and
    returns the rows of applied commands. Raises RuntimeError when dora exits or a node is not ready in time (the
    log tail is in the message)."""

    def __init__(self, width: int, height: int, kind: str, stub_ms: float, timeout_s: float = 180.0,
                 shape: str = "per_component") -> None:
        reason = unavailable_reason()
        if reason:
            raise RuntimeError(reason)
        if shape not in SHAPES:
            raise ValueError(f"dora shape: {shape!r} is not one of {sorted(SHAPES)}")
        self.name = "dora_rs" if shape == "per_component" else "dora_rs_grouped"
        nodes = SHAPES[shape][0]
        self.dir = tempfile.mkdtemp(prefix="aerodaas-dora-")
        Path(self.dir, "params.json").write_text(json.dumps({"width": width, "height": height, "kind": kind,
                                                             "stub_ms": stub_ms}))
        self._set_window(0.0)
        Path(self.dir, "dataflow.yml").write_text(dataflow_yaml(self.dir, shape))
        self.log = open(Path(self.dir, "dora.log"), "w")
        self.proc = subprocess.Popen([dora_cli(), "run", "dataflow.yml", "--log-level", "warn"], cwd=self.dir,
                                     stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        self._offset = 0
        deadline = time.monotonic() + timeout_s
        while not all(Path(self.dir, f"ready_{n}").exists() for n in nodes):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                tail = self._log_tail()
                self.close()
                raise RuntimeError(f"dora run did not get every node ready (exit {self.proc.returncode}): {tail}")
            time.sleep(0.1)

    def _set_window(self, until: float) -> None:
        tmp = Path(self.dir, "window.tmp")
        tmp.write_text(repr(until))
        os.replace(tmp, Path(self.dir, "window"))

    def _log_tail(self) -> str:
        self.log.flush()
        return Path(self.dir, "dora.log").read_text(errors="replace")[-1500:]

    def window(self, seconds: float, settle_s: float = 0.5, drain_s: float = 30.0) -> list[dict]:
        """Run the camera for ``seconds`` (wall s), then wait for the frames still in the pipeline: until no command
        was applied for ``settle_s`` and at least one was since the last window, at most ``drain_s`` more (a loaded
        machine can take longer than ``settle_s`` to move a frame through the dataflow's nodes). Returns the rows of the
        commands applied since the last window. Raises RuntimeError when dora exited or no command was applied (the
        log's tail in the message)."""
        self._set_window(time.monotonic() + seconds)
        time.sleep(seconds + settle_s)
        rows = Path(self.dir, "rows.jsonl")
        deadline, size = time.monotonic() + drain_s, -1
        while time.monotonic() < deadline and self.proc.poll() is None:
            now = rows.stat().st_size if rows.exists() else 0
            if now == size and now > self._offset:
                break
            size = now
            time.sleep(settle_s)
        if self.proc.poll() is not None:
            raise RuntimeError(f"dora run exited ({self.proc.returncode}): {self._log_tail()}")
        with open(rows) as f:
            f.seek(self._offset)
            text = f.read()
        complete = text[:text.rfind("\n") + 1]
        self._offset += len(complete)
        out = [json.loads(line) for line in complete.splitlines() if line]
        if not out:
            waited = seconds + settle_s + drain_s
            raise RuntimeError(f"dora-rs pipeline: no command reached the drone node in {waited:.1f} s: "
                               f"{self._log_tail()}")
        return out

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(10)
        self.log.close()
        shutil.rmtree(self.dir, ignore_errors=True)


# ---------------------------------------------------------------------------------------------- the node processes
def _pack(obj: object):
    import pyarrow as pa  # lazy: optional dependency (dora-rs's pyarrow)

    return pa.array(np.frombuffer(pickle.dumps(obj), np.uint8))


def _unpack(value) -> object:
    return pickle.loads(value.to_numpy(zero_copy_only=False).tobytes())


def _send_frame(node, cam, tick: float, t0: float) -> None:
    """Render one frame (the camera's ``tick``, monotonic seconds; ``t0`` the node's start) and send it on the
    ``frame`` output: a flat uint8 Arrow array of the (H, W, 3) BGR frame, its timing trace as JSON metadata."""
    import pyarrow as pa  # lazy: optional dependency (dora-rs's pyarrow)

    start = time.monotonic()
    frame, meta = cam.capture((0.0, 0.0, HOVER_M), 0.0, start - t0)
    ready = time.monotonic()
    tr = {"tick": tick, "start": start, "ready": ready, "seq": meta.seq, "t": meta.capture_time, "out": ready}
    node.send_output("frame", pa.array(frame.reshape(-1)), {"trace": json.dumps(tr)})


def _camera(node, p: dict, workdir: str) -> None:
    cam = CameraStage(p["width"], p["height"], p["kind"])
    Path(workdir, "ready_camera").touch()
    pacer, t0, until = Pacer(FPS), time.monotonic(), 0.0
    win = Path(workdir, "window")
    while True:
        if time.monotonic() >= until:  # idle between windows: wait for STOP or a new window
            t_poll = time.monotonic()
            ev = node.next(timeout=0.02)
            if ev is not None and ev["type"] == "STOP":
                return
            if time.monotonic() - t_poll < 0.01:  # a timeout comes back as an ERROR event: never spin
                time.sleep(0.01)
            until = float(win.read_text() or 0.0)
            pacer.restart()
            continue
        _send_frame(node, cam, pacer.wait(), t0)


def _rebuild_meta(p: dict, tr: dict):
    return FrameMeta(robot_id="uav", sensor_id="cam", seq=tr["seq"], capture_time=tr["t"], wall_time=time.time(),
                     pose=FramePose(position=(0.0, 0.0, HOVER_M), yaw=0.0, camera_pitch=90),
                     intrinsics=CameraIntrinsics.from_hfov(p["width"], p["height"], 78))


def _worker(node, p: dict, workdir: str, role: str) -> None:
    rc = pl.parsed_config(p["width"], p["height"], p["kind"]).robots[0]
    stage = {"detector": lambda: pl.DetectStage(p["kind"], p["stub_ms"]), "follow": pl.FollowStage,
             "scheduler": lambda: pl.CommandStage(rc), "drone": lambda: pl.DroneStage(rc)}[role]()
    rows = open(Path(workdir, "rows.jsonl"), "a", buffering=1) if role == "drone" else None
    Path(workdir, f"ready_{role}").touch()
    last = time.monotonic()
    for ev in node:
        if ev["type"] == "STOP":
            break
        if ev["type"] != "INPUT":
            continue
        t_in = time.monotonic()
        if role == "detector":
            tr = json.loads(ev["metadata"]["trace"])
            tr["hop_camera_detector"] = t_in - tr["out"]
            frame = ev["value"].to_numpy(zero_copy_only=True).reshape(p["height"], p["width"], 3)
            meta = _rebuild_meta(p, tr)
            dets, tr["inference_ms"], tr["post_ms"] = stage(frame, meta)
            del frame
            tr["out"] = time.monotonic()
            node.send_output("dets", _pack((dets, meta, tr)))
        elif role == "follow":
            dets, meta, tr = _unpack(ev["value"])
            tr["hop_detector_follow"] = t_in - tr["out"]
            nav, ms = stage(dets, meta)
            if nav is not None:
                tr["post_ms"] += ms
                tr["out"] = time.monotonic()
                node.send_output("nav", _pack((nav, meta, tr)))
        elif role == "scheduler":
            nav, meta, tr = _unpack(ev["value"])
            tr["hop_follow_scheduler"] = t_in - tr["out"]
            item = stage(nav, tuple(meta.pose.position), meta.capture_time)
            if item is not None:
                tr["out"] = time.monotonic()
                node.send_output("item", _pack((item, tr)))
        else:
            item, tr = _unpack(ev["value"])
            tr["hop_scheduler_drone"] = t_in - tr["out"]
            stage.step(min(0.1, t_in - last))
            last = t_in
            stage.apply(item)
            tr["applied"] = time.monotonic()
            del tr["out"], tr["seq"], tr["t"]
            rows.write(json.dumps(tr) + "\n")
    if rows is not None:
        rows.close()


def _group(node, p: dict, workdir: str) -> None:
    """The grouped shape's first node: the camera, paced at the pipeline's FPS, and, in the same process, follow ->
    scheduler -> drone on every detection message that comes back (no crossing between them, as in the AeroDaaS
    drone actor). Between frames it waits on its input with ``node.next(timeout)`` until the next frame is due."""
    rc = pl.parsed_config(p["width"], p["height"], p["kind"]).robots[0]
    cam, follow = pl.CameraStage(p["width"], p["height"], p["kind"]), pl.FollowStage()
    sched, drone = pl.CommandStage(rc), pl.DroneStage(rc)
    rows = open(Path(workdir, "rows.jsonl"), "a", buffering=1)
    Path(workdir, "ready_group").touch()
    pacer, t0, until, last = pl.Pacer(pl.FPS), time.monotonic(), 0.0, time.monotonic()
    win = Path(workdir, "window")

    def on_dets(ev) -> None:
        nonlocal last
        t_in = time.monotonic()
        dets, meta, tr = _unpack(ev["value"])
        tr["hop_detector_group"] = t_in - tr["out"]
        nav, ms = follow(dets, meta)
        if nav is None:
            return
        tr["post_ms"] += ms
        item = sched(nav, tuple(meta.pose.position), meta.capture_time)
        if item is None:
            return
        now = time.monotonic()
        drone.step(min(0.1, now - last))
        last = now
        drone.apply(item)
        tr["applied"] = time.monotonic()
        del tr["out"], tr["seq"], tr["t"]
        rows.write(json.dumps(tr) + "\n")

    try:
        while True:
            now = time.monotonic()
            if now >= until:  # idle between windows: answers still in flight, then STOP or a new window
                ev = node.next(timeout=0.02)
                if ev is not None and ev["type"] == "STOP":
                    return
                if ev is not None and ev["type"] == "INPUT":
                    on_dets(ev)
                    continue
                if time.monotonic() - now < 0.01:  # a timeout comes back as an ERROR event: never spin
                    time.sleep(0.01)
                until = float(win.read_text() or 0.0)
                pacer.restart()
                continue
            due = pacer.next_t - now
            if due > 0.0005:  # the next frame is not due yet: serve detections meanwhile
                ev = node.next(timeout=due)
                if ev is not None and ev["type"] == "STOP":
                    return
                if ev is not None and ev["type"] == "INPUT":
                    on_dets(ev)
                if time.monotonic() < pacer.next_t:
                    continue
            _send_frame(node, cam, pacer.wait(), t0)
    finally:
        rows.close()


def node_main(argv: list[str]) -> int:
    """Entry point of a node process: ``NODE WORKDIR``."""
    from dora import Node  # lazy: optional dependency (dora-rs)

    role, workdir = argv
    p = json.loads(Path(workdir, "params.json").read_text())
    node = Node()
    if role == "camera":
        _camera(node, p, workdir)
    elif role == "group":
        _group(node, p, workdir)
    else:
        _worker(node, p, workdir, role)
    return 0


if __name__ == "__main__":
    sys.exit(node_main(sys.argv[1:]))
