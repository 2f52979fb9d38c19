"""The warm driver of ``aerodaas up`` (aerodaas.clusters.warm_driver, aerodaas.clusters.warm_client): an attached
``aerodaas run`` forked from the pre-imported server behaves as the same command run in its own process
(``AERODAAS_NO_WARM_DRIVER=1``): exit code, summary, recording (read with the ``mcap`` reader), errors before Ray (no
actor created, by Ray's state API), Ctrl-C. The client's fall-back (no server, a stale socket file, the switch, a
refusal) and the server's fork-safety check need no cluster.

The cluster tests start their own ``aerodaas up`` under a private ``AERODAAS_STATE_DIR`` and stop it with
``aerodaas down``. Which path a run took is read from the cluster's log, where the server names every run it forked."""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from collections import Counter
from pathlib import Path

import pytest

from aerodaas.clusters import warm_client
from tests.conftest import REPO

APP = textwrap.dedent('''
    from aerodaas import *

    env = Environment(ENV)
    drone = env.get_robot_by_id("d1")
    scheduler = NearestNeighborScheduler(env)
    env.set_trajectory_scheduler(scheduler)
    route = [Waypoint(id=f"wp{i}", x=3.0 * i, y=0, z=Z, hover_duration=HOVER) for i in (1, 2)]
    drone.navigate(scheduler.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, route,
                                                                SchedulingType.ORDERED)))
    drone.start_mission()
''')

ENV = {"name": "warm", "robots": [{
    "id": "d1", "backend": "sim", "home": {"lat": 13.0213, "lon": 77.5671, "alt": 920.0},
    "limits": {"max_speed": 2.0, "max_vertical_speed": 1.0, "max_acceleration": 2.0, "max_yaw_rate": 90},
    "takeoff_altitude": 2.0, "sensors": [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 5}}]}],
    "compute": [{"id": "edge", "tier": "edge", "properties": {"cpus": 2, "memory_gb": 8, "accelerators": []}}],
    "simulation": {"speedup": 5, "physics_hz": 50}}

#: a duration in a summary line (wall time, medians): what differs between two runs of one app
TIMING = re.compile(r"\d+(\.\d+)? ?(ms|s)\b")


def _app(tmp_path: Path, name: str, z: float = 2, hover: float = 1) -> Path:
    (tmp_path / "env.json").write_text(json.dumps(ENV))
    app = tmp_path / f"{name}.py"
    app.write_text(APP.replace("ENV", repr(str(tmp_path / "env.json"))).replace("Z", str(z))
                   .replace("HOVER", str(hover)))
    return app


