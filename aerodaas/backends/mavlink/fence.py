"""The autopilot's own geofence and rally points: the robot's ``safety.geofence`` uploaded to the vehicle over the
mission protocol with ``mission_type = MAV_MISSION_TYPE_FENCE`` (rally points: ``MAV_MISSION_TYPE_RALLY``), the
fence parameters set, and everything read back and compared before the robot may fly.

Our :class:`~aerodaas.navigation.safety.SafetyGate` is the first line: it refuses a command that would leave the
fence before it reaches the vehicle. The autopilot's fence is the second: the firmware checks its own position
against it every control cycle and takes its fence action on a breach, also when our process is gone.

Protocol (mavlink.io "Mission Protocol", mission types; common.xml ``MAV_CMD_NAV_FENCE_*``):

* a polygon of N vertices is N items ``MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION`` (5001) / ``_EXCLUSION`` (5002),
  each with ``param1`` = N and the vertex in ``x``/``y`` (degrees x 1e7), in order;
* a circle is one item ``MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION`` (5003) / ``_EXCLUSION`` (5004), ``param1`` = radius m;
* a rally point is ``MAV_CMD_NAV_RALLY_POINT`` (5100) in MAV_FRAME_GLOBAL_RELATIVE_ALT (``z`` metres above home).

ArduPilot stores them as ``AC_PolyFenceItem`` (``libraries/GCS_MAVLink/MissionItemProtocol_Fence.cpp``
``convert_MISSION_ITEM_INT_to_AC_PolyFenceItem``: frames GLOBAL / GLOBAL_INT / GLOBAL_RELATIVE_ALT(_INT) /
TERRAIN; ``get_item_as_mission_item`` returns ``param1`` = vertex count or radius, the same ``x``/``y`` and
``z`` = 0), so the read-back compares command, ``x``, ``y`` and ``param1``. PX4 keeps them in its dataman
(``src/modules/mavlink/mavlink_mission.cpp``; ``param1`` vertex count / radius, ``param2`` inclusion group).

Parameters (firmware units):

* ArduPilot (``libraries/AC_Fence/AC_Fence.h`` / ``AC_Fence.cpp``): ``FENCE_ENABLE`` 0/1; ``FENCE_TYPE`` bitmask
  1 = max altitude, 2 = circle around home (``FENCE_RADIUS`` m), 4 = polygon (the uploaded inclusion/exclusion
  polygons *and* circles), 8 = min altitude; ``FENCE_ALT_MAX`` metres above home; ``FENCE_ACTION`` 0 report only,
  1 RTL or land, 2 always land, 3 SmartRTL or RTL or land, 4 brake or land, 5 SmartRTL or land; ``FENCE_OPTIONS``
  bit 1 (value 2, ``INCLUSION_UNION``): several inclusion zones allow their union, as our gate does, instead of
  their intersection (set, keeping the other bits, whenever two or more inclusion zones go up;
  :func:`aerodaas.navigation.geofence.autopilot_disagreement` and the geofence module docstring).
* PX4 (``src/modules/navigator/geofence_params.c``): ``GF_ACTION`` (INT32) 0 none, 1 warning, 2 hold mode,
  3 return mode, 4 terminate, 5 land mode; ``GF_MAX_VER_DIST`` / ``GF_MAX_HOR_DIST`` metres from home
  (0 disables). PX4 intersects several inclusion zones and has no parameter to change that: such a fence is refused
  for a PX4 vehicle before anything is uploaded. PX4 refuses a PARAM_SET whose type differs from the parameter's ("param types mismatch",
  ``src/modules/mavlink/mavlink_parameters.cpp``): INT32 parameters go bytewise in the float field
  (:meth:`~aerodaas.backends.mavlink.params.ParameterProtocol.set` ``integer=True``).

The firmware's own return must stay inside the altitude fence. ArduCopter lowers its RTL return target to the
fence's safe maximum itself (``ArduCopter/mode_rtl.cpp`` ``compute_return_target``: ``fence.get_safe_alt_max()``
when ``FENCE_TYPE`` has the max-altitude bit). PX4 does not: its Return mode climbs to ``RTL_RETURN_ALT``
(multicopter default 30 m, ``ROMFS/px4fmu_common/init.d/rc.mc_defaults``; 60 m in ``rtl_params.yaml``), near home
less (``RTL_CONE_ANG``) but not below ``RTL_DESCEND_ALT`` (10 m), and its geofence counts a breach of
``GF_MAX_VER_DIST`` during the return (observed on PX4 SITL with a 30 m fence: "RTL: start return at ... (30 m
above destination)", then "Geofence: exceeding maximum altitude above Home"). So with the altitude fence on, the
backend lowers both to
:func:`px4_return_altitude_ceiling` when they are above it (never raises them) and restores them with the fence.
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable, Iterable, Protocol

from aerodaas.backends.base import BackendError, CommandRefused
from aerodaas.backends.mavlink._common import M, _f32
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.params import ParameterProtocol
from aerodaas.backends.mavlink.transfer import FENCE, RALLY, Wire
from aerodaas.navigation.geofence import GeofenceConfig, autopilot_disagreement


#: ArduPilot FENCE_TYPE bits (AC_Fence.h AC_FENCE_TYPE_*)
AP_FENCE_ALT_MAX, AP_FENCE_CIRCLE, AP_FENCE_POLYGON = 1, 2, 4
#: our ``mavlink.fence.action`` -> (ArduPilot FENCE_ACTION, PX4 GF_ACTION)
FENCE_ACTIONS = {"report": (0, 1), "rtl": (1, 3), "land": (2, 5), "hold": (4, 2)}

#: ArduPilot FENCE_OPTIONS bit (AC_Fence.h ``OPTIONS::INCLUSION_UNION``): inclusion zones allow their union
AP_FENCE_INCLUSION_UNION = 2
#: vehicle seconds to let the firmware act on an uploaded fence before it is read back (ArduPilot's loader runs at
#: 10 Hz: ``AC_PolyFence_loader::update``, see :meth:`AutopilotFence._settled_fence`)
FENCE_SETTLE_S = 1.0
#: the fence parameters of integer type (PX4 takes GF_ACTION only as INT32; ArduPilot converts REAL32 itself)
_INT_PARAMS = {"GF_ACTION", "FENCE_ENABLE", "FENCE_TYPE", "FENCE_ACTION", "FENCE_OPTIONS"}
#: PX4's return altitudes (metres above home), lowered under the altitude fence; PX4 keeps RTL_DESCEND_ALT >= 2 m
PX4_RETURN_ALTITUDES = ("RTL_RETURN_ALT", "RTL_DESCEND_ALT")
PX4_MIN_DESCEND_ALT_M = 2.0


def px4_return_altitude_ceiling(max_altitude_m: float, field: str = "safety.max_altitude") -> float:
    """The highest PX4 return altitude (metres above home) under an altitude fence at ``max_altitude_m``: 10 % of
    the fence height below it, at least 2 m below (PX4 overshoots a climb target by a little: its altitude fence
    must not count the return as a breach). Raises BackendError when that leaves less than PX4's smallest descend
    altitude (2 m, ``RTL_DESCEND_ALT``'s minimum), naming ``field``, the setting the altitude came from."""
    ceiling = max_altitude_m - max(2.0, 0.1 * max_altitude_m)
    if ceiling < PX4_MIN_DESCEND_ALT_M:
        raise BackendError(f"{field} {max_altitude_m:g} m: PX4's Return mode needs at least "
                           f"{PX4_MIN_DESCEND_ALT_M + 2.0:g} m under the altitude fence (RTL_DESCEND_ALT >= "
                           f"{PX4_MIN_DESCEND_ALT_M:g} m, 2 m margin); raise {field} or set "
                           f"mavlink.fence.max_altitude false")
    return ceiling


def fence_items(fence: GeofenceConfig) -> list[Wire]:
    """The fence items for ``fence``: each polygon as its vertices (5001/5002, ``param1`` = vertex count), then
    each circle (5003/5004, ``param1`` = radius m, float32); latitude/longitude as int degrees x 1e7,
    MAV_FRAME_GLOBAL, ``z`` 0 (fences are 2-D; the altitude fence is a parameter)."""
    out: list[Wire] = []
    for poly in fence.polygons:
        cmd = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION if poly.inclusion else \
            M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
        for lat, lon in poly.points:
            out.append((M.MAV_FRAME_GLOBAL, cmd, float(len(poly.points)), 0.0, 0.0, 0.0,
                        int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0))
    for c in fence.circles:
        cmd = M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION if c.inclusion else M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
        out.append((M.MAV_FRAME_GLOBAL, cmd, _f32(c.radius), 0.0, 0.0, 0.0,
                    int(round(c.center[0] * 1e7)), int(round(c.center[1] * 1e7)), 0.0))
    return out


def rally_items(points: Iterable[tuple[float, float, float]]) -> list[Wire]:
    """Rally points ``(latitude, longitude, altitude m above home)`` as MAV_CMD_NAV_RALLY_POINT items
    (MAV_FRAME_GLOBAL_RELATIVE_ALT, as QGroundControl's ``rallyPoints`` mean them)."""
    return [(M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_NAV_RALLY_POINT, 0.0, 0.0, 0.0, 0.0,
             int(round(lat * 1e7)), int(round(lon * 1e7)), _f32(alt)) for lat, lon, alt in points]


def fence_from_items(wire: list[Wire]) -> GeofenceConfig:
    """The :class:`GeofenceConfig` a vehicle's fence items describe (the inverse of :func:`fence_items`): runs of
    ``param1`` consecutive vertex items of one command make a polygon, each circle item a circle; a return point
    (5000) is skipped. Raises ValueError for a polygon whose vertex count does not match its run."""
    polygons, circles, k = [], [], 0
    poly_cmds = (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
    while k < len(wire):
        cmd, p1 = wire[k][1], wire[k][2] or 0.0
        if cmd in poly_cmds:
            n = int(round(p1))
            run = wire[k:k + n]
            if n < 3 or len(run) < n or any(w[1] != cmd for w in run):
                raise ValueError(f"fence item {k}: a polygon of {n} vertices, but the items that follow do not hold them")
            polygons.append({"points": [(w[6] / 1e7, w[7] / 1e7) for w in run],
                             "inclusion": cmd == M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION})
            k += n
            continue
        if cmd in (M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION):
            circles.append({"center": (wire[k][6] / 1e7, wire[k][7] / 1e7), "radius": float(p1),
                            "inclusion": cmd == M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION})
        k += 1
    return GeofenceConfig.model_validate({"polygons": polygons, "circles": circles}, strict=False)


def compare_items(sent: list[Wire], got: list[Wire], compare_z: bool) -> str | None:
    """Why the items read back differ from those sent (None: they match): count, then per item command, ``x``,
    ``y`` (exact ints), ``param1`` (float32 tolerance) and, with ``compare_z``, ``z`` (ArduPilot returns fence
    items with ``z`` 0 and its own frame, so neither is compared for fences)."""
    if len(sent) != len(got):
        return f"{len(got)} items read back, {len(sent)} sent"
    for k, (a, b) in enumerate(zip(sent, got)):
        if a[1] != b[1]:
            return f"item {k}: command {b[1]} read back, {a[1]} sent"
        if (a[6], a[7]) != (b[6], b[7]):
            return f"item {k}: position ({b[6] / 1e7:.7f}, {b[7] / 1e7:.7f}) read back, " \
                   f"({a[6] / 1e7:.7f}, {a[7] / 1e7:.7f}) sent"
        if not math.isclose(a[2] or 0.0, b[2] or 0.0, rel_tol=1e-6, abs_tol=1e-3):
            return f"item {k}: param1 {b[2]:g} read back, {a[2]:g} sent"
        if compare_z and not math.isclose(a[8] or 0.0, b[8] or 0.0, rel_tol=1e-6, abs_tol=1e-2):
            return f"item {k}: z {b[8]:g} read back, {a[8]:g} sent"
    return None


class ItemTransfer(Protocol):
    """The mission protocol's typed transfers (:class:`~aerodaas.backends.mavlink.transfer.MissionTransfer`):
    items of a MAV_MISSION_TYPE to and from the vehicle, as wire tuples."""

    def upload_items(self, mission_type: int, wire: list[Wire]) -> None: ...

    def download_items(self, mission_type: int) -> list[Wire]: ...


class AutopilotFence:
    """The vehicle's own geofence and rally points, a concern object of
    :class:`~aerodaas.backends.mavlink.MavlinkBackend` (see the module docstring for the firmware's rules).

    It is given its collaborators: ``params`` (the backend's
    :class:`~aerodaas.backends.mavlink.params.ParameterProtocol`), ``transfers`` (:class:`ItemTransfer`), ``link``
    (the autopilot, ``"ardupilot"`` / ``"px4"`` once connected; the link check), ``clock`` (vehicle seconds) and
    ``event`` (records a backend event). ``settings``: ``mavlink.fence``
    (:class:`~aerodaas.config.backends.MavlinkFenceConfig`); ``limits`` and ``safety``: the robot's (the altitude
    ceiling, the default fence).

    State: ``applied`` (what :meth:`apply` verified, or None) and the vehicle's fence items and fence parameters
    before :meth:`apply` changed them (for :meth:`restore`; :attr:`has_saved`)."""

    def __init__(self, robot_id: str, settings: Any, limits: Any, safety: Any, *, params: ParameterProtocol,
                 transfers: ItemTransfer, link: MavlinkLink, clock: VehicleClock, event: Callable[..., None]) -> None:
        self.robot_id, self._settings, self.limits, self.safety = robot_id, settings, limits, safety
        self._params, self._transfers, self._link, self._clock, self._event = params, transfers, link, clock, event
        self._saved: dict[str, Any] | None = None
        #: what :meth:`apply` verified (``{"items", "params", "before"}``), or None
        self.applied: dict[str, Any] | None = None

    @property
    def has_saved(self) -> bool:
        """The vehicle's fence before :meth:`apply` is kept, to be put back by :meth:`restore`."""
        return bool(self._saved)

    def fence_parameters(self, fence: GeofenceConfig, have: dict[str, float] | None = None) \
            -> dict[str, tuple[float, bool]]:
        """The fence parameters for ``fence`` and ``mavlink.fence`` on this autopilot: name -> (value in the
        firmware's unit, INT32 on PX4). See the module docstring for their meaning. ``have``: the vehicle's current
        values; PX4's return altitudes (:data:`PX4_RETURN_ALTITUDES`) are ceilings, kept when already below
        :func:`px4_return_altitude_ceiling` (without ``have`` the ceiling itself). Raises BackendError (a fence
        too low for PX4's return)."""
        fc = self._settings
        # the safety gate's ceiling: the lower of the two settings (safety.py SafetyGate.max_alt)
        max_alt = min(float(self.limits.max_altitude), float(self.safety.max_altitude or math.inf))
        ap_action, px4_action = FENCE_ACTIONS[fc.action]
        if self._link.autopilot == "ardupilot":
            bits = (AP_FENCE_POLYGON if not fence.is_empty else 0) | (AP_FENCE_ALT_MAX if fc.max_altitude else 0) \
                | (AP_FENCE_CIRCLE if fc.home_radius_m else 0)
            out = {"FENCE_TYPE": (float(bits), True), "FENCE_ACTION": (float(ap_action), True)}
            if fc.max_altitude:
                out["FENCE_ALT_MAX"] = (max_alt, False)
            if fc.home_radius_m:
                out["FENCE_RADIUS"] = (float(fc.home_radius_m), False)
            if fence.inclusion_count > 1:  # the union of the inclusion zones, as our gate (the other bits kept)
                options = int((have or {}).get("FENCE_OPTIONS", 0.0)) | AP_FENCE_INCLUSION_UNION
                out["FENCE_OPTIONS"] = (float(options), True)
            out["FENCE_ENABLE"] = (1.0, True)  # last: the fence is complete when it is switched on
            return out
        out = {"GF_ACTION": (float(px4_action), True)}
        if fc.max_altitude:
            out["GF_MAX_VER_DIST"] = (max_alt, False)
            field = "safety.max_altitude" if self.safety.max_altitude else "limits.max_altitude"
            ceiling = px4_return_altitude_ceiling(max_alt, field)
            for name in PX4_RETURN_ALTITUDES:
                out[name] = (min(ceiling, (have or {}).get(name, ceiling)), False)
        if fc.home_radius_m:
            out["GF_MAX_HOR_DIST"] = (float(fc.home_radius_m), False)
        return out

    def apply(self, fence: GeofenceConfig | None = None) -> dict[str, Any]:
        """Make ``fence`` (default: the robot's ``safety.geofence``) the vehicle's own fence: keep the vehicle's
        current fence items and parameters (for :meth:`restore`), upload the items
        (``MAV_MISSION_TYPE_FENCE``), set the parameters (:meth:`fence_parameters`), then read both back
        (MISSION_REQUEST_LIST of the fence type, PARAM_REQUEST_READ) and compare. Returns ``{"items": n,
        "params": {name: value read back}, "before": {name: the vehicle's value before}}`` and records a
        ``fence_uploaded`` event. Raises BackendError naming
        what differs ("refusing to fly"), a fence the autopilot would read differently from our gate (before anything
        is sent: :func:`~aerodaas.navigation.geofence.autopilot_disagreement`; an ArduPilot without ``FENCE_OPTIONS``
        for several inclusion zones) or a fence too low for PX4's Return (:func:`px4_return_altitude_ceiling`),
        CommandRefused when the vehicle rejects an item or lacks a fence
        parameter (a firmware built without fences), LinkLost."""
        fence = self.safety.geofence if fence is None else fence
        wire = fence_items(fence)
        where = f"robot {self.robot_id!r}: autopilot geofence"
        why = autopilot_disagreement(fence, self._link.autopilot)
        if why is not None:
            raise BackendError(f"{where}: {why}; refusing to fly")
        try:
            want = self.fence_parameters(fence)
        except BackendError as e:
            raise BackendError(f"{where}: {e}") from None
        have = self._params.read(list(want))
        missing = sorted(set(want) - set(have))
        if "FENCE_OPTIONS" in missing:
            raise BackendError(f"{where}: the vehicle has no FENCE_OPTIONS parameter, so it requires a position "
                               f"inside every one of the fence's {fence.inclusion_count} inclusion zones where "
                               f"AeroDaaS accepts one inside any (ArduPilot without AC_Fence's INCLUSION_UNION "
                               f"option); refusing to fly (draw the allowed area as one inclusion polygon, or set "
                               f"mavlink.fence.upload false to fly on our gate alone)")
        if missing:
            raise BackendError(f"{where}: the {self._link.autopilot} vehicle has no parameter {', '.join(missing)} "
                               f"(firmware without a geofence?); refusing to fly (set mavlink.fence.upload false "
                               f"to fly on our gate alone, or mavlink.fence.max_altitude false without the altitude "
                               f"fence and its return altitudes)")
        want = self.fence_parameters(fence, have)
        if not self._saved:
            try:
                before = self._transfers.download_items(FENCE)
            except (BackendError, CommandRefused) as e:
                before = None
                self._event("fence_download_failed", error=str(e))
            self._saved = {"items": before, "params": dict(have)}
        self._transfers.upload_items(FENCE, wire)
        for name, (value, integer) in want.items():
            if not math.isclose(have[name], value, rel_tol=1e-6, abs_tol=1e-4):
                self._params.set(name, value, integer=integer)
        got_items = self._settled_fence(wire)
        why = compare_items(wire, got_items, compare_z=False)
        if why is not None:
            raise BackendError(f"{where}: the fence read back differs from the one uploaded ({why}); refusing to fly")
        got = self._params.read(list(want))
        for name, (value, _int) in want.items():
            if name not in got:
                raise BackendError(f"{where}: {name} could not be read back; refusing to fly")
            if not math.isclose(got[name], value, rel_tol=1e-5, abs_tol=1e-3):
                raise BackendError(f"{where}: {name} set to {value:g}, the vehicle reports {got[name]:g}; "
                                   f"refusing to fly")
        self.applied = {"items": len(wire), "params": got, "before": {n: have[n] for n in want}}
        self._event("fence_uploaded", items=len(wire), polygons=len(fence.polygons), circles=len(fence.circles),
                    action=self._settings.action, **{k: round(v, 3) for k, v in got.items()})
        return self.applied

    def _settled_fence(self, wire: list[Wire]) -> list[Wire]:
        """The vehicle's fence items once the firmware has acted on the upload of ``wire``
        (:data:`FENCE_SETTLE_S` vehicle seconds later, at most 5 wall seconds). ArduPilot wipes a fence it has just
        stored when that fence has fewer than 3 "vertices" (circles count one each, polygons their vertices) and the
        one before had more: ``write_fence`` sets ``FENCE_TOTAL`` to 0 for such a fence (``new_total``) and, within
        0.1 s, ``update`` takes the change to 0 for an old ground station clearing its fence and formats the
        storage (``AC_PolyFence_loader.cpp``, ``AC_POLYFENCE_FENCE_POINT_PROTOCOL_SUPPORT``). Seen on ArduCopter SITL
        (4.7.0-dev): two inclusion circles after a polygon and a circle read back right after the upload, and 0 items
        0.1 s later, for the whole flight. So the read-back waits, and a fence found wiped is uploaded once more
        (``FENCE_TOTAL`` is 0 by then and stays so: no second wipe), recorded as ``fence_rewritten``."""
        got = self._after_vehicle_s(FENCE_SETTLE_S, lambda: self._transfers.download_items(FENCE))
        if wire and not got:
            self._event("fence_rewritten", items=len(wire), reason="the vehicle cleared the fence after storing it "
                        "(ArduPilot FENCE_TOTAL bookkeeping)")
            self._transfers.upload_items(FENCE, wire)
            got = self._after_vehicle_s(FENCE_SETTLE_S, lambda: self._transfers.download_items(FENCE))
        return got

    def _after_vehicle_s(self, seconds: float, then):
        """``then()`` once the vehicle's clock has run ``seconds`` further (at most 5 wall seconds: a vehicle whose
        clock does not advance is not waited for longer)."""
        t0, end = self._clock.t, time.monotonic() + 5.0
        while self._clock.t - t0 < seconds and time.monotonic() < end:
            self._link.check_link("fence read-back")
            time.sleep(0.02)
        return then()

    def upload_rally(self, points: list[tuple[float, float, float]]) -> int:
        """Upload rally points ``(lat, lon, alt m above home)`` (``MAV_MISSION_TYPE_RALLY``) and read them back.
        Returns how many. Raises BackendError on a mismatch, CommandRefused, LinkLost."""
        wire = rally_items(points)
        self._transfers.upload_items(RALLY, wire)
        why = compare_items(wire, self._transfers.download_items(RALLY), compare_z=True)
        if why is not None:
            raise BackendError(f"robot {self.robot_id!r}: rally points read back differ from those uploaded ({why})")
        self._event("rally_uploaded", items=len(wire))
        return len(wire)

    def restore(self) -> bool:
        """Put back the fence items and fence parameters the vehicle had before :meth:`apply` (best
        effort, ``fence_restored`` / ``fence_restore_failed`` events). Returns True when all was put back."""
        saved = self._saved
        if not saved:
            return True
        ok = True
        try:
            if saved["items"] is not None:
                self._transfers.upload_items(FENCE, saved["items"])
            for name, value in saved["params"].items():
                self._params.set(name, value, integer=name in _INT_PARAMS)
        except Exception as e:  # noqa: BLE001 - closing: report and go on
            ok = False
            self._event("fence_restore_failed", error=str(e))
        if ok:
            self._saved = None
            self._event("fence_restored", items=len(saved["items"] or []), **saved["params"])
        return ok

