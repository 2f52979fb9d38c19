"""Geodetic helpers: WGS-84 <-> local ENU (metres) about a home point.

:func:`geodetic_to_enu` is pymap3d's (``geodetic2enu``). :func:`enu_to_geodetic`, which a simulated drone calls for
every odometry sample, is pymap3d's ``enu2geodetic`` computed on Python floats with the home point's constants kept:
the same rotation of ENU into ECEF (pymap3d ``enu2uvw``) about the home's ECEF position (pymap3d ``geodetic2ecef``,
called once per home) and the same closed-form ECEF -> geodetic step (You, R.-J. (2000), "Transformation of
Cartesian to Geodetic Coordinates without Iterations", J. Surveying Eng. 126(1), eqns. 4a-4c, 7 and 13, as in
pymap3d ``ecef2geodetic``), without numpy's per-call array overhead. A point on the polar axis, where that form
divides by zero, goes to pymap3d itself.
"""
from __future__ import annotations

import functools
import math

import pymap3d

from aerodaas.model.types import GeoPoint

_WGS84 = pymap3d.Ellipsoid.from_name("wgs84")
_A, _B = float(_WGS84.semimajor_axis), float(_WGS84.semiminor_axis)
_E2 = _A * _A - _B * _B  # the square of the linear eccentricity E (m^2)
_E = math.sqrt(_E2)


@functools.lru_cache(maxsize=256)
def _home_constants(lat0: float, lon0: float, h0: float) -> tuple[float, ...]:
    """(x0, y0, z0, sin lat0, cos lat0, sin lon0, cos lon0) of a home point (degrees, metres): its ECEF position
    (metres, pymap3d ``geodetic2ecef``) and the ENU -> ECEF rotation's terms."""
    x0, y0, z0 = (float(c) for c in pymap3d.geodetic2ecef(lat0, lon0, h0))
    la, lo = math.radians(lat0), math.radians(lon0)
    return x0, y0, z0, math.sin(la), math.cos(la), math.sin(lo), math.cos(lo)


def enu_to_geodetic(e: float, n: float, u: float, home: GeoPoint) -> GeoPoint:
    """ENU metres relative to ``home`` -> WGS-84 :class:`GeoPoint` (degrees, metres): pymap3d's ``enu2geodetic``
    (see the module's docstring for the formulas), to rounding. Raises ``pydantic.ValidationError`` for a
    non-finite result (a non-finite input)."""
    lat, lon, alt = enu_to_lat_lon_alt(e, n, u, home)
    return GeoPoint(lat=lat, lon=lon, alt=alt)


def enu_to_lat_lon_alt(e: float, n: float, u: float, home: GeoPoint) -> tuple[float, float, float]:
    """:func:`enu_to_geodetic` as plain floats ``(lat, lon, alt)`` (degrees, degrees, metres), unvalidated: NaN
    for a non-finite input."""
    x0, y0, z0, sla, cla, slo, clo = _home_constants(float(home.lat), float(home.lon), float(home.alt))
    e, n, u = float(e), float(n), float(u)
    t = cla * u - sla * n  # pymap3d enu2uvw
    x = x0 + clo * t - slo * e
    y = y0 + slo * t + clo * e
    z = z0 + sla * u + cla * n
    hxy = math.hypot(x, y)
    r2 = x * x + y * y + z * z
    q = math.sqrt(0.5 * (r2 - _E2) + 0.5 * math.hypot(r2 - _E2, 2.0 * _E * z))  # eqn. 4a (u in the paper)
    if math.isclose(q, 0.0, abs_tol=1e-8) or math.isclose(hxy, 0.0, abs_tol=1e-8):  # on the polar axis
        lat, lon, alt = pymap3d.enu2geodetic(e, n, u, home.lat, home.lon, home.alt)
        return float(lat), float(lon), float(alt)
    hue = math.hypot(q, _E)
    beta = math.atan(hue / q * z / hxy)  # eqn. 4b
    beta += ((_B * q - _A * hue + _E2) * math.sin(beta)) / (_A * hue / math.cos(beta) - _E2 * math.cos(beta))  # 13
    lat = math.atan(_A / _B * math.tan(beta))  # eqn. 4c
    alt = math.hypot(z - _B * math.sin(beta), hxy - _A * math.cos(beta))  # eqn. 7
    if (x * x + y * y) / (_A * _A) + z * z / (_B * _B) < 1.0:  # inside the ellipsoid
        alt = -alt
    return math.degrees(lat), math.degrees(math.atan2(y, x)), alt


def geodetic_to_enu(lat: float, lon: float, alt: float, home: GeoPoint) -> tuple[float, float, float]:
    """WGS-84 latitude/longitude (degrees) and altitude (metres) -> ENU metres relative to ``home``."""
    e, n, u = pymap3d.geodetic2enu(lat, lon, alt, home.lat, home.lon, home.alt)
    return (float(e), float(n), float(u))
