"""Geofence models and geometry (aerodaas.navigation.geofence): QGroundControl/PX4 semantics in local ENU metres."""
from __future__ import annotations

import pytest
from pydantic import ValidationError

from aerodaas.model.geo import enu_to_geodetic
from aerodaas.navigation.geofence import Geofence, GeofenceCircle, GeofenceConfig, GeofencePolygon
from aerodaas.model.types import GeoPoint

HOME = GeoPoint(lat=47.397742, lon=8.545594, alt=488.0)


def ll(x: float, y: float) -> tuple[float, float]:
    """(lat, lon) of the ENU point (x east, y north) metres from HOME."""
    g = enu_to_geodetic(x, y, 0.0, HOME)
    return (g.lat, g.lon)


def square(cx: float, cy: float, half: float) -> list[tuple[float, float]]:
    """Clockwise (as QGroundControl draws) square of side 2*half centred at ENU (cx, cy), as (lat, lon)."""
    return [ll(cx - half, cy + half), ll(cx + half, cy + half), ll(cx + half, cy - half), ll(cx - half, cy - half)]


@pytest.fixture
def fence() -> Geofence:
    """Inclusion square 100 m x 100 m around home; exclusion square 20 m at (30, 30); exclusion circle r=10 m at
    (-30, -30)."""
    cfg = GeofenceConfig(
        polygons=[GeofencePolygon(points=square(0, 0, 50), inclusion=True),
                  GeofencePolygon(points=square(30, 30, 10), inclusion=False)],
        circles=[GeofenceCircle(center=ll(-30, -30), radius=10.0, inclusion=False)],
    )
    return Geofence(cfg, HOME)


def test_points_inside_and_outside_polygons_and_circles(fence):
    assert fence.check_point(0, 0) is None and fence.contains(0, 0)
    assert fence.check_point(45, -45) is None
    assert fence.check_point(60, 0) == "outside inclusion polygon 0"
    assert not fence.contains(60, 0)
    assert fence.check_point(30, 30) == "inside exclusion polygon 1"
    assert fence.check_point(35, 25) == "inside exclusion polygon 1"
    assert fence.check_point(-30, -30) == "inside exclusion circle 0 (radius 10 m)"
    assert fence.check_point(-30, -38) == "inside exclusion circle 0 (radius 10 m)"
    assert fence.check_point(-30, -41) is None  # 11 m from the centre: outside the no-fly circle
    assert fence.check_point(-38, -38) is None  # 11.3 m diagonally


def test_boundaries_are_allowed(fence):
    assert fence.check_point(49.9999, 0) is None  # just inside the inclusion edge
    assert fence.check_point(50.0001, 0) == "outside inclusion polygon 0"
    assert fence.check_point(40.0, 30.0) is None  # on the exclusion square's east edge
    assert fence.check_point(39.9, 30.0) == "inside exclusion polygon 1"


def test_leg_crossing_exclusion_polygon_with_both_ends_outside_it(fence):
    assert fence.check_point(15, 30) is None and fence.check_point(45, 30) is None
    assert fence.check_segment((15, 30), (45, 30)) == "leg crosses exclusion polygon 1"
    # a leg passing beside the zone, and one running exactly along its edge, are fine
    assert fence.check_segment((15, 45), (45, 45)) is None
    assert fence.check_segment((40, 10), (40, 45)) is None


def test_leg_crossing_exclusion_circle_with_both_ends_outside_it(fence):
    assert fence.check_segment((-45, -30), (-15, -30)) == "leg crosses exclusion circle 0 (radius 10 m)"
    assert fence.check_segment((-45, -19), (-15, -19)) is None  # passes 11 m from the centre


def test_leg_leaving_the_inclusion_zone(fence):
    reason = fence.check_segment((0, 0), (70, 0))
    assert reason == "leg leaves inclusion polygon 0 at (50.0, 0.0) m"
    assert fence.check_segment((0, 0), (49, -49)) is None  # the diagonal to (49, 49) would cross the no-fly square


