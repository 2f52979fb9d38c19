"""An application's own environment file with what a test does not look at made cheaper: a camera whose frames the
app never reads dropped, a camera's frame rate lowered where the assertions are per frame or in vehicle seconds.
Run with ``RunOptions.env_path`` (the app file itself unchanged, as ``aerodaas run app.py --env variant.json``)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from aerodaas.config import load_environment_config

from tests.conftest import REPO

__all__ = ["variant_data", "variant_env"]


def variant_data(app: str, *, drop_sensors: tuple[str, ...] = (),
                 camera: dict[str, dict] | None = None) -> tuple[Any, dict]:
    """``apps/<app>.json`` parsed (its imagery paths resolved) and as JSON data with the sensors of ids
    ``drop_sensors`` left out of its first robot and, for each ``camera`` id, those camera properties replaced
    (``{"cam1": {"fps": 5}}``). Returns (the parsed, unchanged environment, the changed data). KeyError naming the id
    when the robot has no such sensor (a test that thinks it drops or changes something it does not)."""
    cfg = load_environment_config(REPO / "apps" / f"{app}.json")
    data = cfg.model_dump(mode="json", exclude={"base_dir"})
    sensors = data["robots"][0]["sensors"]
    ids = [s["id"] for s in sensors]
    for sid in (*drop_sensors, *(camera or {})):
        if sid not in ids:
            raise KeyError(f"apps/{app}.json has no sensor {sid!r} (has {ids})")
    sensors[:] = [s for s in sensors if s["id"] not in drop_sensors]
    for s in sensors:
        s["properties"].update((camera or {}).get(s["id"], {}))
    return cfg, data


def variant_env(app: str, tmp_path: Path, *, drop_sensors: tuple[str, ...] = (),
                camera: dict[str, dict] | None = None) -> Path:
    """:func:`variant_data`'s changed environment written to ``tmp_path``; returns the file's path."""
    path = tmp_path / f"{app}_variant.json"
    path.write_text(json.dumps(variant_data(app, drop_sensors=drop_sensors, camera=camera)[1]))
    return path
