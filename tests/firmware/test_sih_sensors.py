"""A single-vehicle scenario whose PX4 SIH's simulated sensors stopped is flown once more, the first attempt kept
aside (tests/firmware/sih_sensors.py); any other failure, ArduCopter and a rebooted vehicle are not."""
from __future__ import annotations

from pathlib import Path

import pytest

from tests.firmware.sih_sensors import SIH_SENSORS_STOPPED, fly_scenario


class FakeRun:
    """Stands in for ``run_in_namespace``: attempt k writes ``rc0`` = ``rcs[k]``, its firmware log (with
    :data:`SIH_SENSORS_STOPPED` where ``stopped[k]``) and a recording beside the run folder."""

    def __init__(self, rcs: list[int], stopped: list[bool], after_disarm: bool = False) -> None:
        self.rcs, self.stopped, self.after_disarm, self.calls = rcs, stopped, after_disarm, 0

    def __call__(self, autopilot: str, run_dir: Path, steps: list[str], *, with_firmware: bool) -> None:
        k = self.calls
        self.calls += 1
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / "rc0").write_text(f"{self.rcs[k]}\n")
        stop = f"WARN  [health_and_arming_checks] {SIH_SENSORS_STOPPED}\n" if self.stopped[k] else ""
        disarm = "INFO  [commander] Disarmed by external command\n"
        (run_dir / "fw0.log").write_text("INFO  [commander] Armed by external command\n"
                                          + (disarm + stop if self.after_disarm else stop + disarm))
        (run_dir.parent / "guided.mcap").write_text(f"attempt {k}")


def test_a_px4_run_that_failed_with_its_sensors_stopped_is_flown_once_more_the_first_kept_aside(tmp_path):
    (tmp_path / "guided.json").write_text("{}")                            # written before the scenario: stays
    run = FakeRun(rcs=[1, 0], stopped=[True, False])
    with pytest.warns(UserWarning, match="simulated sensors stopped, flown once more"):
        assert fly_scenario(run, "px4", tmp_path / "guided", ["step"], with_firmware=True, fresh=True)
    assert run.calls == 2
    aside = tmp_path / "guided_sih_sensors_stopped"
    assert (aside / "guided" / "rc0").read_text() == "1\n" and (aside / "guided.mcap").read_text() == "attempt 0"
    assert (tmp_path / "guided" / "rc0").read_text() == "0\n" and (tmp_path / "guided.mcap").read_text() == "attempt 1"
    assert (tmp_path / "guided.json").exists() and not (aside / "guided.json").exists()


def test_a_second_stop_is_not_flown_a_third_time(tmp_path):
    run = FakeRun(rcs=[1, 1], stopped=[True, True])
    with pytest.warns(UserWarning):
        assert fly_scenario(run, "px4", tmp_path / "auto", ["step"], with_firmware=True, fresh=True)
    assert run.calls == 2 and (tmp_path / "auto" / "rc0").read_text() == "1\n"


@pytest.mark.parametrize("autopilot, rc, stopped, fresh", [
    ("px4", 0, True, True),          # passed: the message as the firmware is killed after a run
    ("px4", 1, False, True),         # failed for another reason
    ("ardupilot", 1, True, True),    # not PX4 SIH
    ("px4", 1, True, False),         # the vehicle rebooted with its storage cannot be booted fresh
])
def test_any_other_run_is_flown_once(tmp_path, autopilot, rc, stopped, fresh):
    run = FakeRun(rcs=[rc], stopped=[stopped])
    assert not fly_scenario(run, autopilot, tmp_path / "s", ["step"], with_firmware=True, fresh=fresh)
    assert run.calls == 1 and not (tmp_path / "s_sih_sensors_stopped").exists()


def test_a_failed_run_whose_sensors_stopped_only_after_the_disarm_is_flown_once(tmp_path):
    """The message as the firmware is killed after a flight that failed for another reason."""
    run = FakeRun(rcs=[1], stopped=[True], after_disarm=True)
    assert not fly_scenario(run, "px4", tmp_path / "s", ["step"], with_firmware=True, fresh=True)
    assert run.calls == 1 and not (tmp_path / "s_sih_sensors_stopped").exists()
