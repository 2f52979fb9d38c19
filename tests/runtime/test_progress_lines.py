"""The live progress line of a flying drone (:func:`aerodaas.runtime.supervise.progress_lines`) says when a
simulated run's clock has waited for its recorder, from the drone's own status, while the run goes on."""
from __future__ import annotations

import pytest

pytestmark = pytest.mark.e2e


class _Method:
    """An actor method as the driver calls it: ``.remote()`` gives an ObjectRef of ``value``."""

    def __init__(self, value: dict) -> None:
        self.value = value

    def remote(self):
        import ray

        return ray.put(self.value)


class _Drone:
    def __init__(self, status: dict) -> None:
        self.status = _Method(status)


def _status(held_s: float) -> dict:
    return {"robot": "d1", "t": 12.5, "state": "NAVIGATING", "clock_held_s": held_s, "position": [1.0, 2.0, 10.0],
            "battery_pct": 90.0, "visited": 1, "preplanned_total": 4, "preplanned_reached": 1, "cameras": 1,
            "frames": 30, "frames_dropped_at_camera": 2, "outcome": None, "link_ok": True}


@pytest.mark.parametrize("held_s, said", [(0.0, None), (0.03, None), (7.25, "7.2"), (19.96, "20.0")])
def test_the_progress_line_says_how_long_the_clock_has_waited_for_the_recorder(ray_session, held_s, said):
    from aerodaas.runtime.supervise import progress_lines

    [line] = progress_lines({"d1": {"drone": _Drone(_status(held_s)), "analytics": {}}}, 0.0)
    assert line.startswith("[d1] t=  12.5s NAVIGATING")
    if said is None:
        assert "clock held" not in line
    else:
        assert line.endswith(f" clock held {said} s for the recorder")
