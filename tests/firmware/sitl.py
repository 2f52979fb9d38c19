"""Helpers for the real-firmware tests (``tests/firmware/test_sitl_*.py``, marker ``sitl``): ArduCopter and PX4 SITL from
``../shared/sitl`` (or ``$AERODAAS_SITL_DIR``), each run in a private network namespace that has only loopback
(``unshare -n``), together with the ``aerodaas`` commands that talk to it; recordings are read back in the parent
with the ``mcap`` package's own reader (not ours).

Firmware links: ArduCopter instance ``i`` sends MAVLink to ``udpin:127.0.0.1:14550+10*i`` (``--serial0
udpclient:...``; ``-I i`` shifts its other ports by 10*i); PX4 instance ``i`` (``-i i``) sends its offboard/API
link from 14580+i to ``udpin:127.0.0.1:14540+i`` (PX4 ``ROMFS/px4fmu_common/init.d-posix/px4-rc.mavlink``).
PX4's clock factor is ``PX4_SIM_SPEED_FACTOR`` (read by SIH's ``Sih::lockstep_loop`` in
``src/modules/simulation/simulator_sih/sih.cpp``; ``rcS`` scales COM_DL_LOSS_T/COM_OF_LOSS_T/... by it).
"""
from __future__ import annotations

import copy
import json
import math
import os
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from tests.firmware.firmware_boot import boot_check
from tests.firmware.sih_sensors import fly_scenario

REPO = Path(__file__).resolve().parents[2]
SITL_DIR = Path(os.environ.get("AERODAAS_SITL_DIR", REPO.parent / "shared" / "sitl"))
if not SITL_DIR.is_dir():  # a worktree beside /work/main: the shared folder is /work/shared
    SITL_DIR = Path("/work/shared/sitl")
ARDUCOPTER = SITL_DIR / "arducopter" / "arducopter"
PX4 = SITL_DIR / "px4" / "bin" / "px4"
AERODAAS = [sys.executable, "-m", "aerodaas.cli"]

#: firmware clock factors (vehicle seconds per wall second); 2-core machines keep up with these
SPEEDUP = {"ardupilot": 5.0, "px4": 5.0}
#: PX4's ``nice``, as if it had its own processor: at 5x SIH steps its physics every 800 us of wall time, and EKF2 and
#: the controllers starved beside the tests' load answer late (an estimate of 1 m while skidding on the ground)
FIRMWARE_NICE = -10
#: the three-vehicle fleet's speed-up where it differs from :data:`SPEEDUP` (see :func:`fleet_session`)
FLEET_SPEEDUP, FARM_HOME = {"px4": 1.0}, {"lat": 13.0213, "lon": 77.5671, "alt": 920.0}
#: the robots' ``limits.max_speed`` (m/s) per autopilot. Both firmwares run their default parameters plus only what
#: our backend sets. Stock PX4 SIH's EKF2 assumes an IMU far quieter than the one SIH simulates (SIH: accelerometer
#: noise (0.5, 1.7, 1.4) m/s^2, gyro (0.14, 0.07, 0.03) rad/s per 200 Hz sample, ``Sih::reconstruct_sensors_signals``;
#: EKF2 defaults 0.35 m/s^2 and 0.015 rad/s, ``EKF2_ACC_NOISE``/``EKF2_GYR_NOISE``), so the vehicle flies up to
#: 0.5 m/s (p99) faster than its estimate says (against SIH's ground truth HIL_STATE_QUATERNION; GNSS speed minus
#: estimate: the same): no limit PX4 can be given keeps it within 0.55 m/s, and the backend reports that
#: (``speed_limit_unholdable``, aerodaas/backends/mavlink/speed_margin.py). At 2 m/s the limit holds; see HOLD_RADIUS.
MAX_SPEED = {"ardupilot": 0.5, "px4": 2.0}
#: the waypoints' acceptance radius (m) of the SITL surveys (``AERODAAS_SITL_HOLD_RADIUS_M`` of sitl_survey_app.py and
#: sitl_fleet_app.py): ArduCopter 0.3 m, apps/farm_survey.py's own. Stock PX4 SIH's estimate wanders from the setpoint
#: (the estimator mismatch above): its holds at 2 m/s erred up to 0.59-0.69 m, 2.1-4.9 of 5 s within 0.3 m.
HOLD_RADIUS = {"ardupilot": 0.3, "px4": 1.0}
#: PX4 counts a multicopter waypoint reached within the acceptance radius horizontally and this (m) in altitude
#: (NAV_MC_ALT_RAD, default 0.8; navigator mission_block.cpp): its hold may be up to hypot(HOLD_RADIUS, this) away
PX4_ALT_RAD_M = 0.8


