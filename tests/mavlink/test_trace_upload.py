"""The firmware tracer's mission upload (:mod:`aerodaas.emulators.mavlink.trace`, what the emulator-vs-firmware test
compares by): a transfer the vehicle gave up on (PX4's "Operation timeout", then MAV_MISSION_ERROR) is started
again from MISSION_COUNT, up to ``MISSION_UPLOAD_TRIES`` times, and the trace says how many it took."""
from __future__ import annotations

from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import common as M

from aerodaas.emulators.mavlink import trace


class _Vehicle:
    """Answers each MISSION_COUNT with the next of ``acks`` (a MAV_MISSION_RESULT) and refuses the mode change that
    follows an upload (so the trace stops right after it)."""

    def __init__(self, acks: list[int]) -> None:
        self.acks, self.counts = iter(acks), 0
        self.mission_acks: list[int] = []
        self.m = SimpleNamespace(mav=SimpleNamespace(mission_count_send=self._count))
        self.pos = SimpleNamespace(lat=130213000, lon=775671000)
        self.px4, self.alt, self.sysid, self.compid, self.texts, self.vt = True, 5.0, 1, 1, [], 0.0

    def _count(self, sysid: int, compid: int, n: int, mission_type: int) -> None:
        self.counts += 1
        self.mission_acks.append(next(self.acks))

    def wait(self, pred, vehicle_s: float) -> bool:
        return pred()

    def set_mode(self, name: str, tries: int = 1, why: str = "") -> int:
        return M.MAV_RESULT_DENIED


@pytest.mark.parametrize("acks,tries,final", [
    ([M.MAV_MISSION_ACCEPTED], 1, "MAV_MISSION_ACCEPTED"),
    ([M.MAV_MISSION_ERROR, M.MAV_MISSION_ACCEPTED], 2, "MAV_MISSION_ACCEPTED"),
    ([M.MAV_MISSION_ERROR] * 5, trace.MISSION_UPLOAD_TRIES, "MAV_MISSION_ERROR"),
])
def test_a_mission_upload_the_vehicle_gave_up_is_started_again(acks, tries, final):
    v, tr = _Vehicle(acks), {}
    assert trace._mission(v, tr, 60.0, 40.0, 3.0, 2.0) is None  # the refused mode change ends the trace there
    assert v.counts == tries and tr["mission_upload_tries"] == tries and tr["mission_ack"] == final
