"""The scheduler benchmarks' arrival processes (aerodaas/bench/traces.py, make_trace): seeded determinism, drop rate,
jitter bounds, drones joining and leaving, replay of a recording's camera-frame gaps, and errors naming the field."""
from __future__ import annotations

import math

import pytest
from mcap.writer import Writer

from aerodaas.bench.workload import make_trace
from aerodaas.bench.traces import TraceSpec, frame_times, recording_frame_gaps
from aerodaas.schedulers.analytics_base import Workload
from tests.inputs.cli_inprocess import run_cli
from tests.conftest import needs_workload

W = Workload.from_dict({"models": {"A": {"edge_ms": 100, "cloud_ms": 200, "benefit": 50, "edge_cost": 1,
                                         "cloud_cost": 10},
                                   "B": {"edge_ms": 50, "cloud_ms": 150, "benefit": 20, "edge_cost": 1,
                                         "cloud_cost": 5}},
                        "loads": {"T": {"A": 400, "B": 300}}}, "T")
REAL = TraceSpec.parse("realistic")


def frames(rows):
    """(drone -> sorted frame times) of trace rows (one row per model per frame)."""
    out = {}
    for t, _edge, drone, _model in rows:
        out.setdefault(drone, set()).add(t)
    return {d: sorted(ts) for d, ts in out.items()}


def test_realistic_defaults_are_the_audit_setting():
    assert (REAL.jitter, REAL.drop, REAL.joins, REAL.leaves) == (0.2, 0.1, 1, 0)
    assert TraceSpec.parse("periodic") == TraceSpec()


def test_same_seed_same_trace_other_seed_other_trace():
    a = make_trace(W, 12, 60, 4, 3, 1.0, REAL)
    assert a == make_trace(W, 12, 60, 4, 3, 1.0, REAL)
    assert a != make_trace(W, 12, 60, 5, 3, 1.0, REAL)
    # a drone's frames do not depend on the fleet size (seeded per drone)
    assert frames(make_trace(W, 6, 60, 4, 3, 1.0, REAL))["d000"] == frames(a)["d000"]


def test_every_frame_gives_one_task_per_model():
    rows = make_trace(W, 6, 30, 1, 3, 1.0, REAL)
    per_frame = {}
    for t, _e, d, m in rows:
        per_frame.setdefault((d, t), []).append(m)
    assert all(sorted(ms) == ["A", "B"] for ms in per_frame.values())
    assert [r[0] for r in rows] == sorted(r[0] for r in rows)


def test_jitter_bounds_each_gap():
    spec = TraceSpec("realistic", jitter=0.2)
    gaps = []
    for i in range(20):
        ts = frame_times(spec, f"d{i}", 0, 3, i, 1000.0, 120_000.0, seed=2)
        gaps += [b - a for a, b in zip(ts, ts[1:])]
    assert len(gaps) > 2000
    assert all(800.0 - 0.002 <= g <= 1200.0 + 0.002 for g in gaps)
    assert min(gaps) < 820 and max(gaps) > 1180          # the whole ±20 % range is used
    assert abs(sum(gaps) / len(gaps) - 1000.0) < 10.0     # unbiased: the mean rate stays fps


def test_drop_rate():
    kept = sum(len(frame_times(TraceSpec("realistic", drop=0.1), f"d{i}", 0, 3, i, 1000.0, 100_000.0, seed=3))
               for i in range(40))
    sent = sum(len(frame_times(TraceSpec("realistic"), f"d{i}", 0, 3, i, 1000.0, 100_000.0, seed=3)) for i in range(40))
    n = sent
    assert abs((1 - kept / sent) - 0.1) < 4 * math.sqrt(0.1 * 0.9 / n)   # binomial, 4 sigma


