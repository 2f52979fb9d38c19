"""The model ``aerodaas train detector`` starts from: the shipped aerial model when it already knows every class of
the run, else the COCO YOLOX-Nano, or ``--base-model``; one that cannot be found is the whole answer, exit 2,
before anything trains (the command runs in-process, as ``aerodaas`` would)."""
from __future__ import annotations

import socket
from pathlib import Path

import pytest

from aerodaas.cli import main
from aerodaas.model.types import COCO_CLASSES
from aerodaas.training.base import choose_base
from tests.conftest import needs_data
from tests.training.exports import frames, write_ls_yolo


def _closed_port() -> int:
    """A loopback port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def offline(tmp_path, monkeypatch) -> Path:
    """No model folder, an empty cache, and every download refused on loopback (a proxy nobody listens on)."""
    monkeypatch.setenv("AERODAAS_MODEL_DIR", str(tmp_path / "no-models"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    proxy = f"http://127.0.0.1:{_closed_port()}"
    for var in ("https_proxy", "HTTPS_PROXY", "http_proxy", "HTTP_PROXY"):
        monkeypatch.setenv(var, proxy)
    for var in ("no_proxy", "NO_PROXY"):
        monkeypatch.delenv(var, raising=False)
    return tmp_path


def _boat_set(root: Path) -> Path:
    """A Label Studio YOLO export whose classes are not all the aerial model's (a boat)."""
    write_ls_yolo(root, frames(), with_images=True)
    (root / "classes.txt").write_text("car\nboat\n")
    return root


def test_without_a_reachable_base_model_the_message_is_the_answer(offline, capsys):
    data, out = _boat_set(offline / "set"), offline / "run"
    rc = main(["train", "detector", "--data", str(data), "--out", str(out), "--epochs", "1"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("error: model 'yolox_nano' (yolox_nano.onnx) not found"), err
    assert "AERODAAS_MODEL_DIR" in err and "Traceback" not in err and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_a_base_model_path_that_is_no_file_is_named(offline, capsys):
    data = _boat_set(offline / "set")
    rc = main(["train", "detector", "--data", str(data), "--out", str(offline / "run"),
               "--base-model", str(offline / "mine.onnx")])
    err = capsys.readouterr().err
    assert rc == 2 and f"--base-model={str(offline / 'mine.onnx')!r}: no such file" in err, err


def test_a_base_model_that_is_no_yolox_detector_is_named(offline, capsys):
    data, bad = _boat_set(offline / "set"), offline / "notes.onnx"
    bad.write_bytes(b"not a model")
    rc = main(["train", "detector", "--data", str(data), "--out", str(offline / "run"), "--base-model", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and f"--base-model={str(bad)!r}: not a YOLOX ONNX detector" in err, err


def test_the_shipped_aerial_model_is_the_base_when_it_knows_every_class(offline):
    """Offline: the aerial model is installed with the package, so a run of its classes needs no download."""
    base = choose_base(None, ["person", "car"])
    assert base.name == "aerial_nano" and base.path.name == "aerial_nano.onnx"
    assert base.rows == [base.class_names.index("person"), base.class_names.index("car")]
    assert "aerial" in base.why


@needs_data
def test_the_coco_model_is_the_base_for_a_class_the_aerial_model_lacks():
    base = choose_base(None, ["car", "boat"])
    assert base.name == "yolox_nano" and base.class_names == list(COCO_CLASSES)
    assert base.rows == [COCO_CLASSES.index("car"), COCO_CLASSES.index("boat")]
    assert "['boat']" in base.why
    # an --init-from source the aerial model lacks also starts from the COCO model
    assert choose_base(None, ["car"], {"car": "truck"}).rows == [COCO_CLASSES.index("truck")]
    # --base-model yolox_nano: the COCO model by name, whatever the classes
    named = choose_base(Path("yolox_nano"), ["car"])
    assert named.path == base.path and named.rows == [COCO_CLASSES.index("car")] and named.why == "--base-model"
