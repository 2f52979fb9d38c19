"""One recorder per node on a two-node local cluster: two recorders write one run, each on its
node, the live view shows both nodes' channels, and ``aerodaas merge`` + ``aerodaas info`` present the run whole
with the accounting complete. The run is ``tests/cluster/cluster_recorders_app.py`` in a subprocess; placement is read from
Ray's GCS, the files with the mcap library's own reader, the live view with a Foxglove protocol client written
from the spec."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _topics(path) -> dict[str, int]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        s = make_reader(f).get_summary()
    return {c.topic: s.statistics.channel_message_counts.get(cid, 0) for cid, c in s.channels.items()}


def _app(tmp_path, *extra: str) -> dict:
    p = subprocess.run([sys.executable, "tests/cluster/cluster_recorders_app.py", str(tmp_path), *extra], cwd=ROOT,
                       capture_output=True, text=True, timeout=600, env=dict(os.environ))
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert line is not None, (p.returncode, p.stdout[-3000:], p.stderr[-3000:])
    r = json.loads(line[len("RESULT "):])
    assert r["outcome"] == "success" and r["robots"] == {"d00": "success", "d01": "success"}, r
    assert r["accounting"]["lost_total"] == 0 and not r["accounting"]["unaccounted"], r["accounting"]
    return r


@pytest.mark.cluster
def test_two_node_recorders_write_one_run_that_merge_and_info_present_whole(tmp_path):
    r = _app(tmp_path)
    # each node's recorder ran on its node (Ray's GCS, read while the run was up)
    site = {a["name"].split("aerodaas/pernode/")[1]: a["labels"].get("aerodaas/site") for a in r["actors"]
            if (a["name"] or "").startswith("aerodaas/pernode/")}
    assert site["recorder/edge-a"] == "a" and site["recorder/edge-b"] == "b", site
    assert site["drone/d00"] == "a" and site["drone/d01"] == "b", site
    _check_files_live_and_merge(tmp_path, r)


@pytest.mark.cluster  # a whole run with a live-view client: minutes at load, so in the cluster lane beside its two-node twin
def test_on_one_node_the_per_node_recorders_write_one_run_too(tmp_path):
    """The same run on a single-node local Ray (both node recorders on this node): the files, the live view, the
    merge and the accounting as on the cluster."""
    r = _app(tmp_path, "local")
    names = {a["name"] for a in r["actors"]}
    assert {"aerodaas/pernode/recorder/edge-a", "aerodaas/pernode/recorder/edge-b"} <= names, names
    _check_files_live_and_merge(tmp_path, r)


def _check_files_live_and_merge(tmp_path, r: dict) -> None:

    # each drone's data is in its node's file only; the run's summary names the files and how to merge them
    main, a, b = (tmp_path / n for n in ("run.mcap", "run.node-edge-a.mcap", "run.node-edge-b.mcap"))
    assert r["nodes"] == [str(a), str(b)], r["nodes"]
    assert f"aerodaas merge {main} {a} {b} --out ALL.mcap" in r["summary"], r["summary"]
    ta, tb, tm = _topics(a), _topics(b), _topics(main)
    assert ta.get("/d00/camera/cam", 0) > 0 and ta.get("/d00/odometry", 0) > 0 and "/d01/odometry" not in ta
    assert tb.get("/d01/camera/cam", 0) > 0 and tb.get("/d01/odometry", 0) > 0 and "/d00/odometry" not in tb
    assert not any(t.startswith(("/d00/", "/d01/")) and n for t, n in tm.items()), tm

    # the live view (on the driver's node) showed both nodes' channels, with messages
    assert {"/d00/odometry", "/d01/odometry", "/d00/camera/cam", "/d01/camera/cam"} <= set(r["live_channels"]), r
    assert r["live_counts"]["/d00/odometry"] >= 5 and r["live_counts"]["/d01/odometry"] >= 5, r["live_counts"]

    # merged: one run, both drones, the accounting complete
    merged = tmp_path / "all.mcap"
    m = subprocess.run([sys.executable, "-m", "aerodaas.cli", "merge", str(main), str(a), str(b), "--out",
                        str(merged)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert m.returncode == 0, m.stderr
    i = subprocess.run([sys.executable, "-m", "aerodaas.cli", "info", str(merged), "--json"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert i.returncode == 0, i.stderr
    info = json.loads(i.stdout)
    tmerged = {c["topic"]: c["count"] for c in info["channels"]}
    for t in ("/d00/odometry", "/d01/odometry", "/d00/camera/cam", "/d01/camera/cam"):
        assert tmerged[t] == ta.get(t, 0) + tb.get(t, 0) > 0, t
    acc = info["accounting"]
    assert acc["lost_total"] == 0, acc
    for t in ("/d00/odometry", "/d01/odometry"):  # every numbered sample of both drones is in the merged run
        c = acc["channels"][t]
        assert c["produced"] - c["duplicates"] == c["recorded"] == tmerged[t], (t, c)
    assert info["mission"]["outcome"] == "success", info["mission"]