def namespace_skip_reason() -> str | None:
    """Why the SITL tests cannot run here (None: they can): no private network namespace (``unshare -n`` needs
    root or user namespaces), or no firmware."""
    for exe in (ARDUCOPTER, PX4):
        if not exe.is_file():
            return f"SITL firmware {exe} not found (set AERODAAS_SITL_DIR)"
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "unshare/ip not installed: cannot create a private network namespace"
    try:
        r = subprocess.run(["unshare", "-n", "bash", "-c", "ip link set lo up && unshare -m --propagation private true"],
                           capture_output=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"cannot create a private network namespace: {e}"
    if r.returncode != 0:
        return f"cannot create a private network and mount namespace (unshare -n, -m): {r.stderr.decode(errors='replace').strip()}"
    return None


def connection(autopilot: str, instance: int = 0) -> str:
    """The pymavlink connection string of firmware instance ``instance`` inside the namespace."""
    return f"udpin:127.0.0.1:{14550 + 10 * instance}" if autopilot == "ardupilot" else \
        f"udpin:127.0.0.1:{14540 + instance}"


def monitor_connection(autopilot: str, instance: int = 0) -> str:
    """A second link to firmware instance ``instance`` (ArduCopter ``--serial1``; PX4's ground-station link,
    18570+i -> 14550: PX4 SITL sends every instance's to 14550, so a PX4 fleet's observer splits it by system id,
    :func:`tests.firmware.sitl_watchers.observe_raw`), for watchers beside the backend."""
    return f"udpin:127.0.0.1:{14551 + 10 * instance}" if autopilot == "ardupilot" else \
        f"udpin:127.0.0.1:{14550 + instance}"


def firmware_start(autopilot: str, instance: int, home: dict, workdir: Path, speedup: float,
                   sysid: int | None = None, extra: str = "") -> str:
    """A shell command starting firmware instance ``instance`` (fresh parameters: ArduCopter ``-w``, PX4 a new
    working directory) in the background, its output in ``workdir/fw<i>.log`` (``$!`` is the firmware's own pid);
    ``extra``: further ArduCopter options (``--serial2 ...``)."""
    log = workdir / f"fw{instance}.log"
    if autopilot == "ardupilot":
        d = ARDUCOPTER.parent
        cmd = (f"cd {shlex.quote(str(workdir))} && exec {shlex.quote(str(ARDUCOPTER))} --model + --speedup {speedup:g} "
               f"-I{instance} -w --defaults {shlex.quote(str(d / 'copter.parm'))} "
               f"--home {home['lat']},{home['lon']},{home['alt']},0 "
               f"--serial0 udpclient:127.0.0.1:{14550 + 10 * instance} "
               f"--serial1 udpclient:127.0.0.1:{14551 + 10 * instance}"
               + (f" --sysid {sysid}" if sysid is not None else "") + (f" {extra}" if extra else ""))
    else:
        w = workdir / f"px4_{instance}"
        farm = w / "bin"  # the px4-* command aliases must be symlinks to px4 (the shared copy has plain files)
        farm.mkdir(parents=True, exist_ok=True)
        for f in PX4.parent.iterdir():
            link = farm / f.name
            if not link.exists():
                link.symlink_to(f if f.name in ("px4", "px4-alias.sh") else PX4)
        env = (f"PATH={shlex.quote(str(farm))}:\"$PATH\" PX4_SIM_MODEL=sihsim_quadx PX4_SIMULATOR=sihsim HEADLESS=1 "
               f"PX4_SIM_SPEED_FACTOR={speedup:g} PX4_HOME_LAT={home['lat']} PX4_HOME_LON={home['lon']} "
               f"PX4_HOME_ALT={home['alt']}")
        px4 = (f"exec nice -n {FIRMWARE_NICE} env {env} {shlex.quote(str(farm / 'px4'))} -i {instance} "
               f"-d {shlex.quote(str(PX4.parents[1] / 'etc'))} -w {shlex.quote(str(w))}")
        # PX4's server socket and lock are fixed paths (/tmp/px4-sock-N, /tmp/px4_lock-N: px4_daemon
        # get_socket_path): in a private mount namespace with its own /tmp, so runs beside each other never meet;
        # the working directory is bound back in from the descriptor held open across the tmpfs mount (-c: mount
        # must not resolve /proc/self/fd/3 to a path the tmpfs now hides). The pid stays px4's (exec all along).
        inner = (f"exec 3<{shlex.quote(str(w))}; mount -t tmpfs tmpfs /tmp && mkdir -p {shlex.quote(str(w))} && "
                 f"mount -c --bind /proc/self/fd/3 {shlex.quote(str(w))} && exec 3<&- && cd {shlex.quote(str(w))} "
                 f"&& {px4}")
        cmd = f"cd {shlex.quote(str(w))} && exec unshare -m --propagation private bash -c {shlex.quote(inner)}"
    return f"( {cmd} ) > {shlex.quote(str(log))} 2>&1 &"


def mavlink_env(autopilot: str, app_env: Path, n: int = 1, **mavlink: Any) -> dict:
    """``app_env`` (an app's environment.json) with its first robot turned into ``n`` MAVLink robots
    (``<id>``, ``<id>_1``...) on firmware instances 0..n-1, limited to :data:`MAX_SPEED` of the autopilot;
    ``mavlink`` sets further MavlinkConfig fields."""
    cfg = json.loads(app_env.read_text())
    base = cfg["robots"][0]
    robots = []
    for i in range(n):
        r = copy.deepcopy(base)
        r["id"] = base["id"] if i == 0 else f"{base['id']}_{i}"
        r["backend"] = "mavlink"
        r["mavlink"] = {"connection": connection(autopilot, i), "autopilot": autopilot,
                        "connect_timeout_s": 60, "arm_timeout_s": 120, **mavlink}
        r.setdefault("limits", {})["max_speed"] = MAX_SPEED[autopilot]
        if autopilot == "px4":
            # our phase deadlines' margin (vehicle seconds; default 15): a PX4 SIH mission landing beside the cluster
            # lane was 1.67 m up 21.2 vehicle-s after it began (its altitude estimate swings by +-1 m when starved,
            # and the land detector waits for a still estimate), so the run ended landing_stalled (2026-11-27)
            r["deadlines"] = {"margin_s": 45.0}
        robots.append(r)
    cfg["robots"] = robots + cfg["robots"][1:]
    return cfg


def small_cameras(cfg: dict) -> dict:
    """``cfg`` with every robot's camera 320x240 at 2 FPS, for runs whose cameras are not under test: a 640x480
    15 FPS render (JPEG-encoded for the recording) at the firmware's speed-up takes the CPU the firmware needs
    (three beside three PX4 SIH on 2 cores starved them to 1.5x real time instead of 5x; OFFBOARD lost, RTL)."""
    for sensor in (s for r in cfg["robots"] for s in r.get("sensors", [])):
        if sensor.get("type") == "camera":
            sensor.setdefault("properties", {}).update(width=320, height=240, fps=2)
    return cfg


def run_in_namespace(autopilot: str, workdir: Path, steps: list[str], n: int = 1, home: dict | None = None,
                     speedup: float | None = None, timeout_s: float = 900,
                     with_firmware: bool = True, sysids: bool = False, own_dirs: bool = False,
                     extra: str = "") -> subprocess.CompletedProcess:
    """Start ``n`` fresh firmware instances, wait for each one's first HEARTBEAT (tests/firmware/firmware_boot.py),
    run the shell ``steps`` one after another in one private loopback-only network namespace (step k's exit code in
    ``workdir/rc<k>``, output in ``workdir/out<k>``; ``$FW0``..: the firmware pids), kill the firmware. ``sysids``:
    system id i + 1; ``own_dirs``: instance i in ``workdir/v<i+1>`` (its own storage); ``extra``: ArduCopter options."""
    workdir.mkdir(parents=True, exist_ok=True)
    speedup = SPEEDUP[autopilot] if speedup is None else speedup
    ray_tmp = tempfile.mkdtemp(prefix="rs", dir="/tmp")  # Ray's socket paths must stay under 107 bytes
    lines = ["set -u", "ip link set lo up", f"export RAY_TMPDIR={shlex.quote(ray_tmp)}",
             "mkdir -p $RAY_TMPDIR", f"export PYTHONPATH={shlex.quote(str(REPO))}${{PYTHONPATH:+:$PYTHONPATH}}"]
    starts = []
    for i in range(n if with_firmware else 0):
        own = workdir / f"v{i + 1}" if own_dirs else workdir
        own.mkdir(exist_ok=True)
        starts.append((firmware_start(autopilot, i, home or FARM_HOME, own, speedup, sysid=i + 1 if sysids else None,
                                      extra=extra), own / f"fw{i}.log", connection(autopilot, i)))
        lines.append(f"{starts[-1][0]}\nFW{i}=$!")
    if starts:
        lines.append(boot_check(starts, workdir / "boot.json"))
    lines.append("cleanup() { for p in $(jobs -p); do kill -9 $p 2>/dev/null; done; }")
    lines.append("trap cleanup EXIT")
    for k, step in enumerate(steps):
        lines.append(f"( cd {shlex.quote(str(REPO))} && {step} ) > {shlex.quote(str(workdir / f'out{k}'))} 2>&1; "
                     f"echo $? > {shlex.quote(str(workdir / f'rc{k}'))}")
    script = "\n".join(lines) + "\n"
    (workdir / "script.sh").write_text(script)
    # its own process group: whatever ends the wait (its timeout, pytest-timeout, Ctrl-C), the firmware and the run
    # inside are killed with the script (a SIGKILLed bash runs no EXIT trap: three PX4 SIH once outlived a
    # timed-out test and took 1.3 cores from the tests after it)
    proc = subprocess.Popen(["unshare", "-n", "bash", str(workdir / "script.sh")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout_s)
        return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    except subprocess.TimeoutExpired as e:
        raise subprocess.TimeoutExpired(proc.args, timeout_s, e.output, e.stderr) from None
    finally:
        # also when the script ended by itself: a process a step started in the background (the router of
        # router_fleet_session) is no job of the script's shell, so its EXIT trap leaves it running (a MAVProxy
        # outlived the PX4 router test at 55 % of a core); it is still in the script's process group
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
        shutil.rmtree(ray_tmp, ignore_errors=True)


def step_result(workdir: Path, k: int) -> tuple[int | None, str]:
    """(exit code, output) of step ``k`` of :func:`run_in_namespace` (None: it never finished)."""
    rc, out = workdir / f"rc{k}", workdir / f"out{k}"
    return (int(rc.read_text()) if rc.exists() else None), (out.read_text(errors="replace") if out.exists() else "")


def aerodaas_run(app: Path, env: Path, record: Path, timeout_s: float = 600, hold_radius_m: float | None = None) -> str:
    """The shell step ``aerodaas run APP --env ENV --record REC --timeout T --quiet``; ``hold_radius_m``: the
    waypoints' acceptance radius of the SITL apps (``AERODAAS_SITL_HOLD_RADIUS_M``)."""
    args = [*AERODAAS, "run", str(app), "--env", str(env), "--record", str(record), "--timeout", f"{timeout_s:g}",
            "--quiet"]
    prefix = "" if hold_radius_m is None else f"AERODAAS_SITL_HOLD_RADIUS_M={hold_radius_m:g} "
    return prefix + " ".join(shlex.quote(a) for a in args)


def read_recording(path: Path) -> dict[str, list]:
    """The JSON channels of an MCAP recording, read with the ``mcap`` package's reader: ``{topic: [(log_time_ns,
    message dict)]}``."""
    from mcap.reader import make_reader

    out: dict[str, list] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.message_encoding != "json":
                continue
            out.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data)))
    return out


