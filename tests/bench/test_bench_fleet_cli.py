"""``aerodaas bench fleet``'s outputs (the benchmark itself is replaced by a canned report: no Ray, no timing)."""
from __future__ import annotations

import json

import pytest

from aerodaas import cli
from aerodaas.bench import fleet


def _report(sizes, duration_s, groupings=(1,), edge_nodes=1, runs=(), profile=False, camera=True):
    pairs = [(n, k) for n, k in runs] if runs else [(n, k) for k in groupings for n in sizes]
    rows = [{"drones": n, "drones_per_actor": k, "missed_ticks_pct": 0.1 * n, "dropped_frames_pct": 1.0,
             "cpu_pct": 20.0 * n, "rss_mb": 900.0 + 40 * n / k, "pss_mb": 700.0 + 30 * n / k,
             **({"profile": {}} if profile else {})} for n, k in pairs]
    return {"benchmark": "fleet", "machine": {"cpu_count": 2}, "duration_s": duration_s,
            "camera": {"width": 640} if camera else None, "results": rows}


@pytest.fixture
def canned(monkeypatch, tmp_path):
    monkeypatch.setattr(fleet, "run_fleet", _report)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_json_writes_no_file_it_was_not_given(canned, capsys):
    """Without --plot no figure (it used to land as fleet.png in the current directory)."""
    assert cli.main(["bench", "fleet", "--json", "--drones", "1", "--drones", "5", "--duration", "1"]) == 0
    out = capsys.readouterr()
    rep = json.loads(out.out)
    assert [r["drones"] for r in rep["results"]] == [1, 5] and "plot" not in rep
    assert list(canned.iterdir()) == [] and "curve written" not in out.err


def test_plot_and_out_write_where_they_are_told(canned, capsys):
    (canned / "r").mkdir()
    assert cli.main(["bench", "fleet", "--drones", "1", "--duration", "1", "--out", "r/run.json"]) == 0
    assert sorted(p.relative_to(canned).as_posix() for p in canned.rglob("*")) == ["r", "r/run.json"]  # no figure
    assert "plot" not in json.loads((canned / "r" / "run.json").read_text())
    assert cli.main(["bench", "fleet", "--drones", "1", "--duration", "1", "--plot", "curve.png", "--json"]) == 0
    png = canned / "curve.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    out = capsys.readouterr()
    assert json.loads(out.out)["plot"] == str(png) and f"curve written to {png}" in out.err


def test_runs_name_each_fleet_and_its_grouping(canned, capsys):
    """--run N:K (20 and 40 drones one actor each and 100 packed, in one invocation) replaces the grid."""
    assert cli.main(["bench", "fleet", "--json", "--run", "20:1", "--run", "40:1", "--run", "100:10", "--profile",
                     "--duration", "1"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert [(r["drones"], r["drones_per_actor"]) for r in rep["results"]] == [(20, 1), (40, 1), (100, 10)]
    assert all("profile" in r for r in rep["results"])


@pytest.mark.parametrize("bad", ["40", "40:0", "x:1", "0:1", "1:2:3"])
def test_a_bad_run_is_refused_naming_it(canned, capsys, bad):
    assert cli.main(["bench", "fleet", "--run", bad, "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "--run" in err and repr(bad) in err


def _never(*a, **k):
    raise AssertionError("the benchmark ran: a bad value must stop it before Ray starts")


@pytest.mark.parametrize("args, says", [
    (["--edge-nodes", "0"], "--edge-nodes must be >= 1, got 0"),
    (["--edge-nodes", "-2"], "--edge-nodes must be >= 1, got -2"),
    (["--edge-nodes", "3", "--drones", "2"], "--edge-nodes 3 needs at least 3 drones in every run"),
    (["--edge-nodes", "100000", "--drones", "100000"], "--edge-nodes 100000 with 100000 drone actors needs about"),
])
def test_bad_edge_nodes_exit_2_naming_them_before_ray_starts(monkeypatch, capsys, args, says):
    import ray

    # neither the benchmark nor any Ray start may be reached (another test of this worker may have Ray running
    # already, so ray.is_initialized() would not tell)
    monkeypatch.setattr(fleet, "run_fleet", _never)
    monkeypatch.setattr(ray, "init", _never)
    monkeypatch.setattr(fleet, "LocalCluster", _never)
    assert cli.main(["bench", "fleet", "--duration", "1", *args]) == 2
    assert says in capsys.readouterr().err


def test_the_memory_check_counts_head_nodes_and_drone_actors():
    need = fleet.HEAD_EXTRA_MB + 2 * fleet.NODE_FIXED_MB + 8 * fleet.DRONE_ACTOR_MB
    assert fleet.check_edge_nodes(2, ((8, 1),), need) is None
    assert "needs about" in fleet.check_edge_nodes(2, ((8, 1),), need - 1)
    # packed drones: 8 drones in 2 actors need less
    assert fleet.check_edge_nodes(2, ((8, 4),), need - 1) is None


def test_the_framework_share_is_what_the_drone_actors_ran_less_what_the_user_brought():
    """Over the drone actors that flew (an actor that reported no run, lost or not a drone's, counts for nothing):
    CPU-seconds per drone per simulated second of all their threads, of the user's parts and of what is left."""
    def flown(drones, sim_s, cpu, render, analytics, encode):
        return {"cpu": {"drones": drones, "flight_sim_s": sim_s, "flight_cpu_s": cpu, "render_cpu_s": render,
                        "analytics_cpu_s": analytics, "encode_cpu_s": encode}}

    hosts = {"drone/d00": flown(1, 10.0, 0.5, 0.2, 0.05, 0.05), "drone/d01+d02": flown(2, 10.0, 0.9, 0.3, 0.1, 0.0),
             "drone/d03": {"error": "RayActorError: lost"},
             "analytics/edge/count#1": {"cpu": {"render_cpu_s": 0.0, "analytics_cpu_s": 3.0, "encode_cpu_s": 0.0}}}
    row = fleet.drone_actor_cpu(hosts)
    assert row["framework_cpu_s_per_drone_per_sim_s"] == round((1.4 - 0.7) / 30.0, 4)
    assert row["drone_actor_cpu_s_per_drone_per_sim_s"] == {
        "all": round(1.4 / 30, 4), "camera frame making": round(0.5 / 30, 4), "analytics process calls": 0.005,
        "recorded frames' JPEG encode": round(0.05 / 30, 4), "framework": round(0.7 / 30, 4)}
    assert fleet.drone_actor_cpu({"drone/d03": {"error": "lost"}}) == {}
