"""One MAVLink link, many vehicles: robots naming one connection share one socket and receive
their own system id's messages; commands carry each robot's target_system; ``auto`` takes the next unclaimed id;
a clash is refused before Ray starts; ``aerodaas plan`` puts robots of one link in one drone actor."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np
import pytest

from aerodaas.backends import BackendError, make_backend
from aerodaas.backends.mavlink import shared_link
from aerodaas.config import ConfigError, MavlinkConfig, RobotConfig, load_environment_config
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
from aerodaas.model.types import GeoPoint
from tests.inputs.cli_inprocess import run_cli
from tests.mavlink.emulated import run_until
from tests.video.udp_fanout import UdpFanout

ROOT = Path(__file__).resolve().parents[2]
HOME = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)


@pytest.fixture
def fleet():
    """fleet(n, autopilot) -> (emulators with system ids 1..n behind one UDP router, the router's ground-station
    connection string); everything stopped afterwards."""
    made: list = []

    def make(n: int = 3, autopilot: str = "ardupilot"):
        emus = []
        for sysid in range(1, n + 1):
            params = {"COM_OF_LOSS_T": 3.0} if autopilot == "px4" else {}
            emu = MavlinkVehicleEmulator(autopilot, speedup=5.0, system_id=sysid, home=HOME, gps_lock_s=1.0,
                                         params=params)
            emu.start("udpin:127.0.0.1:0")
            made.append(emu)
            emus.append(emu)
        router = UdpFanout([int(e.address.rsplit(":", 1)[1]) for e in emus])
        made.append(router)
        return emus, f"udpout:127.0.0.1:{router.gcs_port}"

    yield make
    for obj in reversed(made):
        obj.close() if hasattr(obj, "close") else obj.stop()


def _backend(rid: str, connection: str, target, **kw):
    mc = MavlinkConfig(connection=connection, target_system=target, stream_rate_hz=5.0, **kw)
    return make_backend(RobotConfig(id=rid, backend="mavlink", home=HOME, mavlink=mc))


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_three_vehicles_on_one_link_each_flies_its_own_target(fleet, autopilot):
    emus, conn = fleet(3, autopilot)
    backends = []
    try:
        # explicit ids first, then 'auto' takes the only id left (3), as the drone actor orders them
        for rid, target in (("r2", 2), ("r1", 1), ("r3", "auto")):
            b = _backend(rid, conn, target)
            backends.append(b)
            b.connect(timeout_s=20)
        by_id = {b.robot_id: b for b in backends}
        assert [by_id[r].link.target[0] for r in ("r1", "r2", "r3")] == [1, 2, 3]
        # one socket for the three: one link object in this process, three ports on it
        links = shared_link.links()
        assert list(links) == [MavlinkConfig(connection=conn).link_key()]
        assert sorted(next(iter(links.values())).ports) == ["r1", "r2", "r3"]
        targets = {"r1": (6.0, 0.0, 3.0), "r2": (0.0, 6.0, 3.0), "r3": (-5.0, -4.0, 3.0)}
        for rid in ("r1", "r2", "r3"):
            by_id[rid].actions.arm()
            by_id[rid].actions.takeoff(3.0)
        for rid in ("r1", "r2", "r3"):
            b = by_id[rid]
            assert run_until(b, lambda: b.state().position[2] > 2.7, 30), (rid, b.state().position)
            b.guidance.goto(targets[rid])
        for rid in ("r1", "r2", "r3"):
            b = by_id[rid]
            assert run_until(b, lambda: np.linalg.norm(b.state().position - targets[rid]) < 0.5, 40), (rid, b.state().position)
        # the firmware agrees: emulator k (system id k) is where robot rk was sent, not where the others were
        for k, rid in enumerate(("r1", "r2", "r3")):
            at = np.asarray(emus[k].snapshot()["position_origin"], float)
            assert np.linalg.norm(at - targets[rid]) < 1.0, (rid, at)
        for b in backends:
            b.guidance.land()
        for b in backends:
            assert run_until(b, lambda: not b.state().armed and not b.state().in_air, 60), (b.robot_id, b.state().position)
        for emu in emus:
            assert not emu.snapshot()["armed"]
    finally:
        for b in backends:
            b.close()
    assert shared_link.links() == {}  # the last robot to leave closed the socket


def test_a_system_id_is_claimed_once_and_a_missing_one_times_out_naming_what_was_seen(fleet):
    emus, conn = fleet(2)
    a = _backend("a", conn, 2)
    a.connect(timeout_s=20)
    try:
        b = _backend("b", conn, 2)
        with pytest.raises(BackendError, match=r"system id 2 .* already flown by robot 'a'"):
            b.connect(timeout_s=5)
        c = _backend("c", conn, 7)
        with pytest.raises(BackendError, match=r"no autopilot HEARTBEAT from system id 7 within 2 s .*seen on the "
                                               r"link: \[1, 2\]"):
            c.connect(timeout_s=2)
        d = _backend("d", conn, "auto")
        d.connect(timeout_s=20)
        assert d.link.target[0] == 1  # the one 'a' did not take
        d.close()
    finally:
        a.close()


def _env(tmp_path, robots: list, **extra) -> Path:
    p = tmp_path / "env.json"
    p.write_text(json.dumps({"name": "fleet", "robots": robots, **extra}))
    return p


def _mav(rid: str, conn: str, target) -> dict:
    return {"id": rid, "backend": "mavlink", "mavlink": {"connection": conn, "target_system": target}}


def test_same_link_and_same_system_id_is_refused_naming_both_robots(tmp_path):
    path = _env(tmp_path, [_mav("a", "udpin:0.0.0.0:14600", 1), _mav("b", "udpin:0.0.0.0:14600", 2),
                           _mav("c", "udp:127.0.0.1:14600", 1)])  # another spelling of the same port
    with pytest.raises(ConfigError) as e:
        load_environment_config(path)
    msg = str(e.value)
    assert "robots.2.mavlink.target_system" in msg and "'a' and 'c'" in msg and "system id 1" in msg
    # different links may reuse an id; 'auto' never clashes
    load_environment_config(_env(tmp_path, [_mav("a", "udpin:0.0.0.0:14600", 1), _mav("b", "udpin:0.0.0.0:14601", 1),
                                     _mav("c", "udpin:0.0.0.0:14600", "auto")]))
    with pytest.raises(ConfigError, match=r"target_system.*1-255.*got 0"):
        load_environment_config(_env(tmp_path, [_mav("a", "udpin:0.0.0.0:14600", 0)]))
    with pytest.raises(ConfigError, match=r"robots.1.mavlink.source_system.*'a' and 'b'"):
        load_environment_config(_env(tmp_path, [_mav("a", "udpin:0.0.0.0:14600", 1),
                                         {**_mav("b", "udpin:0.0.0.0:14600", 2),
                                          "mavlink": {"connection": "udpin:0.0.0.0:14600", "target_system": 2,
                                                      "source_system": 200}}]))


APP = '''
from aerodaas import *
env = Environment({env!r})
for r in env.get_env_robots():
    r.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id=r.id + "_a", x=1, y=0, z=2)]))
env.start_mission(env.get_env_robots())
'''


def _cli(*args: str):
    """``aerodaas ARGS`` in this process (:func:`tests.inputs.cli_inprocess.run_cli`, which fails the test if Ray
    starts)."""
    return run_cli(*args, cwd=ROOT)


def test_run_refuses_a_system_id_clash_with_exit_2_before_ray(tmp_path):
    env = _env(tmp_path, [_mav("a", "udpin:0.0.0.0:14600", 1), _mav("b", "udpin:0.0.0.0:14600", 1)])
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(env)))
    from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

    ray_tmp = fresh_ray_tmp(tmp_path)
    p = run_cli("run", str(app), "--quiet", env={**os.environ, "RAY_TMPDIR": str(ray_tmp)})
    assert p.returncode == 2, p.stderr[-2000:]
    assert "'a' and 'b'" in p.stderr and "system id 1" in p.stderr
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray session was started


def test_plan_puts_robots_of_one_link_in_one_drone_actor(tmp_path):
    """drones_per_actor 1, yet the three robots on udpin:14600 are one actor (one process holds the socket); the
    robot on its own link gets its own actor."""
    env = _env(tmp_path, [_mav("a", "udpin:0.0.0.0:14600", 1), _mav("x", "tcp:127.0.0.1:5760", None),
                          _mav("b", "udpin:0.0.0.0:14600", 2), _mav("c", "udpin:127.0.0.1:14600", "auto")],
               compute=[{"id": "edge", "tier": "edge"}])
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(env)))
    p = _cli("plan", str(app), "--json")
    assert p.returncode == 0, p.stderr[-2000:]
    drones = [a for a in json.loads(p.stdout)["actors"] if a["role"] == "drone"]
    assert len(drones) == 2
    shared = next(a for a in drones if "mavlink_links" in a)
    assert shared["mavlink_links"] == {"udpin:14600": ["a", "b", "c"]}
    assert {"a/drone", "b/drone", "c/drone"} <= set(shared["components"])
    alone = next(a for a in drones if a is not shared)
    assert "x/drone" in alone["components"] and "a/drone" not in alone["components"]
    p = _cli("plan", str(app))
    assert "mavlink link udpin:14600 shared by a, b, c" in p.stdout, p.stdout


@pytest.mark.e2e
def test_each_robot_gets_its_own_connect_error_and_its_own_connect_timeout(ray_session, run_options):
    """Two robots whose vehicles never answer, with connect_timeout_s 1.5 and 2.5: each error names its own robot,
    connection and timeout (mavlink.connect_timeout_s reaches the drone actor; it used to wait its own 30 s), and
    the summary prints each under its robot."""
    from aerodaas import AeroNavigation, Environment, NavigationType, Waypoint
    from aerodaas.config import parse_environment_config
    from aerodaas.emulators import free_udp_port
    from aerodaas.runtime.report import format_summary

    robots = []
    for rid, t in (("a", 1.5), ("b", 2.5)):
        robots.append({"id": rid, "backend": "mavlink", "mavlink": {
            "connection": f"udpin:127.0.0.1:{free_udp_port()}", "connect_timeout_s": t, "set_speed_limits": False}})
    env = Environment(parse_environment_config({"name": "silent", "robots": robots,
                                                "compute": [{"id": "edge", "tier": "edge"}]}))
    for r in env.get_env_robots():
        r.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id=r.id + "_a", x=1, y=0, z=2)]))
    res = env.start_mission(env.get_env_robots(), options=run_options)
    assert res.outcome == "failed"
    ea, eb = res.robots["a"]["error"], res.robots["b"]["error"]
    assert "robot 'a'" in ea and "within 1.5 s" in ea and "robot 'b'" not in ea, ea
    assert "robot 'b'" in eb and "within 2.5 s" in eb and "robot 'a'" not in eb, eb
    text = format_summary(res)
    block_a = text.split("robot a:")[1].split("robot b:")[0]
    assert "within 1.5 s" in block_a and "within 2.5 s" not in block_a, text


def test_messages_a_shared_link_drops_are_reported_as_events():
    """A robot's I/O that falls behind its vehicle on a shared link loses the oldest messages (the link never waits
    for one robot): the backend says so with a ``link_messages_dropped`` event, counted, at most every 5 s."""
    from types import SimpleNamespace as NS

    from aerodaas.backends.mavlink import MavlinkBackend
    from aerodaas.config import MavlinkConfig, RobotConfig

    b = MavlinkBackend(RobotConfig(id="q", backend="mavlink", mavlink=MavlinkConfig()))
    b.link.port = NS(dropped=0)
    b.link.losses.report(b.link.port, 100.0)
    assert [e for e in b.drain_events() if e["event"] == "link_messages_dropped"] == []
    b.link.port.dropped = 7
    b.link.losses.report(b.link.port, 101.0)
    b.link.port.dropped = 9
    b.link.losses.report(b.link.port, 102.0)  # within 5 s of the last report: held back
    b.link.losses.report(b.link.port, 106.5)
    ev = [e for e in b.drain_events() if e["event"] == "link_messages_dropped"]
    assert [(e["dropped"], e["total"]) for e in ev] == [(7, 7), (2, 9)]


def test_messages_lost_before_the_link_are_counted_by_sequence_number_per_vehicle():
    """Each sender numbers its messages 0-255 per link (MAVLink's SEQ field): the shared link counts what a gap says
    was lost, per system id and component, across the wrap, and takes a backwards step (a repeat, a message
    overtaken, a restarted sender) for no further loss;
    the backend reports it as ``link_messages_lost`` (count since the last report, total, received, percent), at
    most every 5 s, counted from its own connection."""
    from types import SimpleNamespace as NS

    from pymavlink.dialects.v20 import ardupilotmega as mav2

    from aerodaas.backends.mavlink import MavlinkBackend

    def wire(sysid: int, compid: int, seqs: list[int]) -> list:
        enc, dec = mav2.MAVLink(None, srcSystem=sysid, srcComponent=compid), mav2.MAVLink(None)
        out = []
        for q in seqs:
            enc.seq = q
            out.append(dec.parse_buffer(enc.heartbeat_encode(2, 3, 0, 0, 0).pack(enc))[0])
        return out

    msgs = iter(wire(1, 1, [250, 251, 253, 254, 2, 3, 3, 4]) + wire(1, 154, [10, 11, 15])
                + wire(2, 1, [0, 2, 1, 3])  # 1 overtaken: counted once at 2, nothing when it comes
                + wire(3, 1, [100, 101, 40, 41, 42, 43]))  # restarted: three steps back re-sync, no loss
    conn = NS(recv_msg=lambda: next(msgs, None), select=lambda t: None, close=lambda: None)
    link = shared_link.SharedLink("test:1", conn, 255, 190)
    try:
        for _ in range(3000):  # the link's reader thread (up to 30 s on a loaded machine)
            if link.messages == 21:
                break
            time.sleep(0.01)
        # system 1: autopilot 252, 255, 0, 1 lost (4), the repeated 3 no loss; camera 12-14 (3)
        assert link.counts(1) == (11, 7) and link.counts(2) == (4, 1) and link.counts(3) == (6, 0)
        assert link.counts(4) == (0, 0)
        port = shared_link.LinkPort(link, "q")
        port.target_system = 1
        assert (port.received, port.lost) == (11, 7)
    finally:
        link.close()

    b = MavlinkBackend(RobotConfig(id="q", backend="mavlink", mavlink=MavlinkConfig()))
    b.link.port = NS(dropped=0, received=100, lost=3)
    b.link.losses.count_from(b.link.port)  # what the link had counted for this system id before, as connect() does
    b.link.losses.report(b.link.port, 100.0)
    b.link.port.received, b.link.port.lost = 190, 13
    b.link.losses.report(b.link.port, 101.0)
    b.link.port.received, b.link.port.lost = 290, 15
    b.link.losses.report(b.link.port, 102.0)  # within 5 s of the last report: held back
    b.link.losses.report(b.link.port, 106.5)
    ev = [e for e in b.drain_events() if e["event"] == "link_messages_lost"]
    assert [(e["lost"], e["total"], e["received"], e["lost_pct"]) for e in ev] == [(10, 10, 90, 10.0),
                                                                                  (2, 12, 190, 5.94)]
