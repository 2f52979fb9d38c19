"""Every option of the scheduler benchmarks honoured or refused: ``python -m
aerodaas.bench.decision_time`` refuses an option its scheduler does not take and takes the ``--trace-*`` options of
``aerodaas bench schedulers``; ``aerodaas bench schedulers`` refuses ``--estimator`` / ``--eviction-scan`` when no
scheduler of the run takes them, and ``--cloud-sigma`` with ``--cloud-jitter`` on the runtime; and every JSON holds
what shaped its result (machine, jitters, trace parameters, options, whether LAPLAN's planner ran compiled). Every
run here is a few simulated seconds on the harness; no Ray."""
from __future__ import annotations

import asyncio
import json

import pytest

from aerodaas.bench import decision_time
from aerodaas.schedulers import single_machine_jit

from tests.conftest import DATA_DIR, needs_workload

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"


# --------------------------------------------------------------------------------------------- decision_time
@pytest.mark.parametrize("argv, named", [
    (["--scheduler", "DEM", "--option", "horizon_ms=0"], "--option horizon_ms: scheduler DEM does not take it"),
    (["--scheduler", "EDGE_EDF", "--option", "estimator=\"mean\""], "--option estimator: scheduler EDGE_EDF"),
    (["--trace", "pareto", "--trace-on-s", "2"], "trace pareto takes no on_s"),
    (["--trace", "periodic", "--trace-drop", "0.1"], "trace periodic takes no drop"),
])
def test_decision_time_refuses_what_it_would_ignore_naming_it(argv, named, tmp_path, monkeypatch, capsys):
    """An option the scheduler does not take was filtered out silently and yet recorded as applied;
    a trace parameter could not be set at all. Refused, exit 2, before any run (no JSON)."""
    monkeypatch.setenv("AERODAAS_DATA_DIR", str(DATA_DIR))
    out = tmp_path / "d.json"
    assert decision_time.main([*argv, "--duration", "2", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert named in captured.err, captured.err
    assert not out.exists() and captured.out == ""


@needs_workload
def test_decision_time_json_holds_what_shaped_the_result(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("AERODAAS_DATA_DIR", str(DATA_DIR))
    out = tmp_path / "d.json"
    assert decision_time.main(["--scheduler", "LAPLAN", "--duration", "4", "--seed", "3", "--trace", "onoff",
                               "--trace-on-s", "1", "--trace-off-s", "2", "--option", "horizon_ms=0",
                               "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res == json.loads(capsys.readouterr().out)
    assert res["machine"]["cpu_count"] >= 1 and res["machine"]["memory_gib"] > 0 and res["machine"]["python"]
    assert res["trace_params"]["kind"] == "onoff" and (res["trace_params"]["on_s"], res["trace_params"]["off_s"]) \
        == (1.0, 2.0)
    assert res["trace"].startswith("onoff(on 1 s, off 2 s")
    assert res["edge_jitter"] == "lognormal:0.05" and res["cloud_jitter"] == "lognormal:0.1"
    assert res["options"] == {"horizon_ms": 0} and res["counters"].get("arrived_as_predicted", 0) == 0
    assert res["laplan_planner"] == single_machine_jit.status()
    assert res["events"] > 0
    # the trace's parameters shape the run: another on/off cycle, another trace
    other = decision_time.measure("LAPLAN", duration_s=4, seed=3, trace="onoff", options={"horizon_ms": 0})
    assert other["trace_params"]["on_s"] == 3.0 and other["utility"] != res["utility"]


def test_the_planner_status_says_why_it_is_not_compiled(monkeypatch):
    monkeypatch.setenv("AERODAAS_NO_JIT", "1")
    assert single_machine_jit.status() == {"compiled": False, "why_not": "AERODAAS_NO_JIT is set"}


# --------------------------------------------------------------------------------------------- bench schedulers
def _bench(argv, tmp_path):
    from aerodaas.cli import main

    return main(["bench", "schedulers", *argv, "--plot", str(tmp_path / "h.png")])


@pytest.mark.parametrize("argv, named", [
    (["--harness", "--schedulers", "EDGE_EDF", "CLOUD", "--estimator", "mean"], "--estimator"),
    (["--harness", "--schedulers", "EDGE_EDF", "--eviction-scan", "full"], "--eviction-scan"),
    (["--schedulers", "CLOUD", "EDGE_FIFO", "--eviction-scan", "reference"], "--eviction-scan"),
    (["--harness", "--schedulers", "LAPLAN", "--eviction-scan", "full"], "--eviction-scan"),
    (["--cloud-sigma", "0.1", "--cloud-jitter", "lognormal:0.3"], "--cloud-sigma, --cloud-jitter"),
])
def test_a_scheduler_option_no_scheduler_takes_is_refused_naming_it(argv, named, tmp_path, capsys):
    """--estimator and --eviction-scan were accepted when no scheduler of the run used them; on the
    runtime --cloud-sigma overrode --cloud-jitter while the JSON recorded the ignored jitter. Exit 2 before any run
    (no Ray, no job, no figure), naming the options."""
    # tiny runs, should one be accepted by mistake (the runtime's default is 80 drones over 60 s x 5 seeds)
    assert _bench([*argv, "--drones", "1", "--duration", "1", "--seeds", "1"], tmp_path) == 2
    err = capsys.readouterr().err
    assert f"aerodaas bench schedulers: {named}: " in err, err
    assert not (tmp_path / "h.png").exists()


@needs_workload
def test_the_harness_json_holds_the_options_it_applied_and_the_planner(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("AERODAAS_DATA_DIR", str(DATA_DIR))
    assert _bench(["--harness", "--seeds", "1", "--load", "HEAVY", "--cloud-sigma", "0.1", "--drones-per-edge", "3",
                   "--scenarios", "none", "--duration", "5", "--drones", "3", "--processes", "1", "--no-bound",
                   "--schedulers", "EDGE_EDF", "DEM", "--eviction-scan", "full", "--estimator", "max:5", "--json"],
                  tmp_path) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["config"]["options"] == {"eviction_scan": "full", "estimator": "max:5"}
    assert res["laplan_planner"] == single_machine_jit.status()


def test_the_runtime_json_records_the_jitter_used_and_the_planner_of_its_hosts():
    """The runtime's config says which cloud jitter its measured runs used (a --cloud-sigma sweep replaces
    --cloud-jitter), and whether LAPLAN's planner ran compiled on every edge host actor (where the policies run)."""
    from aerodaas.bench.edge_host import EdgeHost
    from aerodaas.bench.schedulers import _config, _planner_of

    kw = dict(names=["DEM"], loads=["HEAVY"], drones=3, drones_per_edge=3, n_edges=1, fps=1.0, duration_s=2.0,
              repeat=1, trace_spec=None, edge_jitter="lognormal:0.05", cloud_jitter="lognormal:0.1", network=None,
              seed=0, cloud_nodes=1, address=None, n_hosts=1, n_cloud=1, wpath="w.json", reply_lead_ms=100.0,
              scen=["none"], options={}, emulation_bound_ms=10.0, drain_s=10.0)
    assert _config(**kw, jitters=[(None, "lognormal:0.1")])["cloud_jitter"] == "lognormal:0.1"
    swept = _config(**kw, jitters=[(0.0, "lognormal:0"), (0.2, "lognormal:0.2")])
    assert swept["cloud_jitter"] == "lognormal:<cloud_sigma>" and swept["cloud_sigma"] == [0.0, 0.2]
    info = asyncio.run(EdgeHost("h0").info())
    assert info["laplan_planner"] == single_machine_jit.status()
    off = {**info, "name": "h1", "laplan_planner": {"compiled": False, "why_not": "AERODAAS_NO_JIT is set"}}
    assert _planner_of([info, off]) == {"compiled": False, "why_not": "AERODAAS_NO_JIT is set",
                                        "per_host": {"h0": info["laplan_planner"]["compiled"], "h1": False}}
