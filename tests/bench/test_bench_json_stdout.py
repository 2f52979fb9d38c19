"""Benchmarks a script can read: every ``aerodaas bench <name> --json``, run as a user runs it (a
subprocess, in an empty working folder), prints its JSON document alone on standard output (``json.loads`` of the
whole of it succeeds: no Ray worker warning, progress line or summary before or after it) and leaves the working
folder empty (no ``fleet.png`` or ``bench_schedulers.png`` it was not asked for). The benchmarks are listed from the
CLI's own parser, so a new one fails here until it has a tiny run in :data:`TINY`. Timing is never asserted."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from aerodaas.bench.parsers import add_parsers

from tests.conftest import DATA_DIR, needs_data_case, needs_path

ROOT = Path(__file__).resolve().parents[2]
WORKLOAD = DATA_DIR / "workloads" / "ocularone_lambda.json"
needs_workload = needs_path(WORKLOAD, reason="the inference workload of the shared data (set AERODAAS_DATA_DIR)")
#: a run of Ray processes or of tens of seconds of flight: in the slow tier (the development tier keeps one cheap
#: Ray benchmark, raypath, and the unit test of the redirection below)
slow = pytest.mark.slow

#: each benchmark's smallest runs: arguments ({recording}, {images}, {annotations}: inputs made outside the working
#: folder by the ``inputs`` fixture) and marks. ``--json`` is added by the test.
TINY: dict[str, list] = {
    "tours": [pytest.param(["--sizes", "5", "--instances", "1", "--repeats", "1"], id="tours")],
    "schedulers": [
        pytest.param(["--harness", "--seeds", "1", "--load", "LIGHT", "--cloud-sigma", "0", "--drones-per-edge", "2",
                      "--scenarios", "none", "--duration", "2", "--drones", "2", "--schedulers", "EDGE_FIFO",
                      "--processes", "1", "--no-bound"], id="schedulers-harness", marks=needs_workload),
        pytest.param(["--drones", "2", "--load", "LIGHT", "--duration", "2", "--schedulers", "EDGE_FIFO", "--seeds",
                      "1", "--drones-per-edge", "2"], id="schedulers-runtime", marks=[needs_workload, slow]),
    ],
    "overhead": [pytest.param(["--detector", "stub", "--stub-ms", "1", "--resolution", "160x120", "--duration", "1",
                               "--window", "1", "--layout", "colocated"], id="overhead", marks=slow)],
    "fleet": [pytest.param(["--drones", "1", "--duration", "1"], id="fleet", marks=slow)],
    "fleet-model": [pytest.param([str(ROOT / "docs" / "results" / "bench_fleet_cluster_2node.json")],
                                 id="fleet-model")],
    "startup": [pytest.param(["--mode", "cold", "--repeat", "1", "--app", str(ROOT / "apps" / "farm_survey.py")],
                             id="startup", marks=slow)],
    "tello-video": [pytest.param(["--width", "160", "--height", "120", "--fps", "10", "--seconds", "1"],
                                 id="tello-video")],
    "raypath": [pytest.param(["--repeat", "5"], id="raypath")],
    "detect": [pytest.param(["--images", "{images}", "--annotations", "{annotations}", "--limit", "1", "--repeat",
                             "1"], id="detect", marks=needs_data_case)],
    "tracks": [pytest.param(["{recording}"], id="tracks")],
    "video": [pytest.param(["--readers", "ours", "--sizes", "720p", "--fps", "10", "--seconds", "1"], id="video")],
    "recorder": [pytest.param(["--drones", "2", "--duration", "1", "--width", "160", "--height", "120", "--recorders",
                               "2"], id="recorder", marks=slow)],
}


def _raypath_steps(rep: dict) -> None:
    """``bench raypath``: every step of a 720p frame's hop, each measured ``--repeat`` (5) times."""
    assert rep["benchmark"] == "raypath" and rep["frame_bytes"] == 1280 * 720 * 3 and rep["machine"]["ray"]
    steps = rep["results_us"]
    assert set(steps) == {"put_frame", "call_ref_roundtrip", "call_ref_submit_to_start", "call_ref_start_to_get",
                          "put_plus_call_ref", "actor_get_zero_copy", "get_small_ready", "call_empty_roundtrip",
                          "call_small_inline_roundtrip", "call_frame_by_value_roundtrip"}
    for s in steps.values():
        assert s["n"] == 5 and 0 <= s["median"] <= s["p99"]


#: what a benchmark's report holds beyond the machine, checked on its tiny run (one Ray start serves both)
REPORT_CHECKS = {"raypath": _raypath_steps}


def _bench_names() -> list[str]:
    """The sub-commands of ``aerodaas bench``, as the CLI registers them."""
    sub = argparse.ArgumentParser(prog="aerodaas bench").add_subparsers()
    add_parsers(sub)
    return sorted(sub.choices)


