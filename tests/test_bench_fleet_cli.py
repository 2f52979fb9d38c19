"""``aerodaas bench fleet``'s outputs (the benchmark itself is replaced by a canned report: no Ray, no timing)."""
from __future__ import annotations

import json

import pytest

from aerodaas import cli
from aerodaas.bench import fleet


def _report(sizes, duration_s, groupings=(1,), edge_nodes=1):
    rows = [{"drones": n, "drones_per_actor": k, "missed_ticks_pct": 0.1 * n, "dropped_frames_pct": 1.0,
             "cpu_pct": 20.0 * n, "rss_mb": 900.0 + 40 * n / k, "pss_mb": 700.0 + 30 * n / k}
            for k in groupings for n in sizes]
    return {"benchmark": "fleet", "machine": {"cpu_count": 2}, "duration_s": duration_s, "results": rows}


@pytest.fixture
def canned(monkeypatch, tmp_path):
    monkeypatch.setattr(fleet, "run_fleet", _report)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_json_also_writes_fleet_png_in_the_current_directory(canned, capsys):
    assert cli.main(["bench", "fleet", "--json", "--drones", "1", "--drones", "5", "--duration", "1"]) == 0
    png = canned / "fleet.png"
    assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    out = capsys.readouterr()
    assert json.loads(out.out)["plot"] == str(png)
    assert f"curve written to {png}" in out.err


def test_plot_and_out_choose_where_the_curve_goes(canned):
    (canned / "r").mkdir()
    assert cli.main(["bench", "fleet", "--drones", "1", "--duration", "1", "--out", "r/run.json"]) == 0
    assert (canned / "r" / "run.png").is_file() and not (canned / "fleet.png").exists()
    assert json.loads((canned / "r" / "run.json").read_text())["plot"] == str(canned / "r" / "run.png")
    assert cli.main(["bench", "fleet", "--drones", "1", "--duration", "1", "--plot", "curve.png"]) == 0
    assert (canned / "curve.png").is_file() and not (canned / "fleet.png").exists()
