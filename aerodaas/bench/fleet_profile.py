"""Where a drone's time and memory go: ``aerodaas bench fleet --profile`` measures one drone actor
of the running fleet, and every process of the node, over a window of the flight. The framework's share itself is
not taken from this sample: every drone actor accounts its CPU exactly (:func:`aerodaas.bench.fleet.drone_actor_cpu`);
this breakdown says where in the framework it goes.

CPU: the exact CPU time of every thread of the drone actor over the window, from ``/proc/<pid>/task/<tid>/stat``
(fields 14 and 15, utime and stime, in clock ticks: proc(5)), apportioned to components by a py-spy sample of the
same window (``py-spy record --threads --nonblocking --format raw``: each sample names the native thread id, so a
thread's CPU is split over the components its own samples fall in). Threads py-spy never sees run no Python: Ray's
C++ threads (core worker I/O, gRPC, the object store client...: Ray names them in ``comm``), whose CPU is Ray's
per-actor work, and unnamed ones keeping the process's name: OpenCV's ``parallel_for`` pool (``cv2.getNumThreads()``
is 2 on two cores, so each ``warpPerspective`` of the renderer runs partly on a pool thread: measured alone, that
thread took 2/3 of the warp's CPU). Without py-spy (not on the PATH) every thread keeping the process's name is
in that unnamed row. Node level: the CPU
of every process of this driver's Ray node over the same window (drone actors, the recorder actor, raylet, GCS,
dashboard and runtime-env agents, the driver). Both are given as CPU-seconds per drone per simulated second
(``cpu_s / (drones x window_s x speedup)``): unlike missed ticks, a CPU-time share does not change when other
work shares the cores.

Memory: the drone actor's PSS (``/proc/<pid>/smaps``: proc(5); shared pages divided by the processes mapping them)
split by mapping: the shared ground cache (``aerodaas.sim.ground_cache``), POSIX shared memory, each Python
package's extension libraries (so an import an actor does not need shows up here with its size), the
interpreter and system libraries, and anonymous memory (Python objects, malloc arenas, thread stacks).
"""
from __future__ import annotations

import enum
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, field

from aerodaas.bench.procs import ray_processes
from aerodaas.sim.ground_cache import cache_dir

__all__ = ["Component", "ThreadCpu", "classify_stack", "thread_cpu", "thread_wakes", "process_counts", "bare_row",
           "smaps_pss", "attribute", "ActorProfiler"]


class Component(enum.Enum):
    """Where a drone actor's CPU time goes; the value is the row's label in the cost table."""

    PHYSICS = "physics (vehicle model steps)"
    CONTROL = "control and mission (control ticks, safety gate, waypoint queue)"
    ODOMETRY = "odometry and stat-stream"
    CAMERA = "camera rendering (homography warp of the ground)"
    ANALYTICS = "the drone's colocated analytics (its process call)"
    ANALYTICS_HOST = "analytics hosting (mailbox, outputs, accounting)"
    DATA_PLANE = "data plane (hand-off, channel sends)"
    RECORD_ENCODE = "recording: JPEG encoding of frames"
    RECORDING = "recording: batching and sending to the recorder, checkpoints"
    CLOCK = "clock loop (pacing, scheduling captures)"
    POOL = "thread pools (waiting for and taking each job: the data plane's, Ray's)"
    RAY_PYTHON = "Ray, Python side (worker main loop, actor calls)"
    RAY_CORE = "Ray, C++ threads (core worker I/O, gRPC, heartbeats, object store client)"
    NATIVE_UNNAMED = "unnamed native threads (OpenCV's worker pool: its share of each warp)"


