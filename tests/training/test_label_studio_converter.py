"""Label Studio's own converter (label_studio_sdk, in the Label Studio 1.23.2 install beside the project, run as a
subprocess: it is never installed into the project's Python) writes the YOLO and COCO exports of a small project
of uploaded frames, with and without the images, as the Label Studio server does when one exports; each loads as
it is, every box in pixels where it was drawn, every frame in its flight's video.

The server's upload folder is removed before loading: an export is unpacked elsewhere, where the COCO
``file_name`` (relative to the server's temporary folder) no longer resolves."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from aerodaas.training.dataset import load_set
from tests.conftest import skip_or_fail
from tests.training.exports import LS_CONFIG, assert_loaded, frames, ls_tasks, write_jpeg

LS_HOME = Path(os.environ.get("AERODAAS_LABEL_STUDIO", "/root/.cache/aerodaas/label-studio-1.23.2"))
LS_PYTHON = LS_HOME / "bin" / "python"
FORMATS = ("YOLO", "YOLO_WITH_IMAGES", "COCO", "COCO_WITH_IMAGES")
#: what the server does on export (label_studio/data_export/models.py: ``Converter(config, project_dir=None,
#: upload_dir=<media>/upload, download_resources=...)``, then ``convert(input_json, out, format, is_dir=False)``)
_CONVERT = """
import sys
from label_studio_sdk.converter import Converter
config, tasks, upload, out = sys.argv[1:5]
for fmt in sys.argv[5:]:
    Converter(config=config, project_dir=None, upload_dir=upload,
              download_resources=fmt.endswith("_WITH_IMAGES")).convert(tasks, f"{out}/{fmt}", fmt, is_dir=False)
"""


@pytest.fixture(scope="module")
def exports(tmp_path_factory) -> Path:
    """The four exports of one project, made by Label Studio's converter."""
    if not LS_PYTHON.is_file():
        skip_or_fail(f"Label Studio 1.23.2 is not installed at {LS_PYTHON.parent.parent} (its converter writes the "
                     f"exports this test reads; set AERODAAS_LABEL_STUDIO)")
    tmp = tmp_path_factory.mktemp("ls")
    upload = tmp / "media" / "upload"
    for f in frames():
        write_jpeg(upload / "1" / f.uploaded, f)
    (tmp / "config.xml").write_text(LS_CONFIG)
    (tmp / "project-1.json").write_text(json.dumps(ls_tasks(frames())))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("LABEL_STUDIO_", "PYTHON"))}
    r = subprocess.run([str(LS_PYTHON), "-c", _CONVERT, str(tmp / "config.xml"), str(tmp / "project-1.json"),
                        str(upload), str(tmp / "out"), *FORMATS], capture_output=True, text=True, env=env, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    shutil.rmtree(tmp / "media")  # the server's files stay on the server
    return tmp / "out"


@pytest.mark.parametrize("fmt", FORMATS)
def test_label_studio_export_loads_as_written(exports, tmp_path, fmt):
    root = shutil.copytree(exports / fmt, tmp_path / fmt)
    assert (root / ("result.json" if fmt.startswith("COCO") else "notes.json")).is_file()
    if not fmt.endswith("_WITH_IMAGES"):  # exported without images: the user copies the frames into images/
        assert not any((root / "images").iterdir())
        for f in frames():
            write_jpeg(root / "images" / f.name, f)
    assert_loaded(*load_set(root), frames())