def _aerodaas(env: dict, *args: str, timeout: float = 600, cwd=REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


def _forked(state: Path) -> list[str]:
    """The runs the warm driver forked, from the cluster's log."""
    log = (state / "cluster.log").read_text(errors="replace")
    return re.findall(r"aerodaas warm driver: run \d+ for client \d+: (.*)", log)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """``aerodaas up`` in a private state folder: (environment for its clients, state folder, cluster.json)."""
    state = tmp_path_factory.mktemp("state")
    env = {k: v for k, v in os.environ.items() if k not in ("AERODAAS_NO_ATTACH", warm_client.NO_WARM_DRIVER_ENV)}
    env["AERODAAS_STATE_DIR"] = str(state)
    p = _aerodaas(env, "up", "--cpus", "2")
    assert p.returncode == 0, p.stdout + p.stderr
    st = json.loads((state / "cluster.json").read_text())
    try:
        assert st["warm_driver"].startswith("listening"), st
        yield env, state, st
    finally:
        d = _aerodaas(env, "down")
        assert d.returncode == 0, d.stdout + d.stderr
        assert not os.path.exists(warm_client.socket_path(env)), "aerodaas down left the warm driver's socket"


def _summary(out: str) -> list[str]:
    """The summary lines (from "mission outcome:" on), durations blanked."""
    return [TIMING.sub("<t>", ln).replace("/warm/", "/").replace("/own/", "/")
            for ln in out.split("mission outcome:", 1)[-1].splitlines()]


def _channels(path: Path) -> Counter:
    """Messages per channel topic, read with the ``mcap`` reader."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        return Counter(channel.topic for _schema, channel, _message in reader.iter_messages())


@pytest.mark.cluster
@pytest.mark.timeout(1200)
def test_a_run_through_the_warm_driver_is_the_same_run(cluster, tmp_path):
    env, state, _ = cluster
    app = _app(tmp_path, "warm_same")
    runs = {}
    for how, extra in (("warm", {}), ("own", {warm_client.NO_WARM_DRIVER_ENV: "1"})):
        before = len(_forked(state))
        rec = tmp_path / how / "run.mcap"  # the summary names it: the same name in another folder
        rec.parent.mkdir()
        p = _aerodaas({**env, **extra}, "run", str(app), "--quiet", "--lockstep", "--record", str(rec),
                      cwd=tmp_path)
        runs[how] = (p, rec)
        assert len(_forked(state)) - before == (1 if how == "warm" else 0), (how, p.stderr[-2000:])
    (warm, warm_rec), (own, own_rec) = runs["warm"], runs["own"]
    assert warm.returncode == own.returncode == 0, warm.stderr[-2000:] + own.stderr[-2000:]
    assert "attached to the local cluster" in warm.stderr and "attached to the local cluster" in own.stderr
    assert _summary(warm.stdout) == _summary(own.stdout), (warm.stdout, own.stdout)
    warm_ch, own_ch = _channels(warm_rec), _channels(own_rec)
    assert set(warm_ch) == set(own_ch) and warm_ch, (warm_ch, own_ch)
    assert warm_ch == own_ch, (warm_ch, own_ch)


def _actors(st: dict, env: dict) -> int:
    """How many actors (any state) Ray's state API lists on the cluster."""
    code = ("from aerodaas.clusters.local import enable_token_auth; enable_token_auth()\n"
            "from ray.util.state import list_actors\n"
            f"print('ACTORS', len(list_actors(address={'http://' + st['dashboard']!r}, limit=10000, "
            "raise_on_missing_output=False)))")
    q = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    line = [ln for ln in q.stdout.splitlines() if ln.startswith("ACTORS ")]
    assert line, q.stdout + q.stderr
    return int(line[0].split()[1])


@pytest.mark.cluster
@pytest.mark.timeout(900)
def test_a_refused_app_exits_2_with_the_same_message_and_creates_no_actor(cluster, tmp_path):
    env, state, st = cluster
    app = _app(tmp_path, "warm_refused", z=500)  # 500 m above max_altitude 120: refused before Ray
    actors = _actors(st, env)
    before = len(_forked(state))
    warm = _aerodaas(env, "run", str(app), "--quiet", cwd=tmp_path)
    assert len(_forked(state)) == before + 1, warm.stderr
    own = _aerodaas({**env, warm_client.NO_WARM_DRIVER_ENV: "1"}, "run", str(app), "--quiet", cwd=tmp_path)
    assert warm.returncode == own.returncode == 2, warm.stderr + own.stderr
    assert "max_altitude" in warm.stderr and warm.stderr == own.stderr
    assert warm.stdout == own.stdout
    assert _actors(st, env) == actors


@pytest.mark.cluster
@pytest.mark.timeout(900)
def test_a_failing_or_interrupted_mission_exit_code_passes_through(cluster, tmp_path):
    env, state, _ = cluster
    app = _app(tmp_path, "warm_failing", hover=600)  # hovers for 10 minutes: the --timeout ends it, not successful
    before = len(_forked(state))
    p = _aerodaas(env, "run", str(app), "--quiet", "--timeout", "5", cwd=tmp_path)
    assert len(_forked(state)) == before + 1
    assert p.returncode == 1 and "mission outcome: timeout" in p.stdout, p.stdout + p.stderr[-2000:]
    # Ctrl-C of the client reaches the run: a clean stop, exit 130 (the shell's 128 + SIGINT)
    probe = tmp_path / "probe.txt"
    probe.write_text("")
    q = subprocess.Popen([sys.executable, "-m", "aerodaas.cli", "run", str(app), "--quiet"], cwd=tmp_path,
                         env={**env, "AERODAAS_STARTUP_PROBE": str(probe)}, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        t_end = time.monotonic() + 600
        while "first_processed" not in probe.read_text() and "hosts_ready" not in probe.read_text():
            assert q.poll() is None and time.monotonic() < t_end, q.communicate()
            time.sleep(0.2)
        q.send_signal(signal.SIGINT)
        out, err = q.communicate(timeout=300)
    finally:
        if q.poll() is None:
            q.kill()
    assert len(_forked(state)) == before + 2
    assert q.returncode == 128 + signal.SIGINT and "mission outcome: interrupted" in out, out + err[-2000:]


def _env_for(tmp_path: Path, monkeypatch) -> str:
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path))
    monkeypatch.delenv("AERODAAS_NO_ATTACH", raising=False)
    monkeypatch.delenv(warm_client.NO_WARM_DRIVER_ENV, raising=False)
    path = warm_client.socket_path()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    return path


