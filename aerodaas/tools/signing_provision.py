"""The command ``aerodaas mavlink signing setup|remove --connection C --key-file F --secure-link`` (its options:
:mod:`aerodaas.commands.mavlink`; :func:`provision`): provision a vehicle with a MAVLink 2 signing key, or take it away, with
SETUP_SIGNING (MAVLink common.xml; mavlink.io/en/guide/message_signing.html "Secret Key Management": the key travels
in the clear, so only over a link the user declares secure, e.g. USB or a cable, never a radio), then check the
result by a round trip: after ``setup`` the backend connects with the key (a correctly signed HEARTBEAT, signed
acknowledgements: aerodaas/backends/mavlink/signing.py) and a signed command is acknowledged; after ``remove`` the
vehicle's HEARTBEAT comes unsigned and an unsigned command is acknowledged. No Ray, no environment file. Exit 0 when
checked, 2 for bad input (the key file, no ``--secure-link``), 1 when the vehicle does not answer as it should."""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Literal

from pymavlink import mavutil

from aerodaas.backends import BackendError, make_backend
from aerodaas.backends.mavlink._common import M
from aerodaas.backends.mavlink.shared_link import is_autopilot_heartbeat
from aerodaas.backends.mavlink.signing import (DISABLE_KEY, KeyFileError, now_timestamp, read_key_file, sign_fields,
                                               write_key_file)
from aerodaas.config import MavlinkConfig, RobotConfig

__all__ = ["SigningRequest", "provision"]

#: SETUP_SIGNING has no acknowledgement (common.xml): sent this many times, this far apart (wall seconds)
SETUP_REPEAT, SETUP_GAP_S = 3, 0.2


@dataclass(frozen=True)
class SigningRequest:
    """What ``aerodaas mavlink signing`` does (:func:`provision`).

    ``action``: ``"setup"`` gives the vehicle the key, ``"remove"`` takes signing off; ``connection``: a pymavlink
    connection string; ``key_file``: the vehicle's key file (64 hex characters or 32 raw bytes, mode 0600);
    ``generate``: for ``setup``, create the key file with a new random key when it does not exist; ``secure_link``:
    the user declares the link secure (USB, a cable; without it nothing is sent); ``target_system``: the vehicle's
    MAVLink system id 1-255, None for the first autopilot heard; ``baud``: serial baud rate; ``timeout_s``: seconds
    to wait for the vehicle at each step."""

    action: Literal["setup", "remove"]
    connection: str
    key_file: str
    generate: bool = False
    secure_link: bool = False
    target_system: int | None = None
    baud: int = 57600
    timeout_s: float = 30.0


def provision(request: SigningRequest) -> int:
    """Run ``mavlink signing setup|remove`` (see the module docstring); returns the exit code: 0 when checked, 2 for
    bad input (no ``secure_link``, a system id outside 1-255, a key file that cannot be read or written), 1 when
    the vehicle does not answer as it should."""
    name = "aerodaas mavlink signing"
    if not request.secure_link:
        print(f"{name}: --secure-link: SETUP_SIGNING carries the key in the clear; run it only over a link you "
              "declare secure (USB, a cable) and say so with --secure-link", file=sys.stderr)
        return 2
    if request.target_system is not None and not 1 <= request.target_system <= 255:
        print(f"{name}: --target-system: a MAVLink system id is 1-255, got {request.target_system}", file=sys.stderr)
        return 2
    try:
        if request.generate and request.action == "setup" and not os.path.exists(request.key_file):
            write_key_file(request.key_file, os.urandom(32))
        key = read_key_file(request.key_file)
    except (KeyFileError, OSError) as e:
        print(f"{name}: --key-file: {request.key_file!r}: {e}", file=sys.stderr)
        return 2
    try:
        if request.action == "setup":
            return _setup(request, key, name)
        return _remove(request, name)
    except (TimeoutError, ConnectionError, OSError) as e:
        print(f"{name}: {request.action} on {request.connection!r}: {e}", file=sys.stderr)
        return 1


def _open(request: SigningRequest) -> tuple[Any, Any]:
    """An unsigned pymavlink connection (MAVLink 2) and the autopilot HEARTBEAT of ``--target-system`` (else the
    first autopilot heard). Raises TimeoutError after ``--timeout`` seconds."""
    os.environ["MAVLINK20"] = "1"

    conn = mavutil.mavlink_connection(request.connection, baud=request.baud, source_system=255, source_component=190,
                                      dialect="ardupilotmega", autoreconnect=True)
    deadline = time.monotonic() + request.timeout_s
    while time.monotonic() < deadline:
        conn.mav.heartbeat_send(6, 8, 0, 0, 4)  # MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, MAV_STATE_ACTIVE
        hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
        if hb is not None and is_autopilot_heartbeat(hb, 255, 190) \
                and request.target_system in (None, hb.get_srcSystem()):
            return conn, hb
    conn.close()
    raise TimeoutError(f"no autopilot HEARTBEAT within {request.timeout_s:g} s")