def _read_or_note(path: Path) -> dict[str, list]:
    """:func:`read_recording`, or ``{}`` when the file is missing or not a finished MCAP (a crashed run): the
    test then fails on what it checks (exit code, channels) instead of erroring in its fixture."""
    from mcap.exceptions import McapError

    if not path.exists():
        return {}
    try:
        return read_recording(path)
    except (McapError, ValueError, EOFError) as e:
        print(f"{path}: not readable as a finished MCAP ({type(e).__name__}: {e})")
        return {}


def horizontal_speed(sample: dict) -> float:
    """The reported horizontal speed (m/s) of one odometry sample."""
    return float(math.hypot(sample["velocity"][0], sample["velocity"][1]))


def max_horizontal_speed(odometry: list[dict], from_positions: bool = True, window_s: float = 2.0) -> float:
    """Largest horizontal speed (m/s) in recorded odometry: the vehicle's reported velocity, and
    (``from_positions``) :func:`flown_speed` over ``window_s``."""
    best = max((horizontal_speed(o) for o in odometry), default=0.0)
    return max(best, flown_speed(odometry, window_s)) if from_positions else best


#: one GLOBAL_POSITION_INT as sent: (lat, lon in 1e-7 degrees, AMSL alt in mm), the message's own integers
PositionKey = tuple[int, int, int]


