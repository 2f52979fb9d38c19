"""Analytics ``gas_threshold``: turns gas readings into a navigation command.

When a drone's reading rises above ``hover_ppm`` it hovers where it is for ``hover_s`` seconds (a waypoint at
the reading's position, priority over the survey), once per plume: it re-arms after the reading fell below
``rearm_ppm``. Above ``return_ppm`` it returns to launch instead (``ActionCommand("rtl")``).
"""
from __future__ import annotations

from dataclasses import dataclass

from pydantic import BaseModel, Field

from aerodaas.analytics.core import NavigableAnalytics
from aerodaas.model.types import ActionCommand, AeroNavigation, NavigationType, SchedulingType, Waypoint


class GasThresholdConfig(BaseModel):
    """Thresholds in ppm, hover time in seconds."""

    hover_ppm: float = Field(default=50.0, gt=0)
    rearm_ppm: float = Field(default=40.0, ge=0)
    return_ppm: float = Field(default=1e9, gt=0)
    hover_s: float = Field(default=3.0, ge=0, le=600)


@dataclass
class _State:
    armed: bool = True
    hovers: int = 0


class GasThreshold(NavigableAnalytics):
    """See the module docstring. Consumes ``gas_concentration`` readings (dicts with ``robot``, ``ppm``,
    ``position``); produces an AeroNavigation (ANALYTICS_DRIVEN, ORDERED) or nothing."""

    plugin_kind = "analytics"
    name = "gas_threshold"
    Config = GasThresholdConfig
    consumes = ("gas_concentration",)
    produces = (AeroNavigation,)

    def __init__(self, **settings) -> None:
        super().__init__()
        self.config = GasThresholdConfig(**settings)

    def generate_navigation(self, data, meta):
        c = self.config
        st = self.drone_state(data, meta, _State)
        ppm = float(data["ppm"])
        if ppm >= c.return_ppm:
            return AeroNavigation(NavigationType.ANALYTICS_DRIVEN,
                                  [ActionCommand(action="rtl", reason=f"gas {ppm:.0f} ppm")], SchedulingType.ORDERED)
        if not st.armed:
            st.armed = ppm < c.rearm_ppm
            return None
        if ppm < c.hover_ppm:
            return None
        st.armed = False
        st.hovers += 1
        x, y, z = data["position"]
        wp = Waypoint(id=f"gas-hover-{st.hovers}", x=x, y=y, z=z, hover_duration=c.hover_s)
        return AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [wp], SchedulingType.ORDERED)