def _send_setup(mav: Any, target: tuple[int, int], key: bytes, timestamp: int) -> None:
    """SETUP_SIGNING to ``target`` (system, component) with ``key`` from ``timestamp`` (10 us units since 2015)."""
    mav.setup_signing_send(target[0], target[1], list(key), timestamp)


def _setup(request: SigningRequest, key: bytes, name: str) -> int:
    """SETUP_SIGNING with the key, then the signed round trip with the backend (:func:`_check_signed`)."""
    conn, hb = _open(request)
    target = (hb.get_srcSystem(), hb.get_srcComponent())
    try:
        for _ in range(SETUP_REPEAT):
            _send_setup(conn.mav, target, key, now_timestamp())
            time.sleep(SETUP_GAP_S)
    finally:
        conn.close()
    _check_signed(request, target[0])
    print(f"{name}: system {target[0]} signs with the key in {request.key_file!r}: a signed HEARTBEAT and a signed "
          "command acknowledgement checked")
    return 0


def _check_signed(request: SigningRequest, system: int) -> None:
    """Connect the MAVLink backend with the key file (a correctly signed HEARTBEAT within ``--timeout`` or
    CredentialsRefused) and have a signed MAV_CMD_REQUEST_MESSAGE(AUTOPILOT_VERSION) acknowledged; the vehicle is
    left as it is. Raises ConnectionError naming what failed."""
    mc = MavlinkConfig(connection=request.connection, baud=request.baud, target_system=system,
                       connect_timeout_s=request.timeout_s,
                       signing_key_file=os.path.abspath(request.key_file), set_speed_limits=False,
                       fence={"upload": False})
    backend = make_backend(RobotConfig(id="vehicle", backend="mavlink", mavlink=mc))
    try:
        backend.connect()
        backend.commands.command_long("request AUTOPILOT_VERSION", M.MAV_CMD_REQUEST_MESSAGE,
                             M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    except BackendError as e:
        raise ConnectionError(f"the signed round trip failed: {e}") from None
    finally:
        backend.close(safe_end=False)


def _remove(request: SigningRequest, name: str) -> int:
    """A signed SETUP_SIGNING with the all-zero key and timestamp 0 (signing off), then an unsigned round trip:
    an unsigned HEARTBEAT and an unsigned command acknowledged (:func:`_check_unsigned`)."""
    mc = MavlinkConfig(connection=request.connection, baud=request.baud, target_system=request.target_system,
                       connect_timeout_s=request.timeout_s, signing_key_file=os.path.abspath(request.key_file),
                       set_speed_limits=False, fence={"upload": False})
    backend = make_backend(RobotConfig(id="vehicle", backend="mavlink", mavlink=mc))
    try:
        backend.connect()
        target = backend.link.target
        for _ in range(SETUP_REPEAT):
            backend.link.send(partial(_send_setup, target=target, key=DISABLE_KEY, timestamp=0))
            time.sleep(SETUP_GAP_S)
    except BackendError as e:
        raise ConnectionError(f"the vehicle did not take our signed messages: {e}") from None
    finally:
        backend.close(safe_end=False)
    _check_unsigned(request, target[0])
    print(f"{name}: system {target[0]} no longer signs: an unsigned HEARTBEAT and an unsigned command "
          "acknowledgement checked")
    return 0


def _check_unsigned(request: SigningRequest, system: int) -> None:
    """An unsigned HEARTBEAT from ``system`` and an unsigned MAV_CMD_REQUEST_MESSAGE acknowledged, within
    ``--timeout``. Raises ConnectionError when the vehicle still signs or ignores the command."""
    conn, hb = _open(replace(request, target_system=system))
    try:
        deadline = time.monotonic() + request.timeout_s
        unsigned = acked = False
        next_cmd = 0.0
        while time.monotonic() < deadline and not (unsigned and acked):
            if time.monotonic() >= next_cmd:
                conn.mav.command_long_send(system, hb.get_srcComponent(), 512, 0, 148, 0, 0, 0, 0, 0, 0)
                next_cmd = time.monotonic() + 1.0
            msg = conn.recv_match(type=["HEARTBEAT", "COMMAND_ACK"], blocking=True, timeout=0.5)
            if msg is None or msg.get_srcSystem() != system or sign_fields(msg.get_msgbuf())[0]:
                continue
            unsigned = unsigned or msg.get_type() == "HEARTBEAT"
            acked = acked or (msg.get_type() == "COMMAND_ACK" and msg.command == 512)
    finally:
        conn.close()
    if not (unsigned and acked):
        raise ConnectionError(f"after SETUP_SIGNING off: unsigned HEARTBEAT {'seen' if unsigned else 'not seen'}, "
                              f"unsigned command {'acknowledged' if acked else 'not acknowledged'} within "
                              f"{request.timeout_s:g} s")