#: first match wins: the innermost concern before the caller that contains it (an analytics runs inside the
#: camera's publish, the JPEG encode inside the recorder's send)
_RULES: tuple[tuple[Component, tuple[str, ...]], ...] = (
    (Component.RECORD_ENCODE, ("encode_frame (", "imencode")),
    (Component.ANALYTICS, ("FrameExposure.process", "Analytics.process")),
    (Component.ANALYTICS_HOST, ("AnalyticsComponent",)),
    (Component.RECORDING, ("RemoteRecorder", "RecorderService", "_Checkpointer", "drone_checkpoint")),
    # the frame's making only: the capture's scheduling on the clock thread and the frame's hand-off are the data
    # plane's ("Component." below)
    (Component.CAMERA, ("World.render", "frame_at (", "CameraComponent._produce (")),
    (Component.PHYSICS, ("SimBackend.step", "SimVehicle.step")),
    (Component.ODOMETRY, ("OdometryPublisher", "publish_odometry", "StatStream")),
    (Component.CONTROL, ("DroneComponent", "DroneInbox", "QueueFlight", "MissionFSM", "SafetyGate")),
    (Component.DATA_PLANE, ("DataPlane", "ChannelOutlet", "ChannelServer", "Component.")),
    (Component.CLOCK, ("ActorAssembly.run",)),
    (Component.RAY_PYTHON, ("(ray/", "ray/_private", "ray/_raylet")),
    (Component.POOL, ("_worker (concurrent/futures/thread.py",)),
)

#: the analytics component's calls into the analytics object (``actors/analytics/component.py``)
_USER_CALLS = ("AnalyticsComponent._process_one (", "AnalyticsComponent.handle_batch (")


def classify_stack(stack: str) -> Component:
    """The component of one py-spy stack (``frame;frame;...`` outermost first, each ``function (file:line)``):
    a frame the analytics component called, and what it calls, is the analytics' own; otherwise the first of
    ``_RULES`` whose pattern appears in it, else :attr:`Component.RAY_PYTHON` for an otherwise unknown frame set
    (the worker's own threads)."""
    frames = stack.split(";")
    for i, f in enumerate(frames[:-1]):
        if f.startswith(_USER_CALLS) and ".process" in frames[i + 1]:
            return Component.ANALYTICS
    for comp, patterns in _RULES:
        if any(p in stack for p in patterns):
            return comp
    return Component.RAY_PYTHON


@dataclass(frozen=True)
class ThreadCpu:
    """One thread: native id, ``comm`` (the name Ray's C++ threads set; a Python thread keeps the process's),
    CPU seconds consumed since it started (utime + stime)."""

    tid: int
    comm: str
    cpu_s: float


def thread_cpu(pid: int) -> dict[int, ThreadCpu]:
    """Every thread of ``pid`` now (tid -> :class:`ThreadCpu`); a thread that exits while being read is skipped.
    Raises FileNotFoundError when the process is gone."""
    tick = os.sysconf("SC_CLK_TCK")
    out: dict[int, ThreadCpu] = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{tid}/stat") as f:
                raw = f.read()
        except OSError:
            continue
        comm = raw[raw.index("(") + 1: raw.rindex(")")]
        rest = raw[raw.rindex(")") + 2:].split()  # fields from 3 (state) on; utime, stime are fields 14, 15
        out[int(tid)] = ThreadCpu(int(tid), comm, (int(rest[11]) + int(rest[12])) / tick)
    return out


def thread_wakes(pid: int) -> int:
    """The voluntary context switches of every thread of ``pid`` so far, summed (``voluntary_ctxt_switches`` in each
    ``/proc/<pid>/task/<tid>/status``: proc(5)): each is a thread blocking (a sleep, a lock, a queue, a socket), to
    be woken again, so their rate is the process's wakes per second. A thread that exits between two reads loses
    its count. Raises FileNotFoundError when the process is gone."""
    total = 0
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{tid}/status") as f:
                for line in f:
                    if line.startswith("voluntary_ctxt_switches:"):
                        total += int(line.split()[1])
                        break
        except OSError:
            continue
    return total


_PYSPY_LINE = re.compile(r"^thread \((?:0x)?([0-9a-fA-F]+)\)(?::[^;]*)?;(.*) (\d+)$")


#: innermost frames of a thread that waits: a pool worker blocked taking its next job, a condition or event wait,
#: the clock's sleep, Ray's worker loop (in its C++ event loop), a socket accept or receive. py-spy
#: ``--nonblocking`` reads the Python stacks only and counts such samples too (more on a loaded machine)
_WAITING = ("_worker (concurrent/futures/thread.py", "Condition.wait (threading.py", "Event.wait (threading.py",
            "_sleep_until (", "Worker.main_loop (", "socket.accept (", "Connection._recv (", "Semaphore.acquire (")