def router_positions(tlog: Path) -> dict[int, list[tuple[float, PositionKey]]]:
    """Every GLOBAL_POSITION_INT the router received, per system id, from MAVProxy's own telemetry log (``mav.tlog``,
    read with pymavlink): (the firmware's ``time_boot_ms`` in seconds, :data:`PositionKey`), sorted by time, one per
    time. What reached the router and was forwarded to our port."""
    from pymavlink import mavutil

    out: dict[int, dict[float, PositionKey]] = {}
    m = mavutil.mavlink_connection(str(tlog))
    try:
        while (msg := m.recv_match(type="GLOBAL_POSITION_INT")) is not None:
            out.setdefault(msg.get_srcSystem(), {}).setdefault(msg.time_boot_ms / 1000.0, (msg.lat, msg.lon, msg.alt))
    finally:
        m.close()
    return {k: sorted(v.items()) for k, v in out.items()}


def position_key(odometry: dict) -> PositionKey:
    """The :data:`PositionKey` of a recorded odometry message (its ``geodetic``: the message's integers / 1e7 and
    / 1000, so rounding recovers them)."""
    g = odometry["geodetic"]
    return round(g["lat"] * 1e7), round(g["lon"] * 1e7), round(g["alt"] * 1000)


#: two times this close (s) are one sample: the recording's time is the firmware's time_boot_ms plus one offset (the
#: run's clock origin), exact but for float rounding
_SAME_S = 0.0005


