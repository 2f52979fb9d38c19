"""A Foxglove layout for AeroDaaS runs, built with the ``foxglove-sdk`` package's layout types (``foxglove.layouts``,
https://docs.foxglove.dev/docs/visualization/layouts), so the JSON is the format the Foxglove app imports
("Layouts" -> "Import from file").

Panels: the camera with its detections (and the track ids of a tracking analytics) overlaid and its calibration
(Image), the vehicle in 3-D with the transform tree, its camera frustum, its pose and the geo-located tracks (3D),
the GPS track and each track's position (Map), the mission state over time (State Transitions),
battery percent and altitude (Plot) and the robot's events (Raw Messages). Topics follow the recorder's names
(``/<robot>/camera/<sensor>``, ``/<robot>/<analytics>/detections``, ``/<robot>/gps``, ``/<robot>/pose``, ``/tf``,
``/mission/state``, ``/<robot>/odometry``, ``/<robot>/events``; tracks under ``/<robot>/<analytics>/tracks``, see
:mod:`aerodaas.perception.track_records`). ``docs/foxglove-layout.json`` is
:func:`build_layout` for ``apps/vehicle_tracking.py``; ``aerodaas layout RUN.mcap`` writes one for any recording.
"""
from __future__ import annotations

import json
import os
from typing import Any

__all__ = ["build_layout", "layout_for_recording"]


def build_layout(robot: str, camera: str | None = None, detections: list[str] | None = None,
                 tracks: list[str] | None = None, fixes: list[str] | None = None) -> dict[str, Any]:
    """The layout (a JSON-ready dict, Foxglove layout ``version`` 1) for ``robot``'s camera sensor ``camera`` (None:
    no camera panel) with the ``foxglove.ImageAnnotations`` topics ``detections`` overlaid. ``tracks``: topic
    prefixes of tracking analytics (``/<robot>/<analytics>/tracks``): their image annotations join the camera, their
    ``/scene`` the 3D panel and their ``/fixes`` (``foxglove.LocationFixes``, every track's position) the Map panel;
    ``fixes``: further ``LocationFix``/``LocationFixes`` topics for the Map panel."""
    import foxglove.layouts as fl  # lazy: heavy foxglove

    tracks = list(tracks or [])
    detections = list(detections or []) + [t for t in tracks if t not in (detections or [])]
    image_topic = f"/{robot}/camera/{camera}" if camera else None
    base, cam_frame = f"{robot}/base_link", f"{robot}/{camera}" if camera else None
    image = fl.ImagePanel(title=f"{robot} camera + detections", config=fl.ImageConfig(image_mode=fl.ImageModeConfig(
        image_topic=image_topic, calibration_topic=f"{image_topic}/calibration" if camera else None,
        annotations={t: fl.ImageAnnotationSettings(visible=True) for t in detections or []})))
    three_d_topics: dict[str, Any] = {f"/{robot}/pose": fl.BaseRendererPoseTopicSettings(visible=True, type="arrow")}
    if camera:
        three_d_topics[f"{image_topic}/calibration"] = fl.BaseRendererCameraTopicSettings(visible=True, distance=2.0)
        three_d_topics[image_topic] = fl.BaseRendererImageTopicSettings(visible=True,
                                                                         camera_info_topic=f"{image_topic}/calibration")
    for p in tracks:
        three_d_topics[f"{p}/scene"] = fl.BaseRendererSceneUpdateTopicSettings(visible=True)
    three_d = fl.ThreeDeePanel(title="3D: enu -> base_link -> camera", config=fl.ThreeDeeConfig(
        follow_tf=base, fixed_frame="enu", follow_mode="follow-position", topics=three_d_topics))
    gps = f"/{robot}/gps"
    map_topics = {gps: fl.MapTopicSettings(history_mode="all")}
    map_topics.update({f: fl.MapTopicSettings(history_mode="all", point_display_mode="dot")
                       for f in [f"{p}/fixes" for p in tracks] + list(fixes or [])})
    map_panel = fl.MapPanel(title=f"{robot} GPS" + (" + tracks" if tracks else ""), config=fl.MapConfig(
        follow_topic=gps, layer="map", topic_config=map_topics))
    states = fl.StateTransitionsPanel(title="mission state", config=fl.StateTransitionsConfig(paths=[
        fl.StateTransitionsSeries(value=f'/mission/state{{robot=="{robot}"}}.state', label=f"{robot} state")]))
    odom = f"/{robot}/odometry"
    plot = fl.PlotPanel(title="battery % and altitude (m)", config=fl.PlotConfig(show_legend=True, paths=[
        fl.PlotSeries(value=f"{odom}.battery_pct", label="battery %"),
        fl.PlotSeries(value=f"{odom}.position[2]", label="altitude above home, m", use_right_y_axis=True)]))
    events = fl.RawMessagesPanel(title=f"{robot} events", config=fl.RawMessagesConfig(topic_path=f"/{robot}/events"))

    def split(direction: str, *items: tuple[float, Any]) -> Any:
        return fl.SplitContainer(direction=direction, items=[fl.SplitItem(proportion=p, content=c) for p, c in items])

    top = split("row", *([(1.2, image)] if camera else []), (1.0, three_d), (0.8, map_panel))
    bottom = split("row", (1.0, states), (1.0, plot), (0.7, events))
    return json.loads(fl.Layout(content=split("column", (2.0, top), (1.0, bottom))).to_json())


def layout_for_recording(path: str | os.PathLike) -> dict[str, Any]:
    """:func:`build_layout` for the first robot of a recording that has a pose channel, its first camera, every
    detections channel of that robot and its recorded tracks (read from the file's channels). Raises ValueError when
    the recording has no robot pose channel, ``FileNotFoundError`` when it does not exist."""
    from aerodaas.recording.reader import summarize_mcap  # lazy: heavy cv2, mcap, numpy, protobuf, pydantic

    chans = summarize_mcap(path)["channels"]
    robots = [c["topic"].split("/")[1] for c in chans if c["schema"] == "foxglove.PoseInFrame"
              and c["topic"].count("/") == 2 and c["topic"].endswith("/pose")]
    if not robots:
        raise ValueError(f"{str(path)!r}: no /<robot>/pose channel, is it an AeroDaaS recording?")
    robot = robots[0]
    cams = [c["topic"].split("/")[3] for c in chans if c["schema"] == "foxglove.CompressedImage"
            and c["topic"].startswith(f"/{robot}/camera/") and c["topic"].count("/") == 3]
    dets = [c["topic"] for c in chans if c["schema"] == "foxglove.ImageAnnotations" and c["topic"].startswith(f"/{robot}/")]
    tracks = [c["topic"][:-len("/scene")] for c in chans if c["schema"] == "foxglove.SceneUpdate"
              and c["topic"].startswith(f"/{robot}/") and c["topic"].endswith("/tracks/scene")]
    return build_layout(robot, cams[0] if cams else None, [d for d in dets if d not in tracks], tracks)
