"""The shipped aerial detector (``aerial_nano``): its file is verified by sha256 when loaded, and it is scored on the
committed held-out sample (tests/data/aerial_sample: six frames of flights no training image came from) against the
recall and precision its model card claims for that sample; below them the test fails.

The claims (MODEL_CARD.md, "Committed sample") are the measured values rounded down to 0.05; the detector runs
as the analytics run it (``AerialDetector`` at its ``imgsz`` input size, 736x1280, score threshold 0.3).
"""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import pytest

from aerodaas.perception.scoring import load_annotations, score

SAMPLE = Path(__file__).parents[1] / "data" / "aerial_sample"
NAMES = ["car", "large_vehicle", "person"]
#: (frames, class, input size or None for the model's own, min recall, min precision) at score threshold 0.3
CLAIMS = [
    ("DJI", "car", None, 0.90, 0.65),
    ("DJI", "large_vehicle", None, 0.70, 0.70),
    ("1_", "person", None, 0.35, 0.35),
]


def _scored(prefix: str, cls: str, input_size) -> tuple[float, float, int]:
    from aerodaas.perception.detect import AerialDetector

    det = AerialDetector(score_threshold=0.3, input_size=input_size)
    gts = [g for g in load_annotations(SAMPLE / "labels", SAMPLE / "images", NAMES) if g.file.startswith(prefix)]
    assert gts, f"no sample frame starts with {prefix!r}"
    pairs = [(det.detect(cv2.imread(str(SAMPLE / "images" / g.file))), g) for g in gts]
    s = score(pairs, cls, 0.5)
    return s.recall, s.precision, s.n_gt


@pytest.mark.parametrize("prefix,cls,input_size,min_recall,min_precision", CLAIMS,
                         ids=[f"{c[1]}-{'rgb' if c[0] == 'DJI' else ('thermal-day' if c[0] == '0_' else 'thermal-night')}"
                              for c in CLAIMS])
def test_the_shipped_model_meets_its_card_on_the_held_out_sample(prefix, cls, input_size, min_recall,
                                                                  min_precision):
    recall, precision, n_gt = _scored(prefix, cls, input_size)
    assert n_gt >= 5
    assert recall >= min_recall and precision >= min_precision, (recall, precision, n_gt)


def test_the_shipped_model_is_verified_by_sha256(tmp_path, monkeypatch):
    from aerodaas.perception import model_files

    path = model_files.resolve_model("aerial_nano")
    assert path.parent == model_files.PACKAGED_MODELS_DIR
    assert path.stat().st_size <= 4 * 10**6  # the card's size bound: under 4 MB
    bad = tmp_path / "models"
    bad.mkdir()
    data = bytearray(path.read_bytes())
    data[-100] ^= 0xFF
    (bad / path.name).write_bytes(bytes(data))
    monkeypatch.setattr(model_files, "PACKAGED_MODELS_DIR", bad)
    with pytest.raises(model_files.ModelChecksumError, match="sha256"):
        model_files.resolve_model("aerial_nano")
    shutil.rmtree(bad)
    with pytest.raises(model_files.ModelNotFoundError, match="reinstall"):
        model_files.resolve_model("aerial_nano")


def test_the_model_card_and_data_card_are_beside_the_model():
    from aerodaas.perception.model_files import MODELS, PACKAGED_MODELS_DIR

    card = (PACKAGED_MODELS_DIR / "MODEL_CARD.md").read_text()
    data_card = (PACKAGED_MODELS_DIR / "DATA_CARD.md").read_text()
    assert MODELS["aerial_nano"].sha256 in card
    assert "aerodaas train detector" in card
    for licence in ("CC-BY-4.0", "CC-BY-3.0", "CC-BY-SA-4.0"):
        assert licence in data_card