def test_leg_between_two_inclusion_zones_must_stay_covered():
    cfg = GeofenceConfig(polygons=[GeofencePolygon(points=square(0, 0, 50))],
                         circles=[GeofenceCircle(center=ll(120, 0), radius=30.0)])
    f = Geofence(cfg, HOME)
    assert f.check_point(0, 0) is None and f.check_point(120, 0) is None
    reason = f.check_segment((0, 0), (120, 0))  # both ends allowed, the middle (50..90 m east) is not
    assert reason is not None and reason.startswith("leg leaves every inclusion zone")
    assert "inclusion polygon 0" in reason and "inclusion circle 0 (radius 30 m)" in reason
    assert "(50.0, 0.0) m" in reason
    assert f.check_point(70, 0) == ("outside every inclusion zone (inclusion polygon 0, inclusion circle 0 "
                                    "(radius 30 m))")


def test_adjacent_inclusion_polygons_cover_a_leg_across_their_shared_edge():
    west = [ll(-100, 50), ll(0, 50), ll(0, -50), ll(-100, -50)]
    east = [ll(0, 50), ll(100, 50), ll(100, -50), ll(0, -50)]
    f = Geofence(GeofenceConfig(polygons=[GeofencePolygon(points=west), GeofencePolygon(points=east)]), HOME)
    assert f.check_segment((-90, 10), (90, -10)) is None
    assert f.check_segment((-90, 10), (110, 10)) is not None


def test_empty_config_allows_everything():
    f = Geofence(GeofenceConfig(), HOME)
    assert f.is_empty and GeofenceConfig().is_empty
    assert f.check_point(1e5, -1e5) is None
    assert f.check_segment((0, 0), (1e4, 1e4)) is None


def test_check_path_names_the_leg(fence):
    assert fence.check_path([(0, 0), (10, 10), (20, 45)]) is None
    reason = fence.check_path([(0, 0), (15, 30), (45, 30)])
    assert reason == "leg 1 (point 1 -> 2): leg crosses exclusion polygon 1"


def test_self_intersecting_polygon_is_rejected():
    bow_tie = [ll(-10, 10), ll(10, -10), ll(10, 10), ll(-10, -10)]
    with pytest.raises(ValueError, match=r"polygons\[0\]: not a simple polygon"):
        Geofence(GeofenceConfig(polygons=[GeofencePolygon(points=bow_tie)]), HOME)


def test_models_validate_with_field_and_value_in_the_message():
    with pytest.raises(ValidationError, match=r"points\[1\].*latitude.*95\.0"):
        GeofencePolygon(points=[(47.0, 8.0), (95.0, 8.0), (47.0, 8.1)])
    with pytest.raises(ValidationError, match="at least 3"):
        GeofencePolygon(points=[(47.0, 8.0), (47.1, 8.0)])
    with pytest.raises(ValidationError, match="radius"):
        GeofenceCircle(center=(47.0, 8.0), radius=0.0)
    with pytest.raises(ValidationError, match=r"longitude.*200"):
        GeofenceCircle(center=(47.0, 200.0), radius=5.0)
    with pytest.raises(ValidationError, match="inclusoin"):  # extra="forbid" names the unknown key
        GeofenceConfig.model_validate({"polygons": [{"points": square(0, 0, 5), "inclusoin": False}]})


def test_config_round_trips_through_json_like_environment_json():
    cfg = GeofenceConfig.model_validate({
        "polygons": [{"points": [list(p) for p in square(0, 0, 50)], "inclusion": True}],
        "circles": [{"center": list(ll(-30, -30)), "radius": 10, "inclusion": False}],
    })
    assert GeofenceConfig.model_validate_json(cfg.model_dump_json()) == cfg
    assert Geofence(cfg, HOME).check_point(-30, -30) == "inside exclusion circle 0 (radius 10 m)"