def test_the_client_falls_back_without_a_server_or_with_a_stale_socket(tmp_path, monkeypatch):
    path = _env_for(tmp_path, monkeypatch)
    argv = ["aerodaas", "run", "app.py"]
    assert warm_client.delegate(argv) is None  # no socket file
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    stale.bind(path)
    stale.close()  # the file stays, nobody listens: a server that was killed
    assert os.path.exists(path)
    assert warm_client.delegate(argv) is None


def _one_answer(path: str, answer: dict) -> tuple[threading.Thread, list]:
    """A server that answers one request with ``answer``; the list gets the request."""
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    srv.bind(path)
    srv.listen(1)
    got: list = []

    def serve() -> None:
        srv.settimeout(60)
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        data, fds, _, _ = socket.recv_fds(conn, 1 << 20, 3)
        got.append((json.loads(data), len(fds)))
        for fd in fds:
            os.close(fd)
        conn.send(json.dumps(answer).encode())
        conn.close()
        srv.close()

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return t, got


def test_the_client_runs_the_command_itself_when_refused_or_told_not_to(tmp_path, monkeypatch):
    path = _env_for(tmp_path, monkeypatch)
    t, got = _one_answer(path, {"refused": "another interpreter"})
    monkeypatch.setenv(warm_client.NO_WARM_DRIVER_ENV, "1")
    assert warm_client.delegate(["aerodaas", "run", "app.py"]) is None
    monkeypatch.delenv(warm_client.NO_WARM_DRIVER_ENV)
    assert warm_client.delegate(["aerodaas", "run", "app.py", "--address", "auto"]) is None
    assert warm_client.delegate(["aerodaas", "info", "x.mcap"]) is None
    assert got == []  # none of them connected
    assert warm_client.delegate(["aerodaas", "run", "app.py"]) is None  # connected, refused
    t.join(60)
    (req, nfds), = got
    assert nfds == 3 and req["argv"] == ["aerodaas", "run", "app.py"] and req["cwd"] == os.getcwd()
    assert req["env"]["AERODAAS_STATE_DIR"] == str(tmp_path)


def test_the_preload_starts_no_thread_and_refuses_an_import_that_does(tmp_path):
    # a module that starts a thread when imported, as some native libraries do (onnxruntime's thread pool does or
    # does not, depending on its environment: a module of the test's own makes the refusal deterministic)
    (tmp_path / "starts_a_thread.py").write_text(
        "import threading, time\nthreading.Thread(target=time.sleep, args=(60,), daemon=True).start()\n")
    code = textwrap.dedent("""
        import os, sys, threading
        from aerodaas.clusters.warm_driver import ForkSafetyError, preload
        preload()
        assert threading.active_count() == 1
        sys.path.insert(0, sys.argv[1])
        try:
            preload(("starts_a_thread",), baseline=())
        except ForkSafetyError as e:
            print("REFUSED", e)
    """)
    r = subprocess.run([sys.executable, "-P", "-c", code, str(tmp_path)], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "REFUSED importing starts_a_thread started a thread" in r.stdout, r.stdout
