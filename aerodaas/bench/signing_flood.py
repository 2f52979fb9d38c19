"""What a flood of unsigned (and wrongly signed) MAVLink messages in a vehicle's name costs the MAVLink backend's signed
telemetry: the emulated ArduCopter signs with a key, the backend holds it, and for ``duration_s`` wall seconds the
vehicle's own link (the same socket, UDP or TCP) also carries ``factor`` times as many GLOBAL_POSITION_INT and
ATTITUDE messages as the vehicle streams, forged in its name: unsigned, and signed with another key and a timestamp
far in the future. Measured: the telemetry age (wall seconds since the backend last accepted a signed
GLOBAL_POSITION_INT or ATTITUDE, sampled every 5 ms) without and with the flood, the forged messages dropped, and
whether every signed message the vehicle sent was accepted (by its ``(type, time_boot_ms)``).

``python -m aerodaas.bench.signing_flood [--factor 20] [--duration 10] [--transport udp] [--json]``."""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import tempfile
import threading
import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.backends import make_backend
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator

__all__ = ["FloodSource", "SignedTelemetryTap", "flood_run"]

KEY = hashlib.sha256(b"aerodaas signing flood vehicle key").digest()
FORGER_KEY = hashlib.sha256(b"aerodaas signing flood forger key").digest()
WATCHED = ("GLOBAL_POSITION_INT", "ATTITUDE")


class SignedTelemetryTap:
    """What the vehicle sent and what the backend accepted of :data:`WATCHED`: wraps the emulator's send and the
    backend's handlers. ``sent`` / ``accepted``: sets of ``(type, time_boot_ms)``; ``forged_accepted``: forged
    messages (marked: ATTITUDE roll 3.0 rad, a position 1 degree north) that reached a handler; ``last``: wall time
    (time.monotonic()) of the latest accepted one."""

    def __init__(self, emu: Any, backend: Any) -> None:
        self.sent: set[tuple[str, int]] = set()
        self.accepted: set[tuple[str, int]] = set()
        self.forged_accepted = 0
        self.last = time.monotonic()
        self.recording = False
        self._lock = threading.Lock()
        link, send = emu.link, emu.link.send

        def counting_send(msg: Any, lk: Any = None) -> None:
            if self.recording and msg.get_type() in WATCHED:
                with self._lock:
                    self.sent.add((msg.get_type(), int(msg.time_boot_ms)))
            send(msg, lk)

        link.send = counting_send
        for name in WATCHED:
            handler = backend.link.handlers[name]
            backend.link.handlers[name] = self._wrap(name, handler)

    def _wrap(self, name: str, handler: Any) -> Any:
        def tapped(msg: Any) -> None:
            forged = (getattr(msg, "roll", 0.0) == 3.0) or (getattr(msg, "lat", 0) >= 890_000_000)
            with self._lock:
                if forged:
                    self.forged_accepted += 1
                else:
                    self.accepted.add((name, int(msg.time_boot_ms)))
                    self.last = time.monotonic()
            handler(msg)
        return tapped

    def missing(self) -> set[tuple[str, int]]:
        """Signed messages the vehicle sent while recording that the backend has not accepted (yet)."""
        with self._lock:
            return self.sent - self.accepted


