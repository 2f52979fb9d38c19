"""``--key-file`` on the command line: ``aerodaas sim --mavlink ... --key-file F`` (the emulated vehicle signs what it
sends and drops unsigned commands) and ``aerodaas mission upload|download --key-file F`` (signed as the backend
signs: aerodaas/backends/mavlink/signing.py), against each other over loopback TCP. Judged by what the vehicle
answers (a command acknowledged or not, the mission read back) and the exit codes and messages a user meets."""
from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from aerodaas.backends.mavlink.signing import sign_fields, sign_outgoing, now_timestamp
from aerodaas.cli import main
from tests.mavlink.test_mavlink_signing import KEY, OTHER_KEY, _key_file
from tests.mavlink.test_mission_cli import SQUARE, _positions


@pytest.fixture(scope="module")
def signing_sim(tmp_path_factory):
    """``aerodaas sim`` (ArduPilot, 4x) with the key file of :data:`KEY`, in a process of its own; yields (its
    address, the key file); stopped with SIGTERM after this module's tests, which share it (each judges its own
    exchange with the vehicle: none needs a vehicle nobody else has talked to). 4x, not 10x: the vehicle cancels a
    mission upload after 5 x 1.5 of its seconds without an answer, 0.75 wall s at 10x, which a loaded machine (load
    45) once starved the CLI for."""
    key_file = _key_file(tmp_path_factory.mktemp("signing_sim") / "vehicle.key")
    p = subprocess.Popen([sys.executable, "-m", "aerodaas.cli", "sim", "--mavlink", "tcp:127.0.0.1:0", "--speedup",
                          "4", "--home", "47.397742,8.545594,488", "--key-file", key_file],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = p.stdout.readline()
        assert " on tcp:127.0.0.1:" in line and "signing on" in line, line + p.stderr.read()[-1500:]
        yield line.split(" on ", 1)[1].split(",", 1)[0], key_file
    finally:
        p.send_signal(signal.SIGTERM)
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def test_the_sim_with_a_key_signs_its_traffic_and_drops_unsigned_commands(signing_sim):
    """An unsigned ground station hears only signed HEARTBEATs; its command goes unanswered, while the same
    connection's next command, signed with :func:`sign_outgoing` and the key, is acknowledged. TCP keeps order and
    the vehicle answers in order, so an acknowledgement of the unsigned command would come first."""
    os.environ["MAVLINK20"] = "1"
    from pymavlink import mavutil

    address, _ = signing_sim
    conn = mavutil.mavlink_connection(address, source_system=255, source_component=190, dialect="ardupilotmega")
    try:
        hbs = [conn.recv_match(type="HEARTBEAT", blocking=True, timeout=10) for _ in range(3)]
        assert all(hb is not None for hb in hbs)
        assert all(sign_fields(hb.get_msgbuf())[0] for hb in hbs)  # the vehicle signs what it sends
        for _ in range(3):  # MAV_CMD_REQUEST_MESSAGE(AUTOPILOT_VERSION), unsigned
            conn.mav.command_long_send(1, 1, 512, 0, 148, 0, 0, 0, 0, 0, 0)
        sign_outgoing(conn.mav, KEY, now_timestamp())
        conn.mav.command_long_send(1, 1, 410, 0, 0, 0, 0, 0, 0, 0, 0)  # MAV_CMD_GET_HOME_POSITION, signed
        ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=30)
    finally:
        conn.close()
    assert ack is not None and ack.command == 410, ack  # the unsigned command was never answered


def test_mission_upload_and_download_sign_with_the_key_file(signing_sim, tmp_path):
    address, key_file = signing_sim
    assert main(["mission", "upload", str(SQUARE), "--connection", address, "--key-file", key_file]) == 0
    out = tmp_path / "back.plan"
    assert main(["mission", "download", "--connection", address, "--out", str(out), "--key-file", key_file]) == 0
    want, got = _positions(SQUARE), _positions(out)
    assert len(got) == len(want) == 5
    assert all(a[0] == b[0] and abs(a[1] - b[1]) < 1e-6 and abs(a[2] - b[2]) < 1e-6 for a, b in zip(want, got))


def test_mission_download_without_the_key_or_with_another_gets_nothing(signing_sim, tmp_path, capsys):
    address, _ = signing_sim
    out = tmp_path / "back.plan"
    # 2 s to reach the vehicle, not 3: both refusals below wait the whole of it (the vehicle is up, at 10x)
    assert main(["mission", "download", "--connection", address, "--out", str(out), "--timeout", "2"]) == 2
    err = capsys.readouterr().err
    assert "not signed (no --key-file)" in err, err  # said, and the vehicle dropped what we sent
    other = _key_file(tmp_path / "other.key", OTHER_KEY)
    assert main(["mission", "download", "--connection", address, "--out", str(out), "--timeout", "2",
                 "--key-file", other]) == 2
    assert "no correctly signed heartbeat from system 1" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "back.plan.part").exists()


def test_a_key_file_others_may_read_is_refused_by_both_commands(tmp_path, capsys):
    bad = _key_file(tmp_path / "open.key", mode=0o644)
    assert main(["mission", "download", "--connection", "tcp:127.0.0.1:9", "--out", str(tmp_path / "x.plan"),
                 "--key-file", bad]) == 2
    err = capsys.readouterr().err
    assert "--key-file" in err and "has mode 0644" in err and KEY.hex() not in err, err
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "sim", "--mavlink", "tcp:127.0.0.1:0", "--key-file",
                        bad], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "--key-file" in p.stderr and "has mode 0644" in p.stderr, p.stderr[-1500:]
