"""``aerodaas bench fleet --no-camera --profile`` end to end, as a swarm researcher runs it (a subprocess with its own
Ray): drones packed two per drone actor fly without cameras, their control ticks counted and no frame made; the
profile measures one drone actor beside an idle Ray actor, which the row's processes leave out. No timing is
asserted — the numbers live in docs/results/fleet.md."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.e2e


def test_packed_drones_without_cameras_fly_and_make_no_frame(tmp_path):
    out = tmp_path / "fleet.json"
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "bench", "fleet", "--run", "4:2", "--no-camera",
                        "--duration", "12", "--profile", "--out", str(out)], cwd=tmp_path, capture_output=True,
                       text=True, timeout=600, env=dict(os.environ))
    assert p.returncode == 0, p.stderr[-2000:]
    rep = json.loads(out.read_text())
    assert rep["camera"] is None
    (row,) = rep["results"]
    assert (row["drones"], row["drones_per_actor"]) == (4, 2)
    assert row["worker_processes"] >= 2  # two drone actors (and the recorder's), not one per drone
    # every drone flew its control loop; no camera ticked, no frame reached an analytics
    assert row["ticks"] >= 4 * 10 and row["host_errors"] == 0 and row["outcomes"] == ["timeout"]
    assert row["camera_ticks"] == 0 and row["frames_analysed"] == 0
    # the drone actors' own CPU accounts: no camera made a frame, no analytics ran; all of it is the framework's
    cpu = row["drone_actor_cpu_s_per_drone_per_sim_s"]
    assert cpu["camera frame making"] == cpu["analytics process calls"] == cpu["recorded frames' JPEG encode"] == 0
    assert cpu["framework"] == cpu["all"] == row["framework_cpu_s_per_drone_per_sim_s"] > 0, cpu
    # the profile's window (6 s, from 3 s into the 12 s flight): the drone actor beside the bare actor, the floor
    # of any actor
    prof = row["profile"]
    assert prof["drones_in_actor"] == 2 and prof["actor_wakes_per_s"] > 0, prof
    bare = prof["bare_actor"]
    assert bare["pid"] not in {r["pid"] for r in row["process_rows"]}  # left out of the fleet's processes
    assert bare["pid"] != prof["actor_pid"] and bare["wakes_per_s"] > 0 and bare["threads"] >= 2, bare
    assert bare["pss_mb"] < sum(prof["actor_pss_mb"].values()), (bare, prof["actor_pss_mb"])  # nothing of ours in it
    assert "no cameras" in p.stderr
    assert sorted(x.name for x in tmp_path.iterdir()) == ["fleet.json"]  # nothing it was not asked for
