"""PX4 SIH's simulated sensors stopping in a run: a single-vehicle scenario that failed with them stopped is flown once
more on a freshly booted PX4.

What it looks like (PX4's own ULog of the flight): the barometer, magnetometer, GPS and battery topics
(``sensor_baro``, ``sensor_mag``, ``sensor_gps``, ``battery_status``) stop within 0.1 s of each other while SIH's
IMU goes on, PX4 logs ``MAG #0 failed: TIMEOUT`` and ``Preflight Fail: No valid data from Baro 0`` and fails over to
LAND. Seen at the arming of a freshly booted vehicle (docs/results/test-tiers.md); not the CPU alone (PX4's modules
run ``SCHED_FIFO``). A defect of the simulation, not of the flight under test: the first attempt's files are kept
beside the second's.
"""
from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Callable

#: what PX4 logs once its simulated barometer has stopped (also as the firmware is killed after a run: judged only
#: before the vehicle's disarm, :data:`DISARMED`, and only for a run that failed)
SIH_SENSORS_STOPPED = "Preflight Fail: No valid data from Baro 0"
#: what PX4 logs at the disarm that ends a flight
DISARMED = "Disarmed by"


def sih_sensors_stopped(run_dir: Path) -> bool:
    """PX4 SIH's simulated sensors stopped in flight in the run in ``run_dir``: its ``fw0.log`` holds
    :data:`SIH_SENSORS_STOPPED` before the first :data:`DISARMED` (or with none)."""
    log = run_dir / "fw0.log"
    if not log.exists():
        return False
    text = log.read_text(errors="replace")
    at, disarm = text.find(SIH_SENSORS_STOPPED), text.find(DISARMED)
    return at >= 0 and (disarm < 0 or at < disarm)


def fly_scenario(run: Callable[..., object], autopilot: str, run_dir: Path, steps: list[str], *,
                 with_firmware: bool, fresh: bool) -> bool:
    """``run(autopilot, run_dir, steps, with_firmware=...)`` (:func:`tests.firmware.sitl.run_in_namespace`); when
    its first step failed on a PX4 whose simulated sensors stopped (:func:`sih_sensors_stopped`) and the scenario
    boots a fresh vehicle (``fresh``: not one rebooted with its storage), once more, after moving what the first
    attempt wrote (``run_dir`` and the files of its parent changed since it started) into
    ``<parent>/<run_dir name>_sih_sensors_stopped`` and warning (``UserWarning``). Returns whether it flew once more."""
    started = time.time()
    run(autopilot, run_dir, steps, with_firmware=with_firmware)
    rc = run_dir / "rc0"
    failed = not rc.exists() or rc.read_text().strip() != "0"
    if not (autopilot == "px4" and fresh and with_firmware and failed and sih_sensors_stopped(run_dir)):
        return False
    aside = run_dir.parent / f"{run_dir.name}_sih_sensors_stopped"
    aside.mkdir()
    for f in list(run_dir.parent.iterdir()):
        if f != aside and (f == run_dir or (f.is_file() and f.stat().st_mtime >= started)):
            f.rename(aside / f.name)
    # in pytest's warnings summary, so that a run flown twice is seen
    warnings.warn(f"{run_dir}: PX4 SIH's simulated sensors stopped, flown once more (the first attempt: {aside})",
                  stacklevel=2)
    run(autopilot, run_dir, steps, with_firmware=with_firmware)
    return True
