"""DJI Tello backend: Tello SDK 2.0 text commands over UDP, state packets, and the H.264 video stream.

Protocol (Ryze Tech, *Tello SDK 2.0 User Guide*, V1.0 2018-11):

* **Commands** are UTF-8 text datagrams to the Tello's UDP port 8889; the reply comes back to the sending
  socket: ``ok``, ``error`` (optionally with a reason, e.g. ``error Motor stop``), ``out of range`` or, for read
  commands (``battery?``), the value. ``command`` enters SDK mode and must come first. ``takeoff``, ``land``,
  ``go x y z speed``, ``up x`` ... are answered only when the Tello has *finished* the manoeuvre. ``stop`` (hover)
  works at any time. ``rc a b c d`` sets the four virtual sticks (a: left/right, b: forward/backward, c: up/down,
  d: yaw, each -100..100); Tellos do not answer it in practice, so it is sent without waiting.
  ``go x y z speed``: body frame, x forward, y left, z up, in cm (-500..500, not all three within -20..20 at once),
  speed 10..100 cm/s. ``up``/``down x``: 20..500 cm.
* **State**: after ``command``, the Tello sends ``pitch:%d;roll:%d;yaw:%d;vgx:%d;vgy:%d;vgz:%d;templ:%d;temph:%d;
  tof:%d;h:%d;bat:%d;baro:%.2f;time:%d;agx:%.2f;agy:%.2f;agz:%.2f;\\r\\n`` to UDP 8890 of the host at about
  10 Hz (the Tello EDU prefixes mission-pad fields ``mid;x;y;z;mpry``, which we ignore). pitch/roll/yaw in degrees
  (yaw clockwise-positive, -180..180, relative to the heading at power-on: the Tello has no compass), ``h`` height
  above the take-off point in cm, ``bat`` percent, ``tof`` ToF distance to the ground in cm, ``baro`` metres,
  ``time`` motor-on seconds, ``ag*`` acceleration in 0.001 g.
* **Video**: after ``streamon``, raw H.264 (Annex B) to UDP 11111 of the host. Each encoded frame is cut into
  datagrams of 1460 bytes, the last one shorter; DJI's own ``Tello-Python/Tello_Video`` sample reassembles a frame
  by that rule and so do we.
* **Safety**: the Tello lands by itself when it receives no command for 15 s after finishing the last one; we send
  ``rc`` with the current sticks every ``keepalive_s`` seconds when no manoeuvre is in progress.

What the guide does not say, and what we assume (each a :class:`~aerodaas.config.TelloConfig` field where it can
differ): ``vgx/vgy/vgz`` are in **dm/s** (measured by users: damiafuentes/DJITelloPy issues/96 on GitHub), in a NED-like frame whose x
points along the heading of yaw 0 (``velocity_frame="yaw_zero"``, the ``north_speed/east_speed`` naming of the
Tello's low-level flight data) — ``"body"`` reads them as forward/right instead; ``vgz`` is positive down.

Odometry: the Tello has no GPS. x/y are dead-reckoned by integrating the state velocities (trapezoid rule over the
packets' arrival times), z is ``h``; yaw is converted to ENU with the mission-start reference
``TelloConfig.initial_heading_deg`` (the heading the Tello faces when :meth:`TelloBackend.connect` runs). The
geodetic fix is home + ENU, so it drifts like the dead reckoning does.

Modules, one concern each, the way the MAVLink backend is split (concern objects composed by :class:`~.backend.TelloBackend`,
each given its collaborators): :mod:`.protocol` (the SDK's state packets and ``go`` command), :mod:`.video` (the H.264
stream), :mod:`.link` (sockets, receiver threads, keep-alive, the command channel), :mod:`.control` (the motion
worker and the flight commands) and :mod:`.backend` (the class, its state and odometry).
"""
from aerodaas.backends.tello.backend import TelloBackend

__all__ = ["TelloBackend"]
