"""Analytics ``gas_plume``: a non-navigable analytics with a typed output, a named output and events.

It watches a drone's gas readings and tells, per reading, whether the drone is inside the plume: it enters when a
reading reaches ``enter_ppm`` and leaves when one falls below ``exit_ppm`` (hysteresis, so that noise at the edge
does not flicker). It declares

* ``Output = PlumeStatus``: one status per reading, recorded on ``/<robot>/gas_plume`` with the JSON Schema of
  :class:`PlumeStatus`;
* ``named_outputs = {"crossing": PlumeCrossing}``: one message per crossing of the plume (when the drone leaves it),
  recorded on ``/<robot>/gas_plume/crossing``; another analytics subscribes with
  ``tracker.output_stream("crossing")``;
* the events ``plume_entered`` and ``plume_left`` (``emit_event``), recorded on ``/<robot>/events`` beside the
  drone's own events, shown in the live view and counted in the run's summary;
* ``consumes = (GasReading,)``: fed anything but a gas sensor's stream, the application is refused when it is
  loaded, before Ray starts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from pydantic import BaseModel, Field, model_validator

from aerodaas.analytics.core import Analytics

from aerodaas_example_plugins.gas import GasReading


class PlumeConfig(BaseModel):
    """Thresholds in ppm: enter at ``enter_ppm`` or above, leave below ``exit_ppm``."""

    enter_ppm: float = Field(default=30.0, gt=0)
    exit_ppm: float = Field(default=15.0, ge=0)

    @model_validator(mode="after")
    def _hysteresis(self) -> "PlumeConfig":
        if self.exit_ppm > self.enter_ppm:
            raise ValueError(f"exit_ppm {self.exit_ppm} must not exceed enter_ppm {self.enter_ppm}")
        return self


class PlumeStatus(BaseModel):
    """One gas reading's verdict."""

    robot: str
    t: float = Field(description="vehicle time of the reading, s")
    ppm: float = Field(description="the reading, parts per million")
    inside: bool = Field(description="the drone is inside the plume after this reading")
    peak_ppm: float = Field(description="highest reading of the current crossing, ppm (0 outside the plume)")


class PlumeCrossing(BaseModel):
    """One crossing of the plume, from the reading that entered it to the one that left it."""

    robot: str
    entered_t: float = Field(description="vehicle time of the entering reading, s")
    left_t: float = Field(description="vehicle time of the leaving reading, s")
    peak_ppm: float = Field(description="highest reading inside, ppm")
    peak_position: list[float] = Field(description="where it was read, ENU metres from home")
    width_m: float = Field(description="horizontal distance from the entering to the leaving reading, metres")


@dataclass
class _Crossing:
    inside: bool = False
    entered_t: float = 0.0
    entered_at: list[float] = field(default_factory=list)
    peak_ppm: float = 0.0
    peak_at: list[float] = field(default_factory=list)


class PlumeTracker(Analytics):
    """See the module docstring. One state per drone (``drone_state``): drones may share it."""

    plugin_kind = "analytics"
    name = "gas_plume"
    Config = PlumeConfig
    consumes = (GasReading,)
    Output = PlumeStatus
    named_outputs = {"crossing": PlumeCrossing}

    def __init__(self, name: str | None = None, **settings) -> None:
        super().__init__(name)
        self.config = PlumeConfig(**settings)

    def process(self, data: dict, meta) -> PlumeStatus:
        c = self.config
        st = self.drone_state(data, meta, _Crossing)
        ppm, pos, t = float(data["ppm"]), list(data["position"]), float(data["t"])
        if not st.inside and ppm >= c.enter_ppm:
            st.inside, st.entered_t, st.entered_at, st.peak_ppm, st.peak_at = True, t, pos, ppm, pos
            self.emit_event("plume_entered", ppm=ppm, position=pos, enter_ppm=c.enter_ppm)
        elif st.inside and ppm < c.exit_ppm:
            width = math.dist(st.entered_at[:2], pos[:2])
            self.emit("crossing", PlumeCrossing(robot=data["robot"], entered_t=st.entered_t, left_t=t,
                                                peak_ppm=st.peak_ppm, peak_position=st.peak_at, width_m=width))
            self.emit_event("plume_left", ppm=ppm, position=pos, peak_ppm=st.peak_ppm, width_m=width)
            st.inside, st.peak_ppm = False, 0.0
        elif st.inside and ppm > st.peak_ppm:
            st.peak_ppm, st.peak_at = ppm, pos
        return PlumeStatus(robot=data["robot"], t=t, ppm=ppm, inside=st.inside, peak_ppm=st.peak_ppm)