def parse_pyspy_raw(text: str) -> dict[int, dict[Component, int]]:
    """py-spy ``--threads --format raw`` output -> native tid -> component -> samples. py-spy writes the thread as
    ``thread (<tid>)`` (decimal native id on Linux) as the first frame, optionally followed by its Python name. A
    thread's samples in a wait (:data:`_WAITING`, the innermost frame) count only when it has no other samples
    (its CPU is then its waits': Ray's worker loop); otherwise its CPU is split over what it ran, so a pool thread
    that waited most of the window does not put its renders' CPU into the wait."""
    ran: dict[int, dict[Component, int]] = {}
    waited: dict[int, dict[Component, int]] = {}
    for line in text.splitlines():
        m = _PYSPY_LINE.match(line.strip())
        if not m:
            continue
        tid, stack = int(m.group(1)), m.group(2)
        per = waited if stack.rsplit(";", 1)[-1].startswith(_WAITING) else ran
        comp = classify_stack(stack)
        per.setdefault(tid, {})
        per[tid][comp] = per[tid].get(comp, 0) + int(m.group(3))
    return {tid: ran.get(tid) or waited[tid] for tid in sorted(set(ran) | set(waited))}


def attribute(before: dict[int, ThreadCpu], after: dict[int, ThreadCpu],
              samples: dict[int, dict[Component, int]] | None, process_comm: str) -> dict[Component, float]:
    """CPU seconds per component over a window: each thread's CPU delta (a thread born in the window counts from
    0) split in proportion to its py-spy samples; a thread without samples is Ray's C++ work when its ``comm`` is
    its own (Ray names its threads), else an unnamed native thread (OpenCV's pool). ``samples`` None: no profiler
    ran."""
    cpu: dict[Component, float] = {}
    for tid, th in after.items():
        delta = th.cpu_s - (before[tid].cpu_s if tid in before else 0.0)
        if delta <= 0:
            continue
        mine = (samples or {}).get(tid)
        if mine:
            total = sum(mine.values())
            for comp, n in mine.items():
                cpu[comp] = cpu.get(comp, 0.0) + delta * n / total
        else:
            comp = Component.NATIVE_UNNAMED if th.comm == process_comm else Component.RAY_CORE
            cpu[comp] = cpu.get(comp, 0.0) + delta
    return cpu


def _mapping_kind(path: str, ground_dir: str) -> str:
    """The row of a mapping in the PSS breakdown."""
    if not path or path.startswith("[anon") or path in ("[heap]", "[stack]"):
        return "anonymous (Python objects, malloc arenas, thread stacks)"
    if ground_dir and path.startswith(ground_dir):
        return "shared ground cache (memmap, one per machine)"
    if path.startswith("/dev/shm") or "plasma" in path or path.startswith("/memfd:"):
        return "shared memory (object store, channel slots)"
    m = re.search(r"site-packages/([A-Za-z0-9_.\-]+?)(?:/|\.libs/|$)", path)
    if m:
        pkg = m.group(1).removesuffix(".libs")
        return f"package {pkg.split('-')[0].lower()}"
    if "/lib/python3" in path or "libpython" in path:
        return "CPython standard library"
    return "system libraries and other files"


def smaps_pss(pid: int) -> dict[str, float]:
    """PSS (MiB) of ``pid`` by mapping kind (``/proc/<pid>/smaps``). Raises FileNotFoundError when it is gone."""
    try:
        ground = str(cache_dir())
    except Exception:  # noqa: BLE001 - the ground cache's place only labels rows
        ground = ""
    kinds: dict[str, float] = {}
    path = ""
    with open(f"/proc/{pid}/smaps") as f:
        for line in f:
            head = line.split(None, 5)
            if len(head) >= 5 and "-" in head[0] and not head[0].endswith(":"):
                path = head[5].strip() if len(head) > 5 else ""
            elif line.startswith("Pss:"):
                kind = _mapping_kind(path, ground)
                kinds[kind] = kinds.get(kind, 0.0) + int(line.split()[1]) / 1024.0
    return {k: round(v, 1) for k, v in sorted(kinds.items(), key=lambda kv: -kv[1])}


