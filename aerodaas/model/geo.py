"""Geodetic helpers: WGS-84 <-> local ENU (metres) about a home point, delegated to pymap3d.

pymap3d implements the standard ECEF-based conversions (see its ``enu`` module); we never convert by hand.
"""
from __future__ import annotations

import pymap3d

from aerodaas.model.types import GeoPoint


def enu_to_geodetic(e: float, n: float, u: float, home: GeoPoint) -> GeoPoint:
    """ENU metres relative to ``home`` -> WGS-84 :class:`GeoPoint` (degrees, metres)."""
    lat, lon, alt = pymap3d.enu2geodetic(e, n, u, home.lat, home.lon, home.alt)
    return GeoPoint(lat=float(lat), lon=float(lon), alt=float(alt))


def geodetic_to_enu(lat: float, lon: float, alt: float, home: GeoPoint) -> tuple[float, float, float]:
    """WGS-84 latitude/longitude (degrees) and altitude (metres) -> ENU metres relative to ``home``."""
    e, n, u = pymap3d.geodetic2enu(lat, lon, alt, home.lat, home.lon, home.alt)
    return (float(e), float(n), float(u))