class FloodSource(threading.Thread):
    """Forged :data:`WATCHED` messages in the name of ``emu``'s vehicle written onto its link at ``rate_hz`` in
    all (batches every 10 ms): half unsigned, half signed with :data:`FORGER_KEY` and a timestamp ten days ahead.
    :attr:`count`: messages written."""

    def __init__(self, emu: Any, rate_hz: float) -> None:
        super().__init__(daemon=True, name="signing-flood")
        self.emu, self.rate_hz, self.count = emu, rate_hz, 0
        self.stop = threading.Event()
        self._plain = M.MAVLink(None, srcSystem=emu.system_id, srcComponent=1)
        self._forged = M.MAVLink(None, srcSystem=emu.system_id, srcComponent=1)
        s = self._forged.signing
        s.secret_key, s.sign_outgoing, s.link_id = FORGER_KEY, True, 0
        s.timestamp = int((time.time() - 1420070400) * 100_000) + 10 * 86400 * 100_000

    def _batch(self, n: int) -> bytes:
        out = bytearray()
        for i in range(n):
            enc = self._plain if i % 2 else self._forged
            t = int(self.emu.state.t * 1000)
            if i % 4 < 2:
                msg = M.MAVLink_attitude_message(t, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            else:
                msg = M.MAVLink_global_position_int_message(t, 890_000_000, 0, 100_000, 100_000, 0, 0, 0, 0)
            out += msg.pack(enc)
        return bytes(out)

    def run(self) -> None:
        t0 = time.monotonic()
        while not self.stop.is_set():
            n = int(self.rate_hz * (time.monotonic() - t0)) - self.count
            while n > 0:  # a UDP datagram of up to 40 packets (< 2 kB), as a router forwards them
                k = min(n, 40)
                self.emu.inject(self._batch(k))
                self.count += k
                n -= k
            self.stop.wait(0.01)


def _ages(tap: SignedTelemetryTap, seconds: float) -> list[float]:
    """Telemetry age (s) sampled every 5 ms for ``seconds``."""
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        out.append(time.monotonic() - tap.last)
        time.sleep(0.005)
    return out


def _stats(ages: list[float]) -> dict[str, float]:
    a = sorted(ages)
    pick = (lambda q: round(a[min(len(a) - 1, int(q * len(a)))] * 1000, 1)) if a else (lambda q: float("nan"))
    return {"p50_ms": pick(0.5), "p99_ms": pick(0.99), "max_ms": round(a[-1] * 1000, 1) if a else float("nan"),
            "samples": len(a)}


def flood_run(factor: float = 20.0, duration_s: float = 10.0, transport: str = "udp", speedup: float = 1.0,
              stream_rate_hz: float = 10.0) -> dict[str, Any]:
    """One measurement (see the module docstring); returns its numbers. Raises what connecting raises."""
    emu = MavlinkVehicleEmulator("ardupilot", speedup=speedup, gps_lock_s=0.0, signing_key=KEY)
    address = emu.start("udpin:127.0.0.1:0" if transport == "udp" else "tcp:127.0.0.1:0")
    tmp = tempfile.mkdtemp(prefix="aerodaas-flood-")
    key_file = os.path.join(tmp, "vehicle.key")
    fd = os.open(key_file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(KEY.hex() + "\n")
    conn = address.replace("udpin:", "udpout:") if transport == "udp" else address
    mc = MavlinkConfig(connection=conn, target_system=emu.system_id, signing_key_file=key_file,
                       set_speed_limits=False, stream_rate_hz=stream_rate_hz)
    backend = make_backend(RobotConfig(id="flooded", backend="mavlink", mavlink=mc))
    flood = None
    try:
        backend.connect()
        tap = SignedTelemetryTap(emu, backend)
        time.sleep(1.0)
        base_n = len(tap.accepted)
        calm = _ages(tap, min(duration_s, 5.0))
        rate = (len(tap.accepted) - base_n) / max(min(duration_s, 5.0), 1e-9)  # signed WATCHED per wall second
        tap.recording = True
        flood = FloodSource(emu, factor * rate)
        flood.start()
        flooded = _ages(tap, duration_s)
        flood.stop.set()
        flood.join()
        tap.recording = False
        end = time.monotonic() + 10.0
        while tap.missing() and time.monotonic() < end:  # what is still on its way
            time.sleep(0.05)
        return {"factor": factor, "transport": transport, "duration_s": duration_s,
                "signed_rate_hz": round(rate, 1), "flood_rate_hz": round(flood.count / duration_s, 1),
                "forged_written": flood.count, "unsigned_dropped": backend.signing.unsigned,
                "bad_signature_dropped": backend.signing.bad_signature, "forged_accepted": tap.forged_accepted,
                "signed_sent": len(tap.sent), "signed_missing": len(tap.missing()),
                "queue_dropped": backend.link.port.dropped if backend.link.port is not None else None,
                "age_calm": _stats(calm), "age_flooded": _stats(flooded), "load_avg_1min": os.getloadavg()[0]}
    finally:
        if flood is not None:
            flood.stop.set()
        backend.close(safe_end=False)
        emu.stop()


def main(argv: list[str] | None = None) -> int:
    """The command line (see the module docstring)."""
    p = argparse.ArgumentParser(prog="python -m aerodaas.bench.signing_flood", description=__doc__.split("\n\n")[0])
    p.add_argument("--factor", type=float, default=20.0, help="forged messages per signed telemetry message")
    p.add_argument("--duration", type=float, default=10.0, help="wall seconds of flood")
    p.add_argument("--transport", choices=["udp", "tcp"], default="udp")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    got = flood_run(a.factor, a.duration, a.transport)
    if a.json:
        print(json.dumps(got))
    else:
        for k, v in got.items():
            print(f"{k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
