"""QGroundControl ``.plan`` and ``QGC WPL 110`` missions checked and sent to a MAVLink vehicle (:func:`upload`), or
read from one (:func:`download`): ``aerodaas mission upload|download`` (its options: :mod:`aerodaas.commands.mission`)."""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

from aerodaas.backends import BackendError, make_backend
from aerodaas.backends.mavlink.fence import fence_from_items
from aerodaas.backends.mavlink.transfer import FENCE, RALLY
from aerodaas.backends.mavlink.signing import KeyFileError
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.missionfile import MissionFileError, load_mission, plan_to_flight, save_plan, save_wpl
from aerodaas.missionfile.upload import cap_speeds, check_relative_altitudes, mission_differences, mission_frames
from aerodaas.model.types import GeoPoint

__all__ = ["download", "upload"]

_MISSION_SUFFIXES = (".plan", ".waypoints", ".txt")



def _mission_backend(args: argparse.Namespace, home=None, home_wait_s: float = 5.0):
    """A connected MAVLink backend for ``--connection``, after waiting up to ``home_wait_s`` seconds for the
    vehicle's HOME_POSITION (BackendError / ValueError name the connection)."""
    fence = {"action": args.fence_action} if getattr(args, "fence_action", None) else {}
    # set_speed_limits False: the vehicle's own speed parameters are left as they are (a started mission flies on
    # after we close, so nothing changed could be put back); the file's speeds, capped by --max-speed, are the mission
    key_file = getattr(args, "key_file", None)
    mc = MavlinkConfig(connection=args.connection, autopilot=args.autopilot, connect_timeout_s=args.timeout,
                       fence=fence, set_speed_limits=False,
                       signing_key_file=os.path.abspath(key_file) if key_file else None)
    cfg = RobotConfig(id="vehicle", backend="mavlink", mavlink=mc, **({"home": home} if home is not None else {}))
    try:  # the key read as the backend reads it (signing.py read_key_file), before anything is sent
        backend = make_backend(cfg)
    except KeyFileError as e:
        raise KeyFileError(f"--key-file: {e}") from None
    if not backend.signing.enabled:
        print(f"aerodaas mission {args.mission_cmd}: note: the link {args.connection} is not signed (no --key-file): "
              "anyone on it can command the vehicle", file=sys.stderr, flush=True)
    backend.connect()
    deadline = time.monotonic() + min(args.timeout, home_wait_s)
    while not backend.telemetry.home_received and time.monotonic() < deadline:  # ArduPilot's item 0 and .plan home need it
        time.sleep(0.05)
    return backend


def _download_fence_and_rally(backend, plan, out: Path, name: str):
    """``plan`` with the vehicle's fence (MAV_MISSION_TYPE_FENCE) and rally points (MAV_MISSION_TYPE_RALLY); what
    cannot be read, or cannot be stored in ``out`` (QGC WPL holds neither), is said on stderr, never dropped
    silently."""
    update = {}
    try:
        update["geofence"] = fence_from_items(backend.transfers.download_items(FENCE))
    except (BackendError, ValueError) as e:
        print(f"{name}: WARNING: the vehicle's geofence could not be read ({e}); {str(out)!r} has none",
              file=sys.stderr, flush=True)
    try:
        update["rally_points"] = [(w[6] / 1e7, w[7] / 1e7, float(w[8] or 0.0)) for w in backend.transfers.download_items(RALLY)]
    except BackendError as e:
        print(f"{name}: WARNING: the vehicle's rally points could not be read ({e}); {str(out)!r} has none",
              file=sys.stderr, flush=True)
    plan = plan.model_copy(update=update)
    if out.suffix.lower() != ".plan" and (not plan.geofence.is_empty or plan.rally_points):
        print(f"{name}: WARNING: the vehicle's geofence ({len(plan.geofence.polygons)} polygon(s), "
              f"{len(plan.geofence.circles)} circle(s)) and {len(plan.rally_points)} rally point(s) cannot be stored "
              f"in a QGC WPL file; download to a .plan to keep them", file=sys.stderr, flush=True)
    return plan


def _cruise_speed(backend) -> float | None:
    """The vehicle's own cruise speed in m/s (ArduCopter ``WPNAV_SPEED`` cm/s, PX4 ``MPC_XY_CRUISE`` m/s), read and
    left as it is; None when it does not answer."""
    name, unit = ("WPNAV_SPEED", 0.01) if backend.link.autopilot == "ardupilot" else ("MPC_XY_CRUISE", 1.0)
    got = backend.parameters.read([name])
    return got[name] * unit if name in got else None


