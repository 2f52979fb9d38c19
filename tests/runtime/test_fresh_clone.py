"""The flagship app on a fresh clone (slow tier): ``git clone`` of the committed HEAD into a temporary folder with no
``../shared`` beside it and neither ``AERODAAS_DATA_DIR`` nor ``AERODAAS_MODEL_DIR`` set, then
``aerodaas run apps/vehicle_tracking.py --record`` with the clone's own code: the aerial model, the ground photo
and the car all come from the package, and the recording shows the car detected and followed.

Nothing is installed: the clone's code is put first on ``PYTHONPATH`` (the local Ray's workers inherit it), and the
folders that ``[tool.setuptools.package-dir]`` maps into the package (``actors/`` is ``aerodaas.actors``) are linked
where an install puts them, inside the clone's ``aerodaas/``; without them the editable install of the checkout
under test would serve ``aerodaas.actors`` from there. The test asserts where every one of those modules is
imported from."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from aerodaas.recording.metrics import load_run, tracking_metrics
from aerodaas.recording.reader import summarize_mcap
from tests.conftest import REPO, skip_or_fail

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

#: the packages whose files must come from the clone: the framework, the folders mapped into it, the imagery's home
PACKAGES = ("aerodaas", "aerodaas.actors", "aerodaas.schedulers", "aerodaas.clusters", "aerodaas.sim",
            "aerodaas.perception")


def _clone(dest: Path) -> Path:
    """``git clone --no-hardlinks`` of this checkout's committed HEAD into ``dest``; the package-dir folders linked
    into the clone's ``aerodaas/`` as an install lays them out. Skips (fails in CI) without git or a repository."""
    if shutil.which("git") is None or not (REPO / ".git").exists():
        skip_or_fail("needs git and a git checkout of the repository")
    subprocess.run(["git", "clone", "-q", "--no-hardlinks", str(REPO), str(dest)], check=True, timeout=300)
    mapped = tomllib.loads((dest / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    for name, folder in mapped.items():
        top, _, sub = name.partition(".")
        assert top == "aerodaas" and sub and "." not in sub, name
        (dest / "aerodaas" / sub).symlink_to(dest / folder, target_is_directory=True)
    return dest


def _env(clone: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("AERODAAS_DATA_DIR", "AERODAAS_MODEL_DIR", "PYTHONPATH")}
    env.update(PYTHONPATH=str(clone), AERODAAS_NO_ATTACH="1")
    return env


def test_vehicle_tracking_runs_on_a_fresh_clone_without_shared_data(tmp_path):
    root = tmp_path / "fresh"
    root.mkdir()
    clone = _clone(root / "aerodaas")
    assert not (root / "shared").exists()
    env = _env(clone)

    # every module the run needs is the clone's, not the checkout's that is installed in this venv
    probe = ("import importlib, json; print(json.dumps({n: importlib.import_module(n).__file__ for n in "
             + repr(list(PACKAGES)) + "}))")
    where = json.loads(subprocess.run([sys.executable, "-c", probe], cwd=clone, env=env, capture_output=True,
                                      text=True, check=True, timeout=120).stdout)
    for name, path in where.items():
        assert Path(path).resolve().is_relative_to(clone.resolve()), (name, path)

    rec = tmp_path / "vt.mcap"
    proc = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", "apps/vehicle_tracking.py", "--record",
                           str(rec), "--speedup", "20", "--quiet"], cwd=clone, env=env, capture_output=True,
                          text=True, timeout=540)
    assert proc.returncode == 0, (proc.stdout[-3000:], proc.stderr[-3000:])
    assert "not found" not in proc.stderr, proc.stderr[-3000:]

    s = summarize_mcap(rec)
    assert s["finished"] and s["mission"]["outcome"] == "success", s["mission"]
    run = load_run(str(rec))
    m = tracking_metrics(run, "car1")
    print("fresh clone tracking metrics:", m)
    # as tests/runtime/test_e2e.py asserts of the app: the car found in the frames that hold it, then followed
    assert m["detection_rate"] >= 0.80, m
    assert m["switch_delay_s"] is not None and m["switch_delay_s"] <= 2.0, m
    assert m["tracking_error_m"]["median"] <= 2.0, m
    done = [e["t"] for e in run["events"] if e["event"] == "waypoint_done"]
    assert m["tracking_ended_t"] is not None and max(done) > m["tracking_ended_t"]
