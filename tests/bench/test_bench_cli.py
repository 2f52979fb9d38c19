"""``aerodaas bench overhead`` and ``aerodaas bench startup`` end to end: the JSON reports carry their documented keys
and sane structure. ``bench startup`` runs as a user runs it (a subprocess that starts its own Ray: its phases are
the point); ``bench overhead``, whose point is its report, runs in-process on the pytest worker's shared Ray session
(:func:`tests.inputs.cli_inprocess.run_cli`). No timing is asserted — the numbers live in the benchmark results, not
in tests."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.inputs.cli_inprocess import run_cli

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.e2e


def _aerodaas(*args: str, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout, env=dict(os.environ))


def test_bench_overhead_json_has_every_column_every_layout_and_the_honest_tail(tmp_path, ray_session):
    """Every layout recorded and unrecorded (8 missions) beside the peers, one window of 1 s each after 0.5 s at
    the hover altitude: each mission's commands count from its whole flight (a window holds at least the last
    applied one), so the checks below do not depend on how many frames a loaded machine gets through in the
    window."""
    out = tmp_path / "o.json"
    p = run_cli("bench", "overhead", "--detector", "stub", "--stub-ms", "2", "--resolution", "320x240",
                "--duration", "1", "--window", "1", "--settle", "0.5", "--layout", "all", "--lockstep", "--record",
                "--out", str(out), cwd=ROOT, shared_ray=True)
    assert p.returncode == 0, p.stderr[-2000:]
    rep = json.loads(out.read_text())
    assert rep["benchmark"] == "overhead" and rep["machine"]["cpu_count"] >= 1 and rep["machine"]["ray"]
    assert rep["settle_s"] == 0.5
    assert rep["layouts"] == ["colocated", "actors", "actors-ray", "actors+lockstep"] and rep["recorded"] is True
    assert rep["load"]["load_avg_1min_at_windows"]["n"] >= 3              # one load sample per window
    colo, actors, actors_ray, lockstep = rep["results"]
    # --lockstep: the actors layout under the lock-step clock, on the same channel, every frame through
    ls = lockstep["framework"]
    assert lockstep["layout"] == "actors+lockstep" and ls["lockstep"] and not actors["framework"]["lockstep"]
    assert ls["frame_transport"] == ["channel"] and ls["frames_dropped_busy_detector"] == 0
    assert ls["commands_applied"] > 0 and ls["host_errors"] == 0
    for row in (colo, actors, actors_ray):
        assert row["resolution"] == "320x240" and row["detector"] == "stub" and row["fps"] == 30
        for key in ("framework_overhead_ms", "bare_loop_overhead_ms", "naive_ray_overhead_ms", "dora_rs_overhead_ms",
                    "dora_rs_grouped_overhead_ms"):
            assert key in row
    assert colo["layout"] == "colocated" and actors["layout"] == "actors" and actors_ray["layout"] == "actors-ray"
    # frames left the drone actor: not at all / through the same-node channel / through Ray
    assert [r["framework"]["frame_transport"] for r in (colo, actors, actors_ray)] == [[], ["channel"], ["ray"]]
    for row in (actors, actors_ray):                                       # the hop's parts were measured
        assert {"put_ms", "call_ms", "get_ms"} <= set(row["framework"]["hop_ms"])
    for row in (colo, actors, actors_ray):                                 # every layout really flown
        assert row["status"] == "measured" and row["framework"]["layout"] == row["layout"]
        for side in ("framework_overhead_ms", "bare_loop_overhead_ms", "naive_ray_overhead_ms"):
            assert set(row[side]) == {"median", "p99"} and 0 <= row[side]["median"] <= row[side]["p99"]
        assert row["ratio_median"] == pytest.approx(row["framework_overhead_ms"]["median"]
                                                    / row["bare_loop_overhead_ms"]["median"])
        assert row["framework"]["commands_applied"] > 0 and row["framework"]["host_errors"] == 0
    assert actors["bare_loop_overhead_ms"] == colo["bare_loop_overhead_ms"]  # the peers ran once, beside both
    fw = colo["framework"]
    assert fw["commands_applied"] > 0 and fw["host_errors"] == 0           # the follow really commanded the drone
    assert fw["recorded"] and fw["recording_bytes"] > 0                    # --record recorded the runtime's runs
    un = colo["framework_unrecorded"]                                      # ... beside unrecorded ones, same rotation
    assert not un["recorded"] and un["recording_bytes"] == 0 and un["commands_applied"] > 0
    assert set(colo["framework_unrecorded_overhead_ms"]) == {"median", "p99"}
    assert set(actors["framework_unrecorded_overhead_ms"]) == {"median", "p99"}
    # end-to-end = inference + post-processing + overhead, frame by frame, so the medians are ordered
    assert fw["e2e_ms"]["median"] >= fw["inference_ms"]["median"] >= 2.0 * 0.9
    assert fw["capture_dispatch_ms"]["median"] is not None
    naive = colo["naive_ray"]
    assert naive["available"] and naive["commands_applied"] > 0
    assert set(naive["hops_ms"]) == {"camera_detector", "detector_follow", "follow_scheduler", "scheduler_drone"}
    assert naive["e2e_ms"]["median"] >= naive["inference_ms"]["median"] >= 2.0 * 0.9
    # the honest tail subtracts the nominal 2 ms, not the measured sleep, so it is at least the paper's overhead
    for name in ("framework", "bare_loop", "naive_ray"):
        h = colo["honest_overhead_ms"][name]
        assert set(h) == {"median", "p99"} and h["median"] <= h["p99"]
    assert colo["honest_overhead_ms"]["naive_ray"]["median"] >= colo["naive_ray_overhead_ms"]["median"] - 0.5
    for peer in ("dora_rs", "dora_rs_grouped"):                           # both dora-rs shapes
        dora = colo[peer]
        if dora["available"]:
            assert dora["commands_applied"] > 0 and colo[f"{peer}_overhead_ms"]["median"] >= 0
        else:                                                              # not installed: said so, never a number
            assert colo[f"{peer}_overhead_ms"] is None and "dora" in dora["reason"]


def test_bench_startup_cold_json_reports_phases_in_order(tmp_path):
    """``--mode cold`` (the development tier's share of ``bench startup``): one run that starts its own Ray, its
    phases in order; no `aerodaas up` cluster is started (that is the cluster test below)."""
    out = tmp_path / "s.json"
    p = _aerodaas("bench", "startup", "--app", str(ROOT / "apps" / "farm_survey.py"), "--repeat", "1", "--mode",
                  "cold", "--out", str(out), timeout=240)
    assert p.returncode == 0, p.stderr[-2000:]
    rep = json.loads(out.read_text())
    (run,) = rep["runs"]
    assert rep["seconds_to_first_frame"] == run["seconds_to_first_frame"] > 0
    assert list(run["phases_s"]) == ["cli", "app_built", "ray_ready", "hosts_ready", "first_processed"]
    assert run["phases_s"]["first_processed"] == run["seconds_to_first_frame"]
    assert rep["cold"]["runs"] == [run] and "attached" not in rep
    assert len(rep["load_avg_before"]) == 3 == len(rep["load_avg_after"])


# starts `aerodaas up`'s persistent cluster, on Ray's fixed default ports: the cluster lane of the slow tier
# (tests/conftest.py CLUSTER_GROUPS), as tests/cluster/test_persistent_cluster.py
@pytest.mark.cluster
def test_bench_startup_json_reports_phases_in_order(tmp_path):
    out = tmp_path / "s.json"
    p = _aerodaas("bench", "startup", "--app", str(ROOT / "apps" / "farm_survey.py"), "--repeat", "1",
                  "--out", str(out), timeout=240)
    assert p.returncode == 0, p.stderr[-2000:]
    rep = json.loads(out.read_text())
    (run,) = rep["runs"]
    assert rep["seconds_to_first_frame"] == run["seconds_to_first_frame"] > 0
    phases = run["phases_s"]
    order = ["cli", "app_built", "ray_ready", "hosts_ready", "first_processed"]
    assert list(phases) == order                                             # each phase seen, in this order
    assert phases["first_processed"] == run["seconds_to_first_frame"]
    # attached to an `aerodaas up` cluster of the benchmark's own, stopped afterwards
    (att,) = rep["attached"]["runs"]
    assert list(att["phases_s"]) == order and rep["cold"]["runs"] == [run]
    # the attached run started once the cluster's warm pool was full (clusters.warm_pool)
    assert rep["attached"]["warm_workers"] == 4 and att["warm_idle_at_start"] >= 4
    assert len(rep["load_avg_before"]) == 3 == len(rep["load_avg_after"])


def test_bench_overhead_refuses_a_bad_resolution():
    p = run_cli("bench", "overhead", "--detector", "stub", "--resolution", "640by480", cwd=ROOT)  # in-process
    assert p.returncode == 2 and "--resolution expects WxH" in p.stderr