def _check_read_back(backend, sent, name: str) -> None:
    """Download the vehicle's mission and compare it with ``sent`` (:func:`~aerodaas.missionfile.upload.
    mission_differences`): prints what it stored differently; raises BackendError when that changes the flight
    (command, the frame, position or altitude of a command with a position, a hold time or speed, the number of
    items)."""
    stored = backend.mission.download().items
    diffs = mission_differences(sent, stored)
    flight = [d for d in diffs if d.flight]
    for d in diffs:
        if not d.flight:
            print(f"{name}: note: the vehicle stored {d} (a field it does not keep)", file=sys.stderr, flush=True)
    if flight:
        raise BackendError("the mission read back differs from the one sent: "
                           + "; ".join(str(d) for d in flight[:5]) + "; not started")
    print(f"{name}: read back: the vehicle holds the {len(stored)} items as sent"
          + (f", but for {len(diffs)} field(s) it does not keep (above)" if diffs else ""), flush=True)


def upload(args: argparse.Namespace) -> int:
    """``aerodaas mission upload FILE``: a file of the formats of :mod:`aerodaas.missionfile` sent through the
    MAVLink backend's mission protocol. The file is read and its items checked before anything is
    sent (with :func:`~aerodaas.missionfile.plan_to_flight`: what AeroDaaS and the autopilot can fly; the altitude,
    distance and geofence bounds measured from the vehicle's own home, the file's planned home only when the
    vehicle reports none). A ``.plan``'s geofence goes up first
    (MAV_MISSION_TYPE_FENCE items and the fence parameters, ``--fence-action``; read back and compared: a mismatch
    stops the upload before the mission is sent; each fence parameter changed is printed with its old value), then
    its rally points (MAV_MISSION_TYPE_RALLY), then the mission as written: its speeds unless ``--max-speed`` caps
    them (each item changed is printed, :func:`~aerodaas.missionfile.upload.cap_speeds`), each command without a
    position in ``MAV_FRAME_MISSION`` (printed, :func:`~aerodaas.missionfile.upload.mission_frames`); no other
    vehicle parameter is changed. The mission is then read back and compared as each autopilot stores it
    (:func:`~aerodaas.missionfile.upload.mission_differences`; a different flight: exit 2, not started).
    ``--key-file``: the link signed with that key as the backend signs it (``mavlink.signing_key_file``); a key file
    that cannot be used or a vehicle that does not answer signed: exit 2 (as for a refused file or bound, named)."""
    return _transfer(args, _upload)


def download(args: argparse.Namespace) -> int:
    """``aerodaas mission download --out FILE``: the vehicle's mission read and written to ``--out`` (``.plan``,
    ``.waypoints`` or ``.txt``) only once complete, with a ``.plan``'s geofence and rally points. Exit 0, 2 for a
    file, option or vehicle that refuses (named)."""
    return _transfer(args, _download)


def _transfer(args: argparse.Namespace, step) -> int:
    """Run ``step(args, name, opened)`` (:func:`_upload` or :func:`_download`) and close the backend it opened; exit
    0, or 2 after printing the error (with the connection when the error does not name it)."""
    name = f"aerodaas mission {args.mission_cmd}"
    opened: list = []  # the backend once connected: closed at the end, whatever happened
    try:
        step(args, name, opened)
    except (MissionFileError, BackendError, ValueError, OSError) as e:
        where = f" (connection {args.connection!r})" if isinstance(e, BackendError) and args.connection not in str(e) \
            else ""
        print(f"{name}: {e}{where}", file=sys.stderr)
        return 2
    finally:
        for backend in opened:
            backend.close(safe_end=False)  # hand the vehicle over as it is: a started mission flies on
    return 0


