"""Shared fixtures: one local Ray session for every test that needs it, and the shared data location."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA_DIR = Path(os.environ.get("AERODAAS_DATA_DIR", REPO.parent / "shared" / "data")).resolve()
MODEL_DIR = Path(os.environ.get("AERODAAS_MODEL_DIR", DATA_DIR / "models")).resolve()

# a test's `aerodaas run` starts a Ray of its own: never attach to a cluster of `aerodaas up` that the developer left
# running (its workers would run that cluster's installed code, not this checkout's); the tests of `up` itself and
# `bench startup --mode attached` use a private AERODAAS_STATE_DIR and clear this
os.environ.setdefault("AERODAAS_NO_ATTACH", "1")

needs_data = pytest.mark.skipif(not (DATA_DIR / "imagery").is_dir() or not (MODEL_DIR / "yolox_nano.onnx").is_file(),
                                reason=f"shared data not found at {DATA_DIR} (set AERODAAS_DATA_DIR / AERODAAS_MODEL_DIR)")


#: the groups that the development tier leaves out: real firmware, `ray up`, multi-node clusters and fault runs
SLOW_GROUPS = ("sitl", "rayup", "cluster", "faults")


def pytest_collection_modifyitems(config, items):
    """Mark every test of a slow group ``slow`` too, so that ``pytest -m "not slow"`` is the development tier
    (everything but SITL, ``ray up``, cluster and fault runs); CI runs everything."""
    for item in items:
        if any(item.get_closest_marker(g) for g in SLOW_GROUPS):
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="session")
def ray_session():
    """A local Ray with this node labelled tier=edge (token auth on), shared by all e2e tests."""
    from aerodaas.runtime import driver as runtime

    runtime.ensure_ray(None)
    yield
    runtime.shutdown_ray()


@pytest.fixture
def run_options(tmp_path):
    """Reset the runtime's CLI options around a test."""
    from aerodaas.runtime import driver as runtime

    saved = runtime.RunOptions(**vars(runtime.OPTIONS))
    runtime.OPTIONS.progress = False
    yield runtime.OPTIONS
    for k, v in vars(saved).items():
        setattr(runtime.OPTIONS, k, v)


@pytest.fixture
def data_env(monkeypatch):
    monkeypatch.setenv("AERODAAS_DATA_DIR", str(DATA_DIR))
    monkeypatch.setenv("AERODAAS_MODEL_DIR", str(MODEL_DIR))
