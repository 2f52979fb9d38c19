"""Frame file names map back to ``<flight>_<camera>`` through the training loader's sequence rule, for every flight
name, those ending in digits (``DJI_0025``) included."""
from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aerodaas.labelling.names import clean_name, flight_of, frame_name
from aerodaas.training.labels.images import sequence_of


@pytest.mark.parametrize("stem", ["DJI_0025", "DJI-0025", "flight 12", "2024-05-01_07", "a.b.c-7", "run_", "___",
                                  "0", "Ölüdeniz 3", "x" * 40 + "9"])
def test_a_written_name_maps_back_to_its_flight_and_camera(stem):
    flight = flight_of(f"/footage/{stem}.MP4")
    for camera in ("video", "drone1-cam0", "0", "cam_1."):
        for frame in (0, 7, 123456, 1234567):
            name = frame_name(flight, camera, frame)
            assert sequence_of(Path(f"{name}.jpg")) == f"{flight}_{clean_name(camera, 'cam')}", (stem, camera, frame)
            assert name.endswith(f"-{frame:06d}") and name.count("_") == 1


def test_two_frames_of_one_flight_share_a_sequence_and_two_flights_do_not():
    a0, a1 = frame_name(flight_of("DJI_0025.mp4"), "video", 0), frame_name(flight_of("DJI_0025.mp4"), "video", 99)
    b0 = frame_name(flight_of("DJI_0026.mp4"), "video", 0)
    assert sequence_of(Path(a0)) == sequence_of(Path(a1)) != sequence_of(Path(b0))


@settings(max_examples=100, deadline=None)
@given(st.text(min_size=0, max_size=30), st.text(min_size=0, max_size=12), st.integers(0, 10**7))
def test_any_flight_and_camera_text_round_trips(stem, camera, frame):
    flight = clean_name(stem, "flight")
    name = frame_name(flight, camera, frame)
    assert sequence_of(Path(name + ".jpg")) == f"{flight}_{clean_name(camera, 'cam')}"


def test_a_negative_frame_number_is_refused():
    with pytest.raises(ValueError, match="-1"):
        frame_name("f", "c", -1)