def _upload(args: argparse.Namespace, name: str, opened: list) -> None:
    """``aerodaas mission upload`` (see :func:`upload`); the backend it connects goes into ``opened``."""
    path = Path(args.file)
    if not path.is_file():
        raise MissionFileError(f"{str(path)!r}: mission file not found")
    plan = load_mission(path)
    if not plan.items:
        raise MissionFileError(f"{str(path)!r}: the mission has no items; nothing to upload (an empty upload "
                               f"would clear the vehicle's mission)")
    # the file alone, before connecting: commands, frames, order (the bounds are measured from the vehicle's
    # home, so not yet; a planned home only stands in for AMSL altitudes here)

    plan_to_flight(plan, plan.home or GeoPoint(lat=0.0, lon=0.0, alt=0.0), check_geofence=False,
                   min_altitude=None)

    check_relative_altitudes(plan, args.max_altitude)  # needs no home: refused before connecting
    backend = _mission_backend(args, plan.home, home_wait_s=args.timeout)
    opened.append(backend)
    _check_from_vehicle_home(args, name, plan, backend, path)
    _upload_fence_and_rally(name, plan, backend, path)

    items, frames = mission_frames(plan.expanded_items())
    for f in frames:
        print(f"{name}: {f}", flush=True)
    if args.max_speed is not None:
        items, changes = cap_speeds(items, args.max_speed, _cruise_speed(backend))
        for c in changes:
            print(f"{name}: {c}", flush=True)
    sent = backend.mission.upload(items)
    print(f"{name}: {len(sent)} items from {str(path)!r} uploaded to the {backend.link.autopilot} vehicle on "
          f"{args.connection}", flush=True)
    _check_read_back(backend, sent, name)
    if args.start:
        backend.actions.arm()
        backend.mission.start()
        print(f"{name}: armed and started the mission (ArduPilot AUTO / PX4 AUTO.MISSION)", flush=True)


def _check_from_vehicle_home(args: argparse.Namespace, name: str, plan: Any, backend: Any, path: Path) -> None:
    """The altitude, distance and geofence bounds, measured from the vehicle's own home (the file's planned home
    only when the vehicle reports none). Raises MissionFileError when neither has one."""
    bounds = {"max_altitude": args.max_altitude, "max_distance": args.max_distance}
    if backend.telemetry.home_received:  # as documented: from the vehicle's own home, whatever the file planned
        plan_to_flight(plan, backend.telemetry.home, **bounds)
    elif plan.home is None:  # the bounds are measured from a home, never from a default one
        raise MissionFileError(f"{str(path)!r}: the vehicle on {args.connection} reported no home position "
                               f"within {args.timeout:g} s and the file has none; nothing was uploaded (the "
                               "altitude and distance bounds are measured from it)")
    else:  # no GPS fix yet (bench, indoors)
        print(f"{name}: warning: the vehicle reported no home position within {args.timeout:g} s; the "
              f"items are checked against the file's planned home only", file=sys.stderr, flush=True)
        plan_to_flight(plan, plan.home, **bounds)


def _upload_fence_and_rally(name: str, plan: Any, backend: Any, path: Path) -> None:
    """A ``.plan``'s geofence first (the vehicle must never fly its mission without it; each fence parameter
    changed is printed), then its rally points; both read back by the backend."""
    fence = plan.geofence
    if not fence.is_empty:
        got = backend.fence.apply(fence)
        changed = [f"{k} {got['before'][k]:g} -> {v:g}" for k, v in got["params"].items()
                   if abs(got["before"][k] - v) > 1e-6]
        print(f"{name}: geofence of {str(path)!r} ({len(fence.polygons)} polygon(s), {len(fence.circles)} "
              f"circle(s), {got['items']} fence items) uploaded and read back; it stays on the vehicle with "
              f"its parameters: " + (", ".join(changed) or "none changed"), flush=True)
    if plan.rally_points:
        n = backend.fence.upload_rally(plan.rally_points)
        print(f"{name}: {n} rally point(s) of {str(path)!r} uploaded and read back", flush=True)


def _download(args: argparse.Namespace, name: str, opened: list) -> None:
    """``aerodaas mission download --out FILE`` (see :func:`download`): written only once complete."""
    out = Path(args.out)
    if out.suffix.lower() not in _MISSION_SUFFIXES:
        raise MissionFileError(f"{str(out)!r}: --out must end in {', '.join(_MISSION_SUFFIXES)} "
                               "(QGroundControl .plan or QGC WPL 110 waypoints)")
    backend = _mission_backend(args)
    opened.append(backend)
    plan = backend.mission.download().model_copy(update={
        "firmware_type": 3 if backend.link.autopilot == "ardupilot" else 12, "vehicle_type": 2})
    plan = _download_fence_and_rally(backend, plan, out, name)
    tmp = out.with_name(out.name + ".part")
    (save_plan if out.suffix.lower() == ".plan" else save_wpl)(plan, tmp)
    os.replace(tmp, out)  # never a half-written mission file
    print(f"{name}: {len(plan.items)} items from the {backend.link.autopilot} vehicle on {args.connection} "
          f"written to {str(out)!r}", flush=True)
