"""The pre-label files of a selection, built from its picks' boxes (pixels ``x0, y0, x1, y1`` of each frame):

* :func:`label_studio_tasks`: Label Studio tasks with predictions (Label Studio docs, "Import pre-annotated data
  into Label Studio", ``rectanglelabels``: ``x``, ``y``, ``width``, ``height`` in percent of the image's width and
  height, ``original_width``/``original_height`` in pixels), one per frame, its image referenced as a local file
  (``/data/local-files/?d=<path under LOCAL_FILES_DOCUMENT_ROOT>``) and its bare file name under
  ``data.aerodaas_name``;
* :func:`cvat_xml`: CVAT for images 1.1 (CVAT docs, "CVAT for images" export format: ``<annotations>``,
  ``<version>1.1</version>``, ``<meta><task><labels>``, ``<image id name width height>`` holding
  ``<box label xtl ytl xbr ybr occluded source z_order>`` in pixels), written with :mod:`xml.etree.ElementTree`;
* :func:`coco_json`: COCO detection JSON (Lin et al., "Microsoft COCO", ECCV 2014; the format CVAT calls COCO 1.0:
  ``images``, ``annotations`` with ``bbox`` ``[x, y, width, height]`` pixels and ``area``, ``categories`` numbered
  from 1), each annotation with the detector's ``score``; ``file_name`` is ``images/<name>.jpg``, relative to the
  folder holding the file (what ``aerodaas train detector --data DIR/coco.json`` reads).
"""
from __future__ import annotations

import urllib.parse
import xml.etree.ElementTree as ET
from typing import Sequence

from aerodaas.labelling.select import Candidate

__all__ = ["label_studio_tasks", "cvat_xml", "coco_json", "image_file"]


def image_file(c: Candidate) -> str:
    """The file name a pick is written under: ``<name>.jpg``."""
    return f"{c.ref.name}.jpg"


def _clip(c: Candidate, box) -> tuple[float, float, float, float]:
    x0, y0, x1, y1 = (float(v) for v in box)
    return (min(max(x0, 0.0), c.width), min(max(y0, 0.0), c.height),
            min(max(x1, 0.0), c.width), min(max(y1, 0.0), c.height))


def label_studio_tasks(picks: Sequence[Candidate], images_url_path: str, model_version: str) -> list[dict]:
    """One Label Studio task per pick (module docstring). ``images_url_path``: the images folder relative to Label
    Studio's ``LOCAL_FILES_DOCUMENT_ROOT`` (``/``-separated, percent-encoded here). A task's prediction ``score``
    is the mean of its boxes' scores (0 without boxes)."""
    prefix = urllib.parse.quote(images_url_path.strip("/"), safe="/")
    tasks = []
    for i, c in enumerate(picks):
        name = image_file(c)
        result = []
        for k, d in enumerate(c.boxes or []):
            x0, y0, x1, y1 = _clip(c, d.box)
            result.append({
                "id": f"f{i}b{k}", "type": "rectanglelabels", "from_name": "label", "to_name": "image",
                "original_width": c.width, "original_height": c.height, "image_rotation": 0,
                "value": {"x": 100.0 * x0 / c.width, "y": 100.0 * y0 / c.height,
                          "width": 100.0 * (x1 - x0) / c.width, "height": 100.0 * (y1 - y0) / c.height,
                          "rotation": 0, "rectanglelabels": [d.class_name]},
                "score": float(d.score)})
        mean = sum(r["score"] for r in result) / len(result) if result else 0.0
        tasks.append({"data": {"image": f"/data/local-files/?d={prefix}/{urllib.parse.quote(name)}",
                               "aerodaas_name": name},
                      "predictions": [{"model_version": model_version, "score": mean, "result": result}]})
    return tasks


def cvat_xml(picks: Sequence[Candidate], classes: Sequence[str], task_name: str) -> ET.ElementTree:
    """CVAT for images 1.1 annotations of the picks (module docstring); ``classes``: the labels, in order."""
    root = ET.Element("annotations")
    ET.SubElement(root, "version").text = "1.1"
    task = ET.SubElement(ET.SubElement(root, "meta"), "task")
    ET.SubElement(task, "name").text = task_name
    ET.SubElement(task, "size").text = str(len(picks))
    ET.SubElement(task, "mode").text = "annotation"
    labels = ET.SubElement(task, "labels")
    for n in classes:
        lab = ET.SubElement(labels, "label")
        ET.SubElement(lab, "name").text = n
        ET.SubElement(lab, "type").text = "rectangle"
        ET.SubElement(lab, "attributes")
    for i, c in enumerate(picks):
        img = ET.SubElement(root, "image", id=str(i), name=image_file(c), width=str(c.width), height=str(c.height))
        for d in c.boxes or []:
            x0, y0, x1, y1 = _clip(c, d.box)
            ET.SubElement(img, "box", label=d.class_name, source="auto", occluded="0", xtl=f"{x0:.2f}",
                          ytl=f"{y0:.2f}", xbr=f"{x1:.2f}", ybr=f"{y1:.2f}", z_order="0")
    ET.indent(root)
    return ET.ElementTree(root)


def coco_json(picks: Sequence[Candidate], classes: Sequence[str]) -> dict:
    """COCO detection JSON of the picks (module docstring); categories are ``classes`` numbered from 1."""
    cat = {n: i + 1 for i, n in enumerate(classes)}
    images, anns = [], []
    for i, c in enumerate(picks):
        images.append({"id": i + 1, "file_name": f"images/{image_file(c)}", "width": c.width, "height": c.height})
        for d in c.boxes or []:
            x0, y0, x1, y1 = _clip(c, d.box)
            anns.append({"id": len(anns) + 1, "image_id": i + 1, "category_id": cat[d.class_name],
                         "bbox": [x0, y0, x1 - x0, y1 - y0], "area": (x1 - x0) * (y1 - y0), "iscrowd": 0,
                         "score": float(d.score)})
    return {"info": {"description": "aerodaas label frames: pre-labels"}, "licenses": [], "images": images,
            "annotations": anns,
            "categories": [{"id": i, "name": n, "supercategory": ""} for n, i in cat.items()]}
