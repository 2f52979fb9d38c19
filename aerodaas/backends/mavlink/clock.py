"""The vehicle clock: the run's time from the autopilot's ``time_boot_ms`` (MAVLink common.xml: milliseconds since
the autopilot booted, in SYSTEM_TIME, ATTITUDE, GLOBAL_POSITION_INT, LOCAL_POSITION_NED...), its rate against wall
time (an emulator or SITL may run K times faster or slower than real time), a reboot of the autopilot, and the
heartbeat watch's notion of a *missed* HEARTBEAT measured on that clock. A concern object of
:class:`~aerodaas.backends.mavlink.MavlinkBackend` (:class:`VehicleClock`)."""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any, Protocol

from aerodaas.backends.mavlink._common import _CLOCK_STALE_S


class LinkHealth(Protocol):
    """What the clock reads of the link that feeds it (link.py :class:`~aerodaas.backends.mavlink.link.MavlinkLink`,
    which registers itself with :meth:`VehicleClock.watch` when it is made)."""

    @property
    def link_ok(self) -> bool:
        """HEARTBEATs keep coming (the heartbeat watch)."""
        ...

    def live_since(self, now: float) -> float:
        """Given the wall time ``now`` (time.monotonic()), the wall time since which the link's socket has been
        read empty (shared_link.py ``LinkPort.live_since``)."""
        ...


