"""No secret in a recording, a log or a summary.

One ``aerodaas run`` of a MAVLink mission on the emulated ArduPilot vehicle with every secret the project handles: the
link signed (``mavlink.signing_key_file``, the emulator holding the same key), the HITL API on with a token
(generated, as by default; used during the flight by ``aerodaas inject``, which finds it in the owner-only state
file), the live view with a token (generated, read over WSS by a protocol client; both servers bound off loopback
with a certificate made here, whose private key is a secret too) and Ray's token authentication (``RAY_AUTH_MODE=token``, the token in a file named by ``RAY_AUTH_TOKEN_PATH``). Afterwards every file
the run wrote (the recording and its sidecars, the captured console, the clients' output, the Ray session directory
of the run: its logs) is searched for each secret, as bytes and in the encodings a leak would take (hex, base64);
every MCAP file also record by record, decompressed by the ``mcap`` package's reader (its chunks are zstd-compressed,
so a secret inside a message is not in the file's bytes): every message, attachment, metadata record, channel and
schema. The
inputs (the app, the environment file, the key file, Ray's token file) and the owner-only state files are the only
places a secret may be; the state files must be mode 0600."""
from __future__ import annotations

import base64
import json
import os
import secrets
import ssl
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.inputs.test_app_value import fresh_ray_tmp
from tests.safety.tls_certs import self_signed

pytestmark = pytest.mark.e2e

APP = """from aerodaas import *
env = Environment("env.json")
drone = env.get_robot_by_id("d1")
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=30, y=0, z=5),
                                                              Waypoint(id="b", x=30, y=30, z=5)]))
drone.start_mission()
"""


def _forms(secret: bytes) -> list[bytes]:
    """The ways a leaked secret shows in a file: itself, hex (both cases), base64 and base64url."""
    return [secret, secret.hex().encode(), secret.hex().upper().encode(), base64.b64encode(secret).rstrip(b"="),
            base64.urlsafe_b64encode(secret).rstrip(b"=")]


MCAP_MAGIC = b"\x89MCAP0\r\n"


