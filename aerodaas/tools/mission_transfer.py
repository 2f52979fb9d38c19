"""QGroundControl ``.plan`` and ``QGC WPL 110`` missions checked and sent to a MAVLink vehicle (:func:`upload`), or
read from one (:func:`download`): ``aerodaas mission upload|download`` (its options: :mod:`aerodaas.commands.mission`)."""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from aerodaas.backends import BackendError, make_backend
from aerodaas.backends.mavlink.fence import fence_from_items
from aerodaas.backends.mavlink.transfer import FENCE, RALLY
from aerodaas.backends.mavlink.signing import KeyFileError
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.missionfile import MissionFileError, load_mission, plan_to_flight, save_plan, save_wpl
from aerodaas.missionfile.upload import cap_speeds, check_relative_altitudes, mission_frames
from aerodaas.model.types import GeoPoint

__all__ = ["Download", "Upload", "VehicleLink", "download", "upload"]

_MISSION_SUFFIXES = (".plan", ".waypoints", ".txt")


@dataclass(frozen=True)
class VehicleLink:
    """The MAVLink vehicle a transfer talks to.

    ``connection``: a pymavlink connection string (``tcp:127.0.0.1:5760``, ``udpin:0.0.0.0:14550``, ``/dev/ttyACM0``);
    ``autopilot``: its firmware, or ``"auto"`` from its HEARTBEAT (``mavlink.autopilot``); ``timeout_s``: seconds to
    reach it and, for an upload, to wait for its HOME_POSITION; ``key_file``: its MAVLink 2 signing key file
    (``mavlink.signing_key_file``, docs/security.md), None for an unsigned link."""

    connection: str
    autopilot: Literal["auto", "ardupilot", "px4"] = "auto"
    timeout_s: float = 10.0
    key_file: str | None = None


@dataclass(frozen=True)
class Upload:
    """What ``aerodaas mission upload`` sends (:func:`upload`).

    ``file``: a ``.plan``, ``.waypoints`` or ``.txt`` (QGC WPL 110) mission; ``start``: then arm and start it;
    ``fence_action``: the vehicle's own action on a breach of the plan's geofence (ArduPilot ``FENCE_ACTION``, PX4
    ``GF_ACTION``); ``max_altitude_m`` / ``max_distance_m``: refuse items higher above / farther from the vehicle's
    home, metres; ``max_speed_mps``: cap the file's speeds at this, m/s (None: as written)."""

    file: Path
    link: VehicleLink
    start: bool = False
    fence_action: Literal["rtl", "land", "hold", "report"] = "rtl"
    max_altitude_m: float = 120.0
    max_distance_m: float = 10_000.0
    max_speed_mps: float | None = None


@dataclass(frozen=True)
class Download:
    """What ``aerodaas mission download`` reads (:func:`download`): the vehicle on ``link``, written to ``out``
    (``.plan``, ``.waypoints`` or ``.txt``)."""

    out: Path
    link: VehicleLink


def _mission_backend(link: VehicleLink, name: str, *, fence_action: str | None = None, home=None,
                     home_wait_s: float = 5.0):
    """A connected MAVLink backend for ``link``, after waiting up to ``home_wait_s`` seconds for the
    vehicle's HOME_POSITION (BackendError / ValueError name the connection)."""
    fence = {"action": fence_action} if fence_action else {}
    # set_speed_limits False: the vehicle's own speed parameters are left as they are (a started mission flies on
    # after we close, so nothing changed could be put back); the file's speeds, capped by --max-speed, are the mission
    mc = MavlinkConfig(connection=link.connection, autopilot=link.autopilot, connect_timeout_s=link.timeout_s,
                       fence=fence, set_speed_limits=False,
                       signing_key_file=os.path.abspath(link.key_file) if link.key_file else None)
    cfg = RobotConfig(id="vehicle", backend="mavlink", mavlink=mc, **({"home": home} if home is not None else {}))
    try:  # the key read as the backend reads it (signing.py read_key_file), before anything is sent
        backend = make_backend(cfg)
    except KeyFileError as e:
        raise KeyFileError(f"--key-file: {e}") from None
    if not backend.signing.enabled:
        print(f"{name}: note: the link {link.connection} is not signed (no --key-file): "
              "anyone on it can command the vehicle", file=sys.stderr, flush=True)
    backend.connect()
    deadline = time.monotonic() + min(link.timeout_s, home_wait_s)
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