def test_joins_and_leaves():
    spec = TraceSpec("realistic", joins=1, leaves=1)
    for i in range(3):
        ts = frame_times(spec, f"d{i}", i, 3, i, 1000.0, 100_000.0, seed=9)
        if i == 2:                                        # the last drone on the edge joins mid-run
            assert 20_000.0 <= ts[0] <= 51_000.0
        else:
            assert ts[0] < 1000.0
        if i == 0:                                        # the first one leaves mid-run
            assert 49_000.0 <= ts[-1] < 80_000.0
        else:
            assert ts[-1] > 98_000.0


def test_periodic_is_strictly_periodic():
    for ts in frames(make_trace(W, 6, 30, 1, 3, 2.0)).values():
        assert {round(b - a, 3) for a, b in zip(ts, ts[1:])} == {500.0}


def _recording(path, gaps_ms):
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("foxglove.CompressedImage", "protobuf", b"")
        cam = w.register_channel("/d0/camera/cam1", "protobuf", sid)
        other = w.register_channel("/d0/gps", "json", w.register_schema("foxglove.LocationFix", "jsonschema", b"{}"))
        t = 1_000_000_000
        for k, g in enumerate([0.0, *gaps_ms]):
            t += int(g * 1e6)
            w.add_message(cam, t, b"x", t, k)
            w.add_message(other, t + 1, b"{}", t + 1, k)
        w.finish()


def test_recording_replays_the_recorded_gap_shape(tmp_path):
    gaps = [100.0, 300.0, 100.0, 500.0] * 5                # mean 250 ms
    path = tmp_path / "rec.mcap"
    _recording(path, gaps)
    assert recording_frame_gaps(path) == [pytest.approx(gaps)]
    spec = TraceSpec.parse(f"recording:{path}")
    ts = frame_times(spec, "d0", 0, 3, 0, 1000.0, 60_000.0, seed=1)
    replayed = [round(b - a, 1) for a, b in zip(ts, ts[1:])]
    assert set(replayed) <= {400.0, 1200.0, 2000.0}       # the recorded gaps x (1000 / 250)
    assert abs(sum(replayed) / len(replayed) - 1000.0) < 150.0


def test_bad_trace_options_name_the_field(tmp_path):
    with pytest.raises(ValueError, match="trace kind"):
        TraceSpec.parse("bursty")
    with pytest.raises(ValueError, match="trace jitter"):
        TraceSpec.parse("realistic", jitter=1.5)
    with pytest.raises(ValueError, match="trace drop"):
        TraceSpec.parse("realistic", drop=-0.1)
    with pytest.raises(ValueError, match="joins/leaves"):
        TraceSpec.parse("realistic", joins=-1)
    with pytest.raises(ValueError, match="periodic takes no"):
        TraceSpec.parse("periodic", jitter=0.2)
    with pytest.raises(ValueError, match="no file"):
        TraceSpec.parse(f"recording:{tmp_path / 'missing.mcap'}")
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(ValueError):
        recording_frame_gaps(tmp_path / "empty.mcap")


@needs_workload
def test_sweep_runs_and_records_the_realistic_trace():
    from aerodaas.bench.sweep import run_sweep
    from tests.conftest import WORKLOAD_JSON as wpath

    kw = dict(loads=["HEAVY"], sigmas=[0.0], drones_per_edge=[2], scenarios=["none"], seeds=[0], duration_s=10,
              edges=1, schedulers=["DEM"], processes=1, bound=False, workload_path=wpath)
    per = run_sweep(**kw)
    real = run_sweep(**kw, trace=TraceSpec.parse("realistic", drop=0.3))
    assert real["config"]["trace"]["kind"] == "realistic" and per["config"]["trace"] is None
    # 30 % of the frames lost and one of the two drones joining late: fewer tasks than the periodic trace
    assert real["results"][0]["tasks"]["mean"] < 0.8 * per["results"][0]["tasks"]["mean"]


def test_cli_rejects_a_bad_trace_before_running(tmp_path):

    p = run_cli("bench", "schedulers", "--harness", "--trace", "bursty", "--out", str(tmp_path / "x.json"))
    assert p.returncode == 2 and "trace kind" in p.stderr and "bursty" in p.stderr
    assert not (tmp_path / "x.json").exists()