def _mcap_records(path: Path) -> list[tuple[str, bytes]]:
    """(what, bytes) of every record of the MCAP file ``path``, decompressed, read with the ``mcap`` package: each
    message's data, each attachment (name, media type, data), each metadata record (name, keys, values), and each
    channel (topic, encoding, metadata) and schema (name, encoding, data) of the summary and of the messages."""
    from mcap.reader import make_reader

    out: list[tuple[str, bytes]] = []
    channels, schemas = {}, {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is not None:
            channels.update(summary.channels)
            schemas.update(summary.schemas)
        for schema, channel, message in reader.iter_messages():
            out.append((f"message on {channel.topic}", bytes(message.data)))
            channels[channel.id] = channel
            if schema is not None:
                schemas[schema.id] = schema
        for a in reader.iter_attachments():
            out.append((f"attachment {a.name!r}", a.name.encode() + b"\n" + a.media_type.encode() + b"\n" + bytes(a.data)))
        for m in reader.iter_metadata():
            out.append((f"metadata {m.name!r}",
                        "\n".join([m.name, *(f"{k}={v}" for k, v in m.metadata.items())]).encode()))
    for c in channels.values():
        out.append((f"channel {c.topic}", "\n".join([c.topic, c.message_encoding,
                                                     *(f"{k}={v}" for k, v in c.metadata.items())]).encode()))
    for sc in schemas.values():
        out.append((f"schema {sc.name}", sc.name.encode() + b"\n" + sc.encoding.encode() + b"\n" + bytes(sc.data)))
    return out


def _wait_for(path: Path, proc: subprocess.Popen, timeout_s: float = 240) -> bool:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end and proc.poll() is None:
        if path.is_file():
            return True
        time.sleep(0.2)
    return path.is_file()


def test_no_secret_in_the_recording_the_console_or_rays_logs(tmp_path):
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator

    from tests.liveview.foxglove_ws_client import collect

    key = secrets.token_bytes(32)
    ray_token = secrets.token_hex(32)
    key_file = tmp_path / "vehicle.key"
    key_file.write_text(key.hex() + "\n")
    os.chmod(key_file, 0o600)
    ray_token_file = tmp_path / "ray_auth_token"
    ray_token_file.write_text(ray_token)
    os.chmod(ray_token_file, 0o600)
    out = tmp_path / "out"
    out.mkdir()
    state = tmp_path / "state"
    crt, tls_key = self_signed(tmp_path)  # both servers bound off loopback: HTTPS/WSS with this certificate
    emu = MavlinkVehicleEmulator("ardupilot", speedup=2.0, gps_lock_s=0.0, signing_key=key)
    address = emu.start("tcp:127.0.0.1:0")
    (tmp_path / "env.json").write_text(json.dumps({
        "robots": [{"id": "d1", "backend": "mavlink", "takeoff_altitude": 5.0,
                    "mavlink": {"connection": address, "signing_key_file": str(key_file)}}],
        "compute": [{"id": "edge", "tier": "edge"}],
        "hitl": {"enabled": True, "host": "0.0.0.0", "port": 0, "tls_cert": crt.name, "tls_key": tls_key.name}}))
    (tmp_path / "app.py").write_text(APP)
    ray_tmp = fresh_ray_tmp(tmp_path)
    env = {**os.environ, "RAY_TMPDIR": str(ray_tmp), "AERODAAS_STATE_DIR": str(state), "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN_PATH": str(ray_token_file)}
    for v in ("RAY_ADDRESS", "AERODAAS_LIVE_TOKEN", "AERODAAS_HITL_URL", "AERODAAS_HITL_TOKEN", "AERODAAS_HITL_CAFILE"):
        env.pop(v, None)
    console = out / "console.txt"
    try:
        with open(console, "wb") as sink:
            p = subprocess.Popen([sys.executable, "-m", "aerodaas.cli", "run", "app.py", "--record",
                                  str(out / "run.mcap"), "--live", "0.0.0.0:0", "--tls-cert", str(crt),
                                  "--tls-key", str(tls_key), "--timeout", "240"],
                                 cwd=tmp_path, env=env, stdout=sink, stderr=subprocess.STDOUT)
            try:
                assert _wait_for(state / "hitl.json", p), console.read_text()[-3000:]
                assert _wait_for(state / "live.json", p), console.read_text()[-3000:]
                modes = {f.name: stat.S_IMODE(f.stat().st_mode) for f in state.iterdir()}
                hitl_token = json.loads((state / "hitl.json").read_text())["token"]  # generated: printed once before
                live = json.loads((state / "live.json").read_text())
                live_token = live["token"]
                assert live["url"].startswith("wss://localhost:") and live["cafile"] == str(crt), live["url"]
                inj = subprocess.run([sys.executable, "-m", "aerodaas.cli", "inject", "--drone", "d1", "--waypoint",
                                      "0,10,5"], capture_output=True, env=env, timeout=120)
                (out / "inject.txt").write_bytes(inj.stdout + inj.stderr)
                got = collect(live["url_with_token"], {"/d1/pose": 3}, timeout_s=120,
                              ssl=ssl.create_default_context(cafile=str(crt)))
                rc = p.wait(timeout=600)
            finally:
                if p.poll() is None:
                    p.kill()
                    p.wait()
    finally:
        emu.stop()
    text = console.read_text()
    assert modes == {"hitl.json": 0o600, "live.json": 0o600}, modes
    assert inj.returncode == 0 and b"queued" in inj.stdout, inj.stdout + inj.stderr
    assert len(got["messages"]["/d1/pose"]) >= 3, got["timeline"][-5:]
    assert rc == 0 and "mission outcome: success" in text, text[-3000:]
    assert "human-in-the-loop API at https://0.0.0.0:" in text and "live view at wss://0.0.0.0:" in text, text[:3000]
    assert "INSECURE" not in text
    assert emu.signing.key == key and emu.signing.rejected == 0  # the link was signed: nothing of ours refused
    written = [f for f in (*out.rglob("*"), *ray_tmp.rglob("*")) if f.is_file() and not f.is_symlink()]
    sessions = [d for d in (ray_tmp / "ray").glob("session_*") if d.is_dir() and not d.is_symlink()]
    assert len(sessions) == 1 and any(f.suffix in (".out", ".err", ".log") for f in written), written[:20]
    assert any(f.name.startswith("run") and f.suffix == ".mcap" for f in written)
    contents: list[tuple[str, bytes]] = []  # (where, bytes) of every file, and of every record of each MCAP file
    for f in written:
        try:
            data = f.read_bytes()
        except OSError:
            continue  # a socket or a file that went away
        contents.append((str(f), data))
        if data.startswith(MCAP_MAGIC):
            contents += [(f"{f}: {what}", rec) for what, rec in _mcap_records(f)]
    messages = [w for w, _ in contents if ": message on " in w]
    assert any("/d1/pose" in w for w in messages) and any("/d1/events" in w for w in messages), messages[:20]
    found = []
    pem_body = b"".join(tls_key.read_bytes().splitlines()[1:-1])
    for name, secret in (("signing key", key), ("TLS private key", base64.b64decode(pem_body)),
                         ("HITL token", hitl_token.encode()), ("live view token", live_token.encode()),
                         ("Ray token", ray_token.encode())):
        forms = _forms(secret)
        found += [(name, where) for where, data in contents if any(x in data for x in forms)]
    assert found == [], found