def _report_upload(backend, sent, name: str, where: str, connection: str) -> None:
    """Say what the backend's upload did (its events, :meth:`~aerodaas.backends.mavlink.mission.AutopilotMission.
    upload`): the items sent, a mission the vehicle replaced right after accepting it (uploaded once more, on
    stderr), and each field the vehicle's read-back holds differently without changing the flight, with why."""
    print(f"{name}: {len(sent)} items from {where} uploaded to the {backend.link.autopilot} vehicle on "
          f"{connection}", flush=True)
    not_kept = _say_upload_events(backend, name)
    for d in not_kept:
        print(f"{name}: note: the vehicle stored {d}", file=sys.stderr, flush=True)
    print(f"{name}: read back: the vehicle holds the {len(sent)} items as sent"
          + (f", but for {len(not_kept)} field(s) it stores otherwise (above)" if not_kept else ""), flush=True)


def _say_upload_events(backend, name: str) -> list[str]:
    """Print each ``mission_replaced`` event of the backend's upload (on stderr: the vehicle held another mission
    right after accepting ours, so it was uploaded once more) and return the ``fields_not_kept`` of its
    ``mission_uploaded`` event (empty when the upload failed)."""
    not_kept: list[str] = []
    for ev in backend.drain_events():
        if ev["event"] == "mission_replaced":
            print(f"{name}: note: right after accepting the {ev['count']} items the vehicle held {ev['stored']} "
                  f"({'; '.join(ev['differences'])}): another mission replaced it; uploaded it once more",
                  file=sys.stderr, flush=True)
        elif ev["event"] == "mission_uploaded":
            not_kept = ev["fields_not_kept"]
    return not_kept


