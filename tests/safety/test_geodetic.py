"""The ENU -> WGS-84 conversion every simulated odometry sample makes agrees with pymap3d's ``enu2geodetic`` (the
third-party reference) anywhere on Earth, including below the ellipsoid and on the polar axis."""
from __future__ import annotations

import math

import pymap3d
from hypothesis import given, settings
from hypothesis import strategies as st

from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu
from aerodaas.model.types import GeoPoint


def _agree(e: float, n: float, u: float, home: GeoPoint) -> None:
    got = enu_to_geodetic(e, n, u, home)
    lat, lon, alt = (float(v) for v in pymap3d.enu2geodetic(e, n, u, home.lat, home.lon, home.alt))
    assert math.isclose(got.lat, lat, abs_tol=1e-9)
    assert min(abs(got.lon - lon), 360.0 - abs(got.lon - lon)) < 1e-9
    assert math.isclose(got.alt, alt, abs_tol=1e-6)


@settings(max_examples=300, deadline=None)
@given(lat=st.floats(-89.99, 89.99), lon=st.floats(-180.0, 180.0), h=st.floats(-500.0, 5000.0),
       enu=st.tuples(*[st.floats(-20000.0, 20000.0)] * 3))
def test_enu_to_geodetic_is_pymap3d_s(lat, lon, h, enu):
    _agree(*enu, GeoPoint(lat=lat, lon=lon, alt=h))


def test_poles_below_the_ellipsoid_and_round_trip():
    for home in (GeoPoint(lat=90.0, lon=0.0, alt=10.0), GeoPoint(lat=-90.0, lon=45.0, alt=0.0),
                 GeoPoint(lat=31.5, lon=35.5, alt=-430.0)):  # the last: below the ellipsoid (the Dead Sea)
        _agree(0.0, 0.0, 0.0, home)
        _agree(3.0, -4.0, 2.0, home)
    home = GeoPoint(lat=47.4, lon=8.5, alt=420.0)
    g = enu_to_geodetic(120.0, -35.0, 12.0, home)
    assert all(math.isclose(a, b, abs_tol=1e-6) for a, b in
               zip(geodetic_to_enu(g.lat, g.lon, g.alt, home), (120.0, -35.0, 12.0)))
