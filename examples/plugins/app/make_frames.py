"""Make the image folder of the ``folder_detect`` app (docs/extending-vehicles.md): four 640x480
views of real nadir photos (imagery/brighton_beach under $AERODAAS_DATA_DIR, a DJI Phantom 3 at about 2 cm a
pixel: crops of 1600x1200 pixels, parked cars in three of them) as JPEGs, and their index ``index.csv`` (image,
capture time in seconds of vehicle time, 1.5 s apart from 3 s on). The photos are read in place, never copied
into the repository.
Run: python make_frames.py FOLDER"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import cv2

#: (photo, crop x, y, width, height in pixels, capture time s)
VIEWS = [("DJI_0031.JPG", 2400, 0, 1600, 1200, 3.0), ("DJI_0028.JPG", 0, 0, 1600, 1200, 4.5),
         ("DJI_0031.JPG", 1200, 600, 1600, 1200, 6.0), ("DJI_0028.JPG", 2400, 0, 1600, 1200, 7.5)]


def make_frames(folder: str | Path, data_dir: str | Path | None = None) -> Path:
    """Write the views and ``index.csv`` into ``folder`` (created); returns the index's path. Raises
    FileNotFoundError naming a photo that is not under ``data_dir`` (default $AERODAAS_DATA_DIR)."""
    src = Path(data_dir or os.environ.get("AERODAAS_DATA_DIR", "")) / "imagery" / "brighton_beach"
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    rows = ["image,capture_t_s"]
    for i, (photo, x, y, w, h, t) in enumerate(VIEWS):
        img = cv2.imread(str(src / photo))
        if img is None:
            raise FileNotFoundError(f"{src / photo}: not found or not readable; set AERODAAS_DATA_DIR")
        view = cv2.resize(img[y:y + h, x:x + w], (640, 480), interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(out / f"view{i}.jpg"), view, [cv2.IMWRITE_JPEG_QUALITY, 95])
        rows.append(f"view{i}.jpg,{t}")
    (out / "index.csv").write_text("\n".join(rows) + "\n")
    return out / "index.csv"


if __name__ == "__main__":
    print(make_frames(sys.argv[1] if len(sys.argv) > 1 else "frames"))