def _role(name: str) -> str:
    """A node process's row in the node-level table, from its name."""
    for key, role in (("DroneActor", "drone actors"), ("RecorderActor", "recorder actor"),
                      ("raylet", "raylet"), ("gcs_server", "GCS"), ("driver", "driver (aerodaas bench)")):
        if key in name:
            return role
    return "Ray's other processes (agents, log monitor, idle workers)"


@dataclass
class ActorProfiler:
    """Profiles the first drone actor of the running fleet for ``window_s`` seconds once it flies (``delay_s`` after
    the first drone actor began its flight), in a background thread; :attr:`result` holds the tables (None when no
    window could be taken: the run ended first). ``drones_per_actor`` and ``speedup`` turn CPU seconds into
    CPU-seconds per drone per simulated second; ``drones`` is the fleet size (node-level rows). ``bare_pid``: the
    process of an idle :class:`~aerodaas.bench.bare_actor.BareActor` beside the fleet, measured over the same window
    (``"bare_actor"`` in the tables) and left out of the node's rows."""

    drones: int
    drones_per_actor: int
    bare_pid: int | None = None
    speedup: float = 1.0
    window_s: float = 10.0
    delay_s: float = 3.0
    rate_hz: int = 50
    result: dict | None = None
    error: str | None = None
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    def start(self) -> "ActorProfiler":
        self._thread = threading.Thread(target=self._run, name="bench-fleet-profiler", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(self.window_s + 30)

    @staticmethod
    def _flying_actor(procs: list) -> int | None:
        """The pid of a drone actor running its flight (Ray titles the worker ``ray::DroneActor.run`` while it
        executes :meth:`DroneActor.run`), or None."""
        for p in procs:
            try:
                if " ".join(p.cmdline()[:1]).startswith("ray::DroneActor.run"):
                    return p.pid
            except Exception:  # noqa: BLE001 - a process that exited
                continue
        return None

    def _run(self) -> None:
        try:
            self.result = self._measure()
        except Exception as e:  # noqa: BLE001 - reported in the benchmark's JSON, never fatal to the run
            self.error = f"{type(e).__name__}: {e}"

    def _measure(self) -> dict | None:
        procs, pid = [], None
        while pid is None:  # the fleet's start takes 3 s to a minute, with the load
            if self._stop.wait(0.5):
                return None
            procs = ray_processes()
            pid = self._flying_actor(procs)
        if self._stop.wait(self.delay_s):  # past the take-off (the driver starts every actor's flight at once)
            return None
        procs = ray_processes(exclude=(self.bare_pid,) if self.bare_pid else ())
        comm = open(f"/proc/{pid}/comm").read().strip()
        node0 = _node_cpu(procs)
        bare0 = process_counts(self.bare_pid)
        before, wakes0, t0 = thread_cpu(pid), thread_wakes(pid), time.monotonic()
        samples = self._pyspy(pid)
        if samples is None:
            self._stop.wait(self.window_s)
        after, wakes1, window = thread_cpu(pid), thread_wakes(pid), time.monotonic() - t0
        bare1 = process_counts(self.bare_pid)
        node1 = _node_cpu(procs)
        per = self.drones_per_actor * window * self.speedup
        actor = attribute(before, after, samples, comm)
        node: dict[str, float] = {}
        for key, (role, c1) in node1.items():
            node[role] = node.get(role, 0.0) + c1 - node0.get(key, (role, c1))[1]
        sim_s = self.drones * window * self.speedup
        return {"actor_pid": pid, "window_s": round(window, 2), "drones_in_actor": self.drones_per_actor,
                "profiler": "py-spy" if samples is not None else "none (per-thread CPU only)",
                "threads": len(after),
                "actor_cpu_s_per_drone_per_sim_s": {c.value: round(v / per, 4) for c, v in
                                                    sorted(actor.items(), key=lambda kv: -kv[1])},
                "actor_cpu_s_per_drone_per_sim_s_total": round(sum(actor.values()) / per, 4),
                "threads_cpu_s_per_drone_per_sim_s": _busiest_threads(pid, before, after, per),
                "node_cpu_s_per_drone_per_sim_s": {r: round(v / sim_s, 4) for r, v in
                                                   sorted(node.items(), key=lambda kv: -kv[1])},
                "node_cpu_s_per_drone_per_sim_s_total": round(sum(node.values()) / sim_s, 4),
                "actor_wakes_per_s": round((wakes1 - wakes0) / window, 1),
                "actor_pss_mb": smaps_pss(pid),
                **({"bare_actor": bare_row(self.bare_pid, bare0, bare1, window, per)} if bare0 and bare1 else {})}

    def _pyspy(self, pid: int) -> dict[int, dict[Component, int]] | None:
        """py-spy over the window (blocks for it): tid -> component -> samples; None without py-spy on the PATH.
        Its raw output goes to a temporary file, removed after reading."""
        exe = shutil.which("py-spy")
        if exe is None:
            return None
        fd, path = tempfile.mkstemp(prefix="aerodaas-fleet-pyspy-", suffix=".txt")
        os.close(fd)
        subprocess.run([exe, "record", "--pid", str(pid), "--duration", str(int(round(self.window_s))),
                        "--rate", str(self.rate_hz), "--threads", "--nonblocking", "--format", "raw", "-o", path],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=self.window_s + 30, check=False)
        with open(path) as f:
            text = f.read()
        os.unlink(path)
        return parse_pyspy_raw(text)


def process_counts(pid: int | None) -> tuple[float, int, int] | None:
    """Process ``pid``'s (CPU seconds, wakes, threads) so far (:func:`thread_cpu`, :func:`thread_wakes`); None for
    no pid or when it is gone."""
    if not pid:
        return None
    try:
        threads = thread_cpu(pid)
        return sum(t.cpu_s for t in threads.values()), thread_wakes(pid), len(threads)
    except FileNotFoundError:
        return None


def bare_row(pid: int, c0: tuple[float, int, int], c1: tuple[float, int, int], window: float, per: float) -> dict:
    """The bare actor's row from its :func:`process_counts` ``c0`` and ``c1`` taken ``window`` seconds apart: its CPU
    per second (cores) and per ``per`` (drones x window x speed-up of the profiled actor: the floor of that grouping
    per drone per simulated second), its wakes per second, threads and PSS (MiB; None when it is gone)."""
    try:
        pss = round(sum(smaps_pss(pid).values()), 1)
    except FileNotFoundError:
        pss = None
    cpu = c1[0] - c0[0]
    return {"pid": pid, "cpu_s_per_s": round(cpu / window, 4), "cpu_s_per_drone_per_sim_s": round(cpu / per, 4),
            "wakes_per_s": round((c1[1] - c0[1]) / window, 1), "threads": c1[2], "pss_mb": pss}


def _busiest_threads(pid: int, before: dict[int, ThreadCpu], after: dict[int, ThreadCpu], per: float) -> list[list]:
    """The six threads of process ``pid`` with the most CPU in the window, ``[tid, comm, CPU-s per drone per sim
    s]``, its main thread (Ray's worker loop; its tid is the pid) marked ``main``."""
    rows = [[tid, "main" if tid == pid else th.comm, (th.cpu_s - (before[tid].cpu_s if tid in before else 0.0)) / per]
            for tid, th in after.items()]
    return [[tid, comm, round(v, 4)] for tid, comm, v in sorted(rows, key=lambda r: -r[2])[:6]]


def _node_cpu(procs: list) -> dict[int, tuple[str, float]]:
    """pid -> (role, CPU seconds so far) of every process in ``procs`` still alive."""
    out: dict[int, tuple[str, float]] = {}
    for p in procs:
        try:
            t = p.cpu_times()
            name = "driver" if p.pid == os.getpid() else (p.name() + " " + " ".join(p.cmdline()[:1]))
        except Exception:  # noqa: BLE001 - exited
            continue
        out[p.pid] = (_role(name), t.user + t.system)
    return out