def _cases() -> list:
    out = []
    for name in _bench_names():
        for case in TINY.get(name, [pytest.param(None, id=f"{name}-missing")]):
            out.append(pytest.param(name, *case.values, id=case.id, marks=case.marks))
    return out


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, str]:
    """The inputs some benchmarks read, made outside the working folder: a recording with the simulator's truth and
    one drone's track scene (three frames at 20 m), and the annotated shared photo of ``bench detect``."""
    from aerodaas.perception.track_records import tracks_prefix, write_tracks
    from aerodaas.recording.writer import McapRecorder

    rec_path = tmp_path_factory.mktemp("inputs") / "run.mcap"
    with McapRecorder(rec_path) as rec:
        for seq in range(3):
            t = (seq + 1) * 10**9
            rec.write_json("/d1/odometry", t, {"robot_id": "d1", "position": [0.0, 0.0, 20.0]},
                           schema_name="aerodaas.Odometry")
            rec.write_json("/world/targets", t, {"robot": "d1", "seq": seq, "t": seq + 1.0, "targets": [
                {"id": "car1", "class_name": "car", "x": 5.0, "y": 5.0, "heading": 0.0, "vx": 0.0, "vy": 0.0,
                 "present": True, "in_view": True, "fully_in_view": True}]}, schema_name="aerodaas.GroundTruth")
            write_tracks(rec, tracks_prefix("d1", "follow"), t, "d1", [
                {"track_id": 1, "class_name": "car", "score": 0.9, "box": [10.0, 10.0, 30.0, 30.0],
                 "enu": [5.5, 5.0, 0.0], "cov": [[1.0, 0.0], [0.0, 1.0]], "sigma_m": 1.0}], None)
    return {"recording": str(rec_path), "images": str(DATA_DIR / "imagery" / "brighton_beach"),
            "annotations": str(ROOT / "tests" / "data" / "brighton_beach_cars.json")}


@pytest.mark.parametrize("name, argv", _cases())
def test_bench_json_is_the_whole_stdout_and_the_working_folder_stays_empty(name, argv, inputs, tmp_path):
    assert argv is not None, f"`aerodaas bench {name}` has no tiny run in TINY (tests/{Path(__file__).name})"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "bench", name, *[a.format(**inputs) for a in argv],
                        "--json"], cwd=cwd, capture_output=True, text=True, timeout=600, env=dict(os.environ))
    assert p.returncode == 0, p.stderr[-3000:]
    try:
        report = json.loads(p.stdout)  # the whole of stdout: one document, nothing before or after it
    except ValueError:
        pytest.fail(f"stdout of `aerodaas bench {name} --json` is not one JSON document:\n{p.stdout[:3000]}")
    assert isinstance(report, dict) and report["machine"]["cpu_count"] >= 1  # the benchmark's report, not a stray
    REPORT_CHECKS.get(name, lambda rep: None)(report)
    assert sorted(os.listdir(cwd)) == []


def test_report_only_stdout_sends_threads_children_and_fd_1_to_stderr():
    """The redirection behind every benchmark, on what Ray's driver does: its log monitor thread prints worker lines
    to whatever ``sys.stdout`` is when it prints (``ray/_private/worker.py`` ``print_to_stdstream``), a child
    process inherits descriptor 1, C code writes to descriptor 1, and Ray's shutdown at exit prints after the
    benchmark returned. Only the report reaches standard output; the rest is on standard error, nothing lost."""
    script = textwrap.dedent("""
        import os, subprocess, sys, threading
        from aerodaas.bench.output import print_report, report_only_stdout

        with report_only_stdout(restore=False):
            t = threading.Thread(target=lambda: print("(raylet) WARNING: from a thread", file=sys.stdout))
            t.start(); t.join()
            subprocess.run([sys.executable, "-c", "print('(pid=1) from a child')"], check=True)
            os.write(1, b"from descriptor 1\\n")
            print_report('{"report": 1}')
            print("after the report")
        print("at exit", flush=True)
    """)
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert p.stdout == '{"report": 1}\n'
    for line in ("(raylet) WARNING: from a thread", "(pid=1) from a child", "from descriptor 1", "after the report",
                 "at exit"):
        assert line in p.stderr.splitlines(), p.stderr


def test_report_only_stdout_restores_both_outputs(capfd):
    """Inside a process that goes on (``restore=True``, as under pytest): after the block ``sys.stdout`` and
    descriptor 1 are back, and the report went to the standard output of before the block."""
    from aerodaas.bench.output import print_report, report_only_stdout

    before = sys.stdout
    with report_only_stdout():
        print("noise")
        os.write(1, b"fd noise\n")
        print_report("the report")
    assert sys.stdout is before
    print("after")
    os.write(1, b"fd after\n")
    out, err = capfd.readouterr()
    assert out.splitlines() == ["the report", "after", "fd after"] and err.splitlines() == ["noise", "fd noise"]


def test_the_cli_runs_a_benchmark_inside_the_redirection(monkeypatch, capfd):
    """``aerodaas bench tours --json`` in-process, its computation replaced by one that makes noise the way Ray's
    driver and a child process do and then computes the real (tiny) result: standard output is the JSON alone."""
    import threading

    from aerodaas import cli
    from aerodaas.bench import tours

    real = tours.run_tours

    def noisy_run_tours(**kw):
        t = threading.Thread(target=print, args=("(raylet) WARNING: from a thread",), kwargs={"file": sys.stdout})
        t.start()
        t.join()
        subprocess.run([sys.executable, "-c", "print('(pid=1) from a child')"], check=True)
        return real(**kw)

    monkeypatch.setattr(tours, "run_tours", noisy_run_tours)
    assert cli.main(["bench", "tours", "--sizes", "5", "--instances", "1", "--repeats", "1", "--json"]) == 0
    out, err = capfd.readouterr()
    assert json.loads(out)["config"]["instances"] == 1
    assert "(raylet) WARNING: from a thread" in err and "(pid=1) from a child" in err