@pytest.mark.parametrize("kind", ["pareto", "onoff", "flush"])
def test_bursty_traces_keep_the_mean_rate_and_are_seeded(kind):
    spec = TraceSpec.parse(kind)
    runs = [frame_times(spec, f"d{i}", 0, 3, i, 1000.0, 600_000.0, seed=5) for i in range(12)]
    assert runs[0] == frame_times(spec, "d0", 0, 3, 0, 1000.0, 600_000.0, seed=5)           # seeded
    assert runs[0] != frame_times(spec, "d0", 0, 3, 0, 1000.0, 600_000.0, seed=6)
    rate = sum(len(ts) for ts in runs) / 12 / 600.0
    assert 0.9 < rate < 1.15, rate                   # the mean rate of 1 frame/s (Pareto's tail converges slowly)
    assert all(all(b > a for a, b in zip(ts, ts[1:])) for ts in runs)
    from aerodaas.bench.traces import gap_stats
    assert min(gap_stats(ts)["cv"] for ts in runs) > 0.5     # bursty: far from periodic (cv 0)


def test_bursty_trace_shapes():
    on = frame_times(TraceSpec.parse("onoff", on_s=3.0, off_s=3.0), "d0", 0, 1, 0, 1000.0, 60_000.0, seed=1)
    gaps = sorted({round(b - a) for a, b in zip(on, on[1:])})
    assert gaps[0] == 500 and max(gaps) > 3000        # 2 fps within a burst, then 3 s of silence
    fl = frame_times(TraceSpec.parse("flush", stall_s=2.0, stall_every_s=6.0, flush_gap_ms=2.0), "d0", 0, 1, 0,
                     1000.0, 120_000.0, seed=1)
    gaps = [round(b - a, 3) for a, b in zip(fl, fl[1:])]
    assert min(gaps) == 2.0 and max(gaps) > 1000.0    # buffered frames flushed 2 ms apart after a stall
    pa = frame_times(TraceSpec.parse("pareto", alpha=1.5), "d0", 0, 1, 0, 1000.0, 600_000.0, seed=1)
    gaps = [b - a for a, b in zip(pa, pa[1:])]
    assert min(gaps) >= 1000.0 / 3 - 1e-3 and max(gaps) > 5000.0   # Pareto scale period/3, a heavy tail


def test_trace_parameters_a_kind_does_not_use_are_refused():
    with pytest.raises(ValueError, match="onoff takes no alpha"):
        TraceSpec.parse("onoff", alpha=2.0)
    with pytest.raises(ValueError, match="pareto takes no jitter"):
        TraceSpec.parse("pareto", jitter=0.1)
    with pytest.raises(ValueError, match="trace alpha"):
        TraceSpec.parse("pareto", alpha=1.0)
    with pytest.raises(ValueError, match="trace stall_s"):
        TraceSpec.parse("flush", stall_s=0.0)
    assert TraceSpec.parse("flush", stall_s=1.0).stall_s == 1.0
    assert TraceSpec.parse("realistic") == TraceSpec("realistic", jitter=0.2, drop=0.1, joins=1)


def test_the_cli_takes_the_bursty_trace_options(tmp_path):
    from aerodaas.bench.schedulers_cli import add_parser
    from aerodaas.bench.schedulers_main import trace_spec
    import argparse

    sub = argparse.ArgumentParser().add_subparsers()
    p = add_parser(sub)
    args = p.parse_args(["--harness", "--trace", "onoff", "--trace-on-s", "2", "--trace-off-s", "4"])
    assert trace_spec(args) == TraceSpec("onoff", on_s=2.0, off_s=4.0)
    with pytest.raises(ValueError, match="takes no"):
        trace_spec(p.parse_args(["--harness", "--trace", "periodic", "--trace-stall-s", "1"]))