class VehicleClock:
    """The vehicle's time (seconds since :meth:`start`, the backend's :attr:`t`): the autopilot's ``time_boot_ms``
    once one arrives, wall time until then; while nothing timestamped arrives (the link is down, or not yet declared
    down) it runs on from the last sample at the measured vehicle/wall rate :attr:`ratio`, and never goes back.

    It knows only what it is given: ``settings`` (:class:`~aerodaas.config.MavlinkConfig`: its
    ``heartbeat_timeout_s``, wall seconds, read when needed), ``lock`` (the backend's lock; the I/O thread feeds
    samples under it) and the link it :meth:`watch` es (:class:`LinkHealth`; none yet: the link counts as down).
    It records no events itself: :meth:`on_boot_ms` returns the ones its caller records."""

    def __init__(self, settings: Any, *, lock: threading.RLock) -> None:
        self._settings, self._lock = settings, lock
        self._link: LinkHealth | None = None
        self._wall0 = time.monotonic()
        self._boot_ref: tuple[int, float] | None = None  # (time_boot_ms, vehicle seconds at that sample)
        self._boot_last = 0
        self._boot_wall = 0.0  # wall (monotonic) time of the latest time_boot_ms sample
        self._boot_live = 0.0  # that sample was received after the link's socket was empty at this time
        self._t_connect = 0.0
        self._ratio = 1.0
        self._clock_samples: deque[tuple[float, int]] = deque()
        self._t_max = 0.0
        self._reanchor = False  # the link was lost: the next time_boot_ms may re-anchor the clock

    @property
    def boot_ms(self) -> int:
        """The vehicle's latest ``time_boot_ms`` (0 before any)."""
        return self._boot_last

    @property
    def live_since(self) -> float:
        """The latest ``time_boot_ms`` sample was received after the link's socket was empty at this wall time."""
        return self._boot_live

    @property
    def ratio(self) -> float:
        """Vehicle seconds per wall second, estimated from ``time_boot_ms`` (1 for a real vehicle)."""
        return self._ratio

    @property
    def t_connect(self) -> float:
        """The raw vehicle clock (s) at :meth:`start`: the run's zero."""
        return self._t_connect

    def start(self) -> None:
        """The connection's zero: :attr:`t` counts from now. Caller holds ``lock``."""
        self._t_connect = self.raw_t()
        self._t_max = 0.0

    def watch(self, link: LinkHealth) -> None:
        """Take ``link``'s HEARTBEAT watch and socket state from now on (the link calls this when it is made)."""
        self._link = link

    def link_lost(self) -> None:
        """The link was declared lost: the next ``time_boot_ms`` may re-anchor the clock (:meth:`on_boot_ms`)."""
        self._reanchor = True

    def on_boot_ms(self, ms: int) -> tuple[str, ...]:
        """A ``time_boot_ms`` ``ms`` received. A first sample, or one more than 5 s before the latest (the autopilot
        rebooted: ``vehicle_rebooted``), anchors the clock; after a link loss a vehicle clock that stood still while
        ours ran on is re-anchored where :attr:`t` got to (``vehicle_clock_resumed``). Returns the names of those
        events, for the caller to record now (their time is :attr:`t` after this sample). Caller holds ``lock``."""
        now = time.monotonic()
        events: tuple[str, ...] = ()
        if self._boot_ref is None or ms + 5000 < self._boot_last:  # first sample, or the autopilot rebooted
            if self._boot_ref is not None:
                events += ("vehicle_rebooted",)
            self._boot_ref = (ms, self.raw_t())
            self._clock_samples.clear()
        self._boot_last = max(ms, self._boot_last) if self._boot_ref[0] <= ms else ms
        resumed = False
        if self._reanchor and self.raw_t() - self._t_connect < self._t_max - 1.0:
            # after a link loss, the vehicle's clock stood still while ours ran on (the autopilot was stopped):
            # go on from where :attr:`t` got to, so the recording has no step back (a short stall of our own
            # process needs nothing: the vehicle's clock ran on meanwhile)
            self._boot_ref = (ms, self._t_max + self._t_connect)
            self._boot_last = ms
            self._clock_samples.clear()
            resumed = True
        self._reanchor = False
        self._boot_wall = now
        # received after then (shared_link.py LinkPort)
        self._boot_live = self._link.live_since(now) if self._link is not None else now
        if resumed:  # recorded after this sample: the event reads :attr:`t`, which before it still counted the
            # silence on top of the re-anchored clock (t jumped by the whole stop x the clock ratio: 28 s at 5x for 6 s)
            events += ("vehicle_clock_resumed",)
        # vehicle seconds per wall second over the last few seconds (an emulator may run K times faster)
        samples = self._clock_samples
        samples.append((now, ms))
        while len(samples) > 2 and now - samples[0][0] > 5.0:
            samples.popleft()
        span = now - samples[0][0]
        if span >= 0.2:
            r = (ms - samples[0][1]) / 1000.0 / span
            if 0.05 < r < 200:
                self._ratio = r
        return events

    def sample_time(self, ms: int) -> float:
        """``time_boot_ms`` ``ms`` of a sample on the raw vehicle clock (s): its own time when the clock's anchor is
        not after it, else the clock's latest reading."""
        if self._boot_ref is not None and self._boot_ref[0] <= ms:
            return self._boot_ref[1] + (ms - self._boot_ref[0]) / 1000.0
        return self.raw_t()

    def raw_t(self) -> float:
        """The raw vehicle clock (s): the latest ``time_boot_ms`` on its anchor, wall time before any."""
        if self._boot_ref is None:
            return time.monotonic() - self._wall0
        return self._boot_ref[1] + (self._boot_last - self._boot_ref[0]) / 1000.0

    @property
    def t(self) -> float:
        """Vehicle seconds since :meth:`start`, extrapolated at :attr:`ratio` while nothing timestamped arrives,
        never decreasing."""
        with self._lock:
            t = self.raw_t() - self._t_connect
            silent = time.monotonic() - self._boot_wall
            link_ok = self._link is not None and self._link.link_ok
            if self._boot_ref is not None and (not link_ok or silent > _CLOCK_STALE_S):
                # nothing timestamped arrives (the link is down, or not yet declared down): the vehicle's clock
                # goes on at its last rate, so odometry and control ticks go on before link loss is declared
                t += silent * self._ratio
            t = max(t, self._t_max)
            self._t_max = t
            return t

    def heartbeats_missed(self, now: float, hb_boot_ms: int) -> bool:
        """No HEARTBEAT for ``heartbeat_timeout_s`` wall seconds (checked by the caller; the latest came at the
        vehicle's ``hb_boot_ms``): is that a lost link? The heartbeat protocol counts *expected* heartbeats that did
        not come (mavlink.io/en/services/heartbeat.html), and an autopilot sends one per second of its own clock
        (PX4: the constant-rate 1 Hz HEARTBEAT stream, src/modules/mavlink/mavlink_main.cpp; ArduPilot: its 1 Hz
        scheduler task). A simulated autopilot that runs slower than real time (PX4 SIH lock-step, three of them
        on a loaded 2-core machine: heartbeats 3.0-3.7 s of wall time apart while position reports went on) has
        missed none until its clock, as its timestamped messages show it, has run ``heartbeat_timeout_s`` past its
        last HEARTBEAT. Lost when those messages stopped too (a stopped process, a cut link) or the vehicle's clock
        ran on that long without a heartbeat. Caller holds ``lock``."""
        if self._boot_ref is None or now - self._boot_wall > self._settings.heartbeat_timeout_s:
            return True
        return (self._boot_last - hb_boot_ms) / 1000.0 > self._settings.heartbeat_timeout_s

    def heartbeat_due(self, started: float, boot0: int, wait_s: float) -> bool:
        """Has a HEARTBEAT been due since ``started`` (monotonic), when the vehicle's time_boot_ms was ``boot0``:
        ``wait_s`` wall seconds passed, and the vehicle's own clock ran min(``wait_s``, ``heartbeat_timeout_s``)
        too (an autopilot sends HEARTBEAT at 1 Hz of its clock, which a simulator may run slower than real time;
        see :meth:`heartbeats_missed`; a clock that stopped ends the wait through link loss)."""
        now = time.monotonic()
        if now - started < wait_s:
            return False
        if self._boot_ref is None or now - self._boot_wall > self._settings.heartbeat_timeout_s:
            return True  # no clock of the vehicle's to go by: wall time alone
        return (self._boot_last - boot0) / 1000.0 >= min(wait_s, self._settings.heartbeat_timeout_s)

    def boot_ms_out(self) -> int:
        """Our own ``time_boot_ms`` for the messages we send (wall milliseconds since this clock was made, 32 bits)."""
        return int((time.monotonic() - self._wall0) * 1000) & 0xFFFFFFFF