def upload(request: Upload) -> int:
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
    vehicle parameter is changed. The backend's upload reads the mission back and compares it as each autopilot
    stores it (:meth:`~aerodaas.backends.mavlink.mission.AutopilotMission.upload`: a vehicle holding another flight
    than it has just accepted gets it once more; still another: exit 2, not started); each field stored
    differently without changing the flight is printed (:func:`_report_upload`).
    ``--key-file``: the link signed with that key as the backend signs it (``mavlink.signing_key_file``); a key file
    that cannot be used or a vehicle that does not answer signed: exit 2 (as for a refused file or bound, named)."""
    return _transfer(request, request.link, "aerodaas mission upload", _upload)


def download(request: Download) -> int:
    """``aerodaas mission download --out FILE``: the vehicle's mission read and written to ``--out`` (``.plan``,
    ``.waypoints`` or ``.txt``) only once complete, with a ``.plan``'s geofence and rally points. Exit 0, 2 for a
    file, option or vehicle that refuses (named)."""
    return _transfer(request, request.link, "aerodaas mission download", _download)


def _transfer(request: Upload | Download, link: VehicleLink, name: str, step) -> int:
    """Run ``step(request, name, opened)`` (:func:`_upload` or :func:`_download`) and close the backend it opened;
    exit 0, or 2 after printing the error (with the connection when the error does not name it)."""
    opened: list = []  # the backend once connected: closed at the end, whatever happened
    try:
        step(request, name, opened)
    except (MissionFileError, BackendError, ValueError, OSError) as e:
        where = f" (connection {link.connection!r})" if isinstance(e, BackendError) and link.connection not in str(e) \
            else ""
        print(f"{name}: {e}{where}", file=sys.stderr)
        return 2
    finally:
        for backend in opened:
            backend.close(safe_end=False)  # hand the vehicle over as it is: a started mission flies on
    return 0


def _upload(request: Upload, name: str, opened: list) -> None:
    """``aerodaas mission upload`` (see :func:`upload`); the backend it connects goes into ``opened``."""
    path = Path(request.file)
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

    check_relative_altitudes(plan, request.max_altitude_m)  # needs no home: refused before connecting
    backend = _mission_backend(request.link, name, fence_action=request.fence_action, home=plan.home,
                               home_wait_s=request.link.timeout_s)
    opened.append(backend)
    _check_from_vehicle_home(request, name, plan, backend, path)
    _upload_fence_and_rally(name, plan, backend, path)

    items, frames = mission_frames(plan.expanded_items())
    for f in frames:
        print(f"{name}: {f}", flush=True)
    if request.max_speed_mps is not None:
        items, changes = cap_speeds(items, request.max_speed_mps, _cruise_speed(backend))
        for c in changes:
            print(f"{name}: {c}", flush=True)
    try:
        sent = backend.mission.upload(items)  # read back and compared by the backend (a different flight raises)
    except BackendError:
        _say_upload_events(backend, name)  # the first read-back's difference, before the error itself
        raise
    _report_upload(backend, sent, name, repr(str(path)), request.link.connection)
    if request.start:
        backend.actions.arm()
        try:
            backend.mission.start()
        except BackendError:  # e.g. the vehicle holds another mission now: armed by us, not left armed on the ground
            backend.actions.disarm()
            raise
        print(f"{name}: armed and started the mission (ArduPilot AUTO / PX4 AUTO.MISSION)", flush=True)


def _check_from_vehicle_home(request: Upload, name: str, plan: Any, backend: Any, path: Path) -> None:
    """The altitude, distance and geofence bounds, measured from the vehicle's own home (the file's planned home
    only when the vehicle reports none). Raises MissionFileError when neither has one."""
    bounds = {"max_altitude": request.max_altitude_m, "max_distance": request.max_distance_m}
    link = request.link
    if backend.telemetry.home_received:  # as documented: from the vehicle's own home, whatever the file planned
        plan_to_flight(plan, backend.telemetry.home, **bounds)
    elif plan.home is None:  # the bounds are measured from a home, never from a default one
        raise MissionFileError(f"{str(path)!r}: the vehicle on {link.connection} reported no home position "
                               f"within {link.timeout_s:g} s and the file has none; nothing was uploaded (the "
                               "altitude and distance bounds are measured from it)")
    else:  # no GPS fix yet (bench, indoors)
        print(f"{name}: warning: the vehicle reported no home position within {link.timeout_s:g} s; the "
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


def _download(request: Download, name: str, opened: list) -> None:
    """``aerodaas mission download --out FILE`` (see :func:`download`): written only once complete."""
    out = Path(request.out)
    if out.suffix.lower() not in _MISSION_SUFFIXES:
        raise MissionFileError(f"{str(out)!r}: --out must end in {', '.join(_MISSION_SUFFIXES)} "
                               "(QGroundControl .plan or QGC WPL 110 waypoints)")
    backend = _mission_backend(request.link, name)
    opened.append(backend)
    plan = backend.mission.download().model_copy(update={
        "firmware_type": 3 if backend.link.autopilot == "ardupilot" else 12, "vehicle_type": 2})
    plan = _download_fence_and_rally(backend, plan, out, name)
    tmp = out.with_name(out.name + ".part")
    (save_plan if out.suffix.lower() == ".plan" else save_wpl)(plan, tmp)
    os.replace(tmp, out)  # never a half-written mission file
    print(f"{name}: {len(plan.items)} items from the {backend.link.autopilot} vehicle on {request.link.connection} "
          f"written to {str(out)!r}", flush=True)