def unrecorded_samples(recorded: list[tuple[float, PositionKey]], sent: list[tuple[float, PositionKey]],
                       period_s: float, within: tuple[float, float] | None = None) -> tuple[float, list[tuple]]:
    """Which of the vehicle's position samples ``sent`` ((its own time in seconds, :data:`PositionKey`), sorted, from
    :func:`router_positions`) the recording's odometry ``recorded`` ((the run's vehicle clock: the same time plus
    the clock's origin, :func:`position_key`)) should hold and does not.

    The offset between the two clocks is found from the content: the median of (recorded time - sent time) over the
    recorded samples whose position the vehicle sent at one time only. (Found from times alone it is ambiguous: a
    PX4 streams GLOBAL_POSITION_INT at up to 50 Hz to its onboard link, and any offset on a 4 ms grid lands most
    10 Hz recorded times on some sent time: a first version of this check chose a wrong offset and paired 85 % of
    the samples with the wrong messages, 2026-11-24.) A recorded sample is one the vehicle sent when a sent one has
    its time (within :data:`_SAME_S`) and the same position. The drone records at most one sample per ``period_s``
    (actors/drone/odometry.py: a sample a full period after the last recorded one is always taken), so a sent
    sample is missing when it lies at least ``period_s`` after a recorded one and before the next. ``within``
    (recorded times, seconds): only that stretch (e.g. the flight) is judged.

    Returns (the fraction of recorded samples there that are sent samples, [(gap start, gap length, sample time),
    ...]: every sent sample in a gap, so a 50 Hz stream lists several per missing 10 Hz slot); (0.0, []) when
    nothing recorded lies within ``within`` or no recorded position was sent at one time only."""
    import bisect
    import collections

    if not recorded or not sent:
        return 0.0, []
    rec = sorted(recorded)
    times = [f for f, _ in sent]
    at = dict(sent)
    when = collections.defaultdict(list)
    for f, key in sent:
        when[key].append(f)
    lo_t, hi_t = within if within is not None else (rec[0][0], rec[-1][0])
    judged = [(t, key) for t, key in rec if lo_t <= t <= hi_t]
    if not judged:
        return 0.0, []
    offsets = sorted(t - when[key][0] for t, key in judged if len(when.get(key, ())) == 1)
    if not offsets:
        return 0.0, []
    shift = offsets[len(offsets) // 2]

    def sent_as(t: float, key: PositionKey) -> bool:
        i = bisect.bisect_left(times, t - shift - _SAME_S)
        return i < len(times) and times[i] <= t - shift + _SAME_S and at[times[i]] == key

    matched = sum(sent_as(t, key) for t, key in judged) / len(judged)
    missing = []
    for (a, _), (b, _) in zip(rec, rec[1:]):
        if b < lo_t or a > hi_t:
            continue
        lo = bisect.bisect_left(times, max(a + period_s, lo_t) - shift - 1e-6)
        hi = bisect.bisect_left(times, min(b, hi_t) - shift - _SAME_S)
        missing += [(round(a, 3), round(b - a, 3), round(f + shift, 3)) for f in times[lo:hi]]
    return matched, missing


def flown_speed(odometry: list[dict], window_s: float) -> float:
    """Largest horizontal distance flown between samples at least ``window_s`` vehicle seconds apart, divided by
    their time apart (m/s). Shorter windows mostly measure the jitter between a position's arrival and its
    odometry time stamp."""
    best, j = 0.0, 0
    for i, o in enumerate(odometry):
        while j + 1 < i and o["t"] - odometry[j + 1]["t"] >= window_s:
            j += 1
        dt = o["t"] - odometry[j]["t"]
        if dt >= window_s:
            p, q = o["position"], odometry[j]["position"]
            best = max(best, math.hypot(p[0] - q[0], p[1] - q[1]) / dt)
    return best


def sustained_speed(odometry: list[dict], window_s: float) -> float:
    """Largest median of the reported horizontal speed (m/s) over any ``window_s`` vehicle seconds of odometry
    (windows of at least half that): what the vehicle held, without the single samples that an estimator's
    correction jolts upward."""
    speeds = [horizontal_speed(o) for o in odometry]
    best, j = 0.0, 0
    for i, o in enumerate(odometry):
        while o["t"] - odometry[j]["t"] > window_s:
            j += 1
        if o["t"] - odometry[j]["t"] >= 0.5 * window_s:
            best = max(best, statistics.median(speeds[j:i + 1]))
    return best


# ---------------------------------------------------------------------------------------------- scenarios
FARM_APP = REPO / "apps" / "farm_survey.py"
#: the farm survey with HOLD_RADIUS (PX4)
SURVEY_APP = Path(__file__).with_name("sitl_survey_app.py")


def survey_step(autopilot: str, env: Path, record: Path, corners: int = 4) -> str:
    """The farm survey for ``autopilot``: apps/farm_survey.py itself where the firmware holds its 0.3 m
    (ArduCopter), else tests/firmware/sitl_survey_app.py with :data:`HOLD_RADIUS`; ``corners``: of the four."""
    if HOLD_RADIUS[autopilot] == 0.3 and corners == 4:
        return aerodaas_run(FARM_APP, env, record)
    return ("" if corners == 4 else f"AERODAAS_SITL_CORNERS={corners:d} ") + aerodaas_run(
        SURVEY_APP, env, record, hold_radius_m=HOLD_RADIUS[autopilot])
FARM_ENV = REPO / "apps" / "farm_survey.json"
FARM_CORNERS = [(0.0, 0.0, 1.5), (0.0, 10.0, 1.5), (10.0, 10.0, 1.5), (10.0, 0.0, 1.5)]
FLEET_APP = Path(__file__).with_name("sitl_fleet_app.py")
#: the geofence run: an exclusion circle of this radius (m) around the (10, 10) corner
FENCE_RADIUS_M = 2.0


def _write_env(path: Path, cfg: dict) -> Path:
    path.write_text(json.dumps(cfg, indent=1))
    return path


def single_vehicle_session(autopilot: str, workdir: Path, only: tuple[str, ...] | None = None) -> dict[str, Any]:
    """The single-vehicle scenarios, each in its own namespace with a freshly booted firmware instance (cold, fresh
    parameters): the farm survey in GUIDED/OFFBOARD, the same with ``use_autopilot_mission``, ``aerodaas mission
    upload --start`` (then observed until it lands; on PX4 first a mission replaced by another station, ``plan_id``),
    the farm survey with a geofence exclusion around one corner (refused before anything flies), and the farm survey
    while the firmware is stopped for 6 s (SIGSTOP/SIGCONT) in flight; on PX4 also the autopilot mission once more on
    the same vehicle rebooted (``auto_again``), our drone actor frozen in OFFBOARD (its failsafe) and the survey at
    0.5 m/s with SIH's ground truth observed (``slow``, :func:`tests.firmware.sitl_watchers.observe_truth`);
    ``only``: just these (by hand). Returns ``{name: {"rc", "out", "rec" or "observed"}}``."""
    from aerodaas.model.geo import enu_to_geodetic
    from aerodaas.model.types import GeoPoint
    from tests.firmware.sitl_mission import mission_file

    workdir.mkdir(parents=True, exist_ok=True)
    env_guided = _write_env(workdir / "guided.json", small_cameras(mavlink_env(autopilot, FARM_ENV)))
    env_auto = _write_env(workdir / "auto.json",
                          small_cameras(mavlink_env(autopilot, FARM_ENV, use_autopilot_mission=True)))
    fenced = small_cameras(mavlink_env(autopilot, FARM_ENV))
    c = enu_to_geodetic(10.0, 10.0, 0.0, GeoPoint(**FARM_HOME))
    fenced["robots"][0]["safety"] = {"geofence": {"circles": [
        {"center": [c.lat, c.lon], "radius": FENCE_RADIUS_M, "inclusion": False}]}}
    env_fence = _write_env(workdir / "fence.json", fenced)
    plan = mission_file(workdir / "mission.waypoints", FARM_HOME)
    py = shlex.quote(sys.executable)
    conn = connection(autopilot)
    # --max-speed 2: the file sets no speed, so the vehicle would fly at its own cruise speed (ArduCopter
    # WPNAV_SPEED 10 m/s, PX4 MPC_XY_CRUISE 5 m/s); the cap inserts a DO_CHANGE_SPEED 2 m/s after the take-off
    upload = " ".join(shlex.quote(a) for a in [*AERODAAS, "mission", "upload", str(plan), "--start", "--connection",
                                                conn, "--timeout", "60", "--max-speed", "2"])
    # the observer follows the vehicle on its second link from before the upload (on the CLI's link it could only start
    # once the CLI had left, and on a loaded machine a PX4 at 5x had flown past the first waypoint by then)
    seen, ready, log = (shlex.quote(str(workdir / f)) for f in ("observed.json", "observer.ready", "observer.log"))
    observe = (f"( {py} -m tests.firmware.sitl_watchers observe {monitor_connection(autopilot)} {seen} 300 {ready} "
               f"> {log} 2>&1 & ) ; for k in $(seq 1 240); do [ -e {ready} ] && break; sleep 0.5; done ; ")
    observed = f"for k in $(seq 1 700); do [ -e {seen} ] && break; sleep 0.5; done ; cat {log}"
    stopper = (f"( {py} -m tests.firmware.sitl_watchers stop-when-flying {monitor_connection(autopilot)} $FW0 3 6 "
               f"> {shlex.quote(str(workdir / 'stopper.log'))} 2>&1 & ) ; ")
    freezer = (f"( {py} -m tests.firmware.sitl_watchers freeze-our-drone {monitor_connection(autopilot)} $$ "
               f"{shlex.quote(str(workdir / 'failsafe_modes.json'))} 3 3 "
               f"> {shlex.quote(str(workdir / 'freezer.log'))} 2>&1 & ) ; ")
    # every scenario on a vehicle booted for it (the farm survey is relative to where the vehicle takes off)
    plan_id = (f"{py} -m tests.firmware.sitl_plan_id {conn} {monitor_connection(autopilot)} {FARM_HOME['lat']} "
               f"{FARM_HOME['lon']} {FARM_HOME['alt']} {shlex.quote(str(workdir / 'plan_id.json'))} ; ")
    scenarios = {
        "guided": [survey_step(autopilot, env_guided, workdir / "guided.mcap")],
        "auto": [survey_step(autopilot, env_auto, workdir / "auto.mcap")],
        "upload": [(plan_id if autopilot == "px4" else "") + observe + upload, observed],
        "fence": [survey_step(autopilot, env_fence, workdir / "fence.mcap")],
        "linkloss": [stopper + survey_step(autopilot, env_guided, workdir / "linkloss.mcap")],
    }
    # the app's mission again on the vehicle that flew it, rebooted with its storage (PX4 keeps the mission it flew
    # and reports its last item after the new upload); ArduCopter's -w wipes its storage, so only PX4
    again = {"auto_again": "auto"} if autopilot == "px4" else {}
    scenarios.update({name: [survey_step(autopilot, env_auto, workdir / f"{name}.mcap")] for name in again})
    if autopilot == "px4":  # PX4's offboard-loss failsafe; ArduCopter has none in GUIDED with stock parameters
        scenarios["failsafe"] = [freezer + survey_step(autopilot, env_guided, workdir / "failsafe.mcap")]
        # the farm survey's own 0.5 m/s on stock PX4 SIH, SIH's truth observed: a limit that cannot hold; one leg
        slow = small_cameras(mavlink_env(autopilot, FARM_ENV))
        slow["robots"][0]["limits"]["max_speed"] = 0.5
        def observed(name: str, step: str, stop: str = "") -> str:  # with SIH's truth beside it (truth_<name>.json)
            f = shlex.quote(str(workdir / f"truth_{name}.json"))  # it stops 1 s after the disarm, or told after 30 s
            return (f"( {py} -m tests.firmware.sitl_watchers observe-truth {monitor_connection(autopilot)} {f} 300"
                    f"{stop} > {shlex.quote(str(workdir / f'truth_{name}.log'))} 2>&1 & ) ; {step}; rc=$?; for k in "
                    f"$(seq 1 80); do [ -e {f} ] && break; [ $k = 60 ] && pkill -TERM -f {f}; sleep 0.5; done; exit $rc")
        scenarios["slow"] = [observed("slow", survey_step(autopilot, _write_env(workdir / "slow.json", slow),
                                                          workdir / "slow.mcap", corners=2))]
        for name in ("guided", "auto"):  # ... and the surveys at MAX_SPEED; the link loss's stop by the observer
            scenarios[name] = [observed(name, scenarios[name][0])]
        scenarios["linkloss"] = [observed("linkloss", survey_step(autopilot, env_guided, workdir / "linkloss.mcap"),
                                          " $FW0 3 6")]
    out: dict[str, Any] = {}
    for name, steps in scenarios.items():
        if only is not None and name not in only:
            continue
        d = workdir / again.get(name, name)
        fly_scenario(run_in_namespace, autopilot, d, steps, with_firmware=name != "fence", fresh=name not in again)
        for k, step in enumerate(steps):
            rc, text = step_result(d, k)
            out[name if k == 0 else "observe"] = {"rc": rc, "out": text}
    for name in ("guided", "auto", "auto_again", "linkloss", "failsafe", "slow"):
        if name in out:
            out[name]["rec"] = _read_or_note(workdir / f"{name}.mcap")
    for name in ("slow", "guided", "auto", "linkloss"):
        if name in out and (workdir / f"truth_{name}.json").exists():
            out[name]["truth"] = json.loads((workdir / f"truth_{name}.json").read_text())
    if "failsafe" in out:
        modes = workdir / "failsafe_modes.json"
        out["failsafe"]["firmware"] = json.loads(modes.read_text()) if modes.exists() else {}
    obs, plan = workdir / "observed.json", workdir / "plan_id.json"
    if "observe" in out:
        out["observe"]["observed"] = json.loads(obs.read_text()) if obs.exists() else {}
        out["plan_id"] = json.loads(plan.read_text()) if plan.exists() else {}
    return out


def fleet_session(autopilot: str, workdir: Path, n: int = 3) -> dict[str, Any]:
    """``n`` fresh firmware instances flying :data:`FLEET_APP` together (one app, one clock)."""
    workdir.mkdir(parents=True, exist_ok=True)
    env = _write_env(workdir / "fleet.json", small_cameras(mavlink_env(autopilot, FARM_ENV, n=n)))
    # PX4 SIH's CPU grows with its speed factor: three at 5x on 2 cores went silent for 3.4-4.7 s at a time (link
    # lost, OFFBOARD setpoints stopped, PX4's failsafe RTL) once anything else ran beside them; at 2x beside the
    # cluster lane one's altitude estimate swung by +-1 m and its landing stalled (2026-11-27); at 1x they keep up
    speedup = FLEET_SPEEDUP.get(autopilot)
    run_in_namespace(autopilot, workdir, [aerodaas_run(FLEET_APP, env, workdir / "fleet.mcap",
                                                              hold_radius_m=HOLD_RADIUS[autopilot])], n=n,
                     speedup=speedup)
    rc, text = step_result(workdir, 0)
    rec = workdir / "fleet.mcap"
    return {"rc": rc, "out": text, "rec": _read_or_note(rec)}


#: the ground-station port of the router (MAVProxy ``--out``) every vehicle of :func:`router_fleet_session` is behind
ROUTER_PORT = 14600


def router_fleet_session(autopilot: str, workdir: Path, n: int = 3) -> dict[str, Any]:
    """``n`` fresh ArduCopters with system ids 1..n behind ONE MAVProxy output port (as a ground station meets a
    fleet through one telemetry radio or router port): MAVProxy takes each firmware's serial0 as a master and
    forwards everything to ``udp:127.0.0.1:ROUTER_PORT``; the robots all name ``udpin:127.0.0.1:ROUTER_PORT`` with
    ``target_system`` 1..n. Each vehicle's own serial1 is followed by a raw pymavlink observer (:func:`tests.firmware.sitl_watchers.observe_raw`,
    its own link, the firmware's own time stamps) for the firmware's telemetry. Returns ``{"rc", "out", "rec", "observed": [per vehicle], "mavproxy": log,
    "router_positions": system id -> the position samples the router received (:func:`router_positions`),
    "udp": the namespace's UDP counters}``."""
    workdir.mkdir(parents=True, exist_ok=True)
    cfg = mavlink_env(autopilot, FARM_ENV, n=n)
    for i, r in enumerate(cfg["robots"]):
        r["mavlink"]["connection"] = f"udpin:127.0.0.1:{ROUTER_PORT}"
        r["mavlink"]["target_system"] = i + 1
    env = _write_env(workdir / "fleet.json", small_cameras(cfg))
    py = shlex.quote(sys.executable)
    masters = " ".join(f"--master={connection(autopilot, i)}" for i in range(n))
    router = (f"( cd {shlex.quote(str(workdir))} && exec {py} -m MAVProxy.mavproxy {masters} "
              f"--out=udp:127.0.0.1:{ROUTER_PORT} --daemon --non-interactive --streamrate=-1 "
              # MAVProxy's "delayed link" check (mavproxy_link.py handle_msec_timestamp) is for redundant links to
              # ONE vehicle: a time_boot_ms lower than the highest seen marks the link delayed and its SYS_STATUS,
              # GLOBAL_POSITION_INT, GPS_RAW_INT, VFR_HUD ... are not forwarded. PX4 stamps messages with their sample
              # time (not in send order), so about half of a PX4's SYS_STATUS were held back (tlog of 2026-11-23)
              "--cmd='set checkdelay 0' "
              # a router only: none of MAVProxy's ground-station modules (param fetches each PX4's 876 parameters at
              # start, terrain/wp/fence/rally ask for more, every module looks at every message); with them, and two
              # CPU burners, MAVProxy lost 45 % of three PX4 onboard streams at start and a robot's PARAM_SET went
              # unanswered 4 times (2026-11-24). The link module and the tlog are MAVProxy's core
              "--default-modules=log "
              f"--state-basedir={shlex.quote(str(workdir))} > {shlex.quote(str(workdir / 'mavproxy.log'))} 2>&1 & "
              f"echo $! > {shlex.quote(str(workdir / 'router.pid'))} ) ; ")
    def _watcher(conn: str, first: int, extra: str = "") -> str:
        return (f"( {py} -m tests.firmware.sitl_watchers observe-raw {conn} {shlex.quote(str(workdir / f'observed{first}.json'))} 900"
                f"{extra} > {shlex.quote(str(workdir / f'observer{first}.log'))} 2>&1 & "
                f"echo $! > {shlex.quote(str(workdir / f'observer{first}.pid'))} ) ; ")

    if autopilot == "px4":  # every PX4 instance's ground-station link goes to 14550: one observer, split by sysid
        extra = "".join(f" {i + 1}={shlex.quote(str(workdir / f'observed{i}.json'))}" for i in range(n))
        watchers = _watcher(monitor_connection(autopilot, 0), 0, extra)
    else:
        watchers = "".join(_watcher(monitor_connection(autopilot, i), i) for i in range(n))
    wait_obs = " ".join(f"{shlex.quote(str(workdir / f'observed{i}.json'))}" for i in range(n))
    step = (router + watchers + aerodaas_run(FLEET_APP, env, workdir / "fleet.mcap", hold_radius_m=HOLD_RADIUS[autopilot])
            # the namespace's UDP counters (RcvbufErrors: datagrams a full socket buffer dropped), for diagnosis
            + f"; rc=$?; cat /proc/net/snmp > {shlex.quote(str(workdir / 'snmp.txt'))}; for k in $(seq 1 600); do ok=1; for f in {wait_obs}; do [ -e $f ] || ok=0; done; "
              "[ $ok = 1 ] && break; sleep 0.5; done; "
              # the router and the observers are detached (their own process groups): stop them by pid, or they
              # outlive the test and load the ones after it
              f"kill $(cat {shlex.quote(str(workdir))}/*.pid) 2>/dev/null; exit $rc")
    run_in_namespace(autopilot, workdir, [step], n=n, sysids=True, timeout_s=1500, speedup=FLEET_SPEEDUP.get(autopilot))
    rc, text = step_result(workdir, 0)
    observed = []
    for i in range(n):
        f = workdir / f"observed{i}.json"
        observed.append(json.loads(f.read_text()) if f.exists() else {})
    log = workdir / "mavproxy.log"
    return {"rc": rc, "out": text, "rec": _read_or_note(workdir / "fleet.mcap"), "observed": observed,
            "mavproxy": log.read_text(errors="replace")[-2000:] if log.exists() else "",
            "router_positions": router_positions(workdir / "mav.tlog") if (workdir / "mav.tlog").exists() else {},
            "udp": _udp_counters(workdir / "snmp.txt")}


def _udp_counters(snmp: Path) -> dict[str, int]:
    """The namespace's UDP counters after the run (``/proc/net/snmp``'s ``Udp:`` lines), {} when not written."""
    rows = [line.split()[1:] for line in snmp.read_text().splitlines() if line.startswith("Udp:")] if snmp.exists() else []
    return dict(zip(rows[0], map(int, rows[1]))) if len(rows) >= 2 else {}


def odometry(rec: dict, robot: str = "quadrotor_base") -> list[dict]:
    return [m for _, m in rec.get(f"/{robot}/odometry", [])]


def events(rec: dict, robot: str = "quadrotor_base") -> list[dict]:
    return [m for _, m in rec.get(f"/{robot}/events", [])]
