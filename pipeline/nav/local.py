"""A local North/East/Down map around an origin, for planar vehicle models.

Planar models (the tractor of paper 000, the bicycle model of paper 003) work in metres
East/North of an origin. ``LocalFrame`` maps those coordinates to WGS-84 latitude, longitude and
ellipsoidal height and back with the meridian and transverse radii of curvature at the origin
(an equirectangular map): north = (lat - lat0)(R_M + h0), east = (lon - lon0)(R_N + h0) cos lat0,
down = h0 - h. The two directions are exact inverses of each other. Against the curvilinear
(mechanization) frame the east scale is off by tan(lat0) * north / R, e.g. 3e-5 m per metre
east at 200 m north of the origin at 40 deg latitude; use it for drives of a few hundred metres
(the tractor), and integrate latitude and longitude along the trajectory for longer ones (as
the car and fwekf synthesizers do).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.nav.earth import radii

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LocalFrame:
    """A local map by its origin: geodetic latitude, longitude (deg), ellipsoidal height (m).

    Also the ``origin`` section of the synthesizers' parameters.
    """

    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self) -> None:
        if not -89.0 <= self.lat_deg <= 89.0:
            raise FieldError("lat_deg", "must be within -89..89")
        if not -180.0 <= self.lon_deg <= 180.0:
            raise FieldError("lon_deg", "must be within -180..180")

    def _scales(self) -> tuple[float, float]:
        lat0 = math.radians(self.lat_deg)
        rm, rn = radii(lat0)
        m_per_rad_lat = rm + self.alt_m
        m_per_rad_lon = (rn + self.alt_m) * math.cos(lat0)
        return m_per_rad_lat, m_per_rad_lon

    def to_geodetic(
        self, north_m: F64 | float, east_m: F64 | float, down_m: F64 | float = 0.0
    ) -> tuple[F64, F64, F64]:
        """Local North/East/Down (m) to latitude, longitude (deg) and height (m)."""
        s_lat, s_lon = self._scales()
        n = np.asarray(north_m, dtype=np.float64)
        e = np.asarray(east_m, dtype=np.float64)
        d = np.asarray(down_m, dtype=np.float64)
        lat = self.lat_deg + np.degrees(n / s_lat)
        lon = self.lon_deg + np.degrees(e / s_lon)
        alt = self.alt_m - d
        return lat, lon, np.broadcast_to(alt, np.broadcast(n, e, d).shape).astype(np.float64)

    def to_ned(
        self, lat_deg: F64 | float, lon_deg: F64 | float, alt_m: F64 | float
    ) -> tuple[F64, F64, F64]:
        """Latitude, longitude (deg) and height (m) to local North/East/Down (m)."""
        s_lat, s_lon = self._scales()
        n = np.radians(np.asarray(lat_deg, dtype=np.float64) - self.lat_deg) * s_lat
        e = np.radians(np.asarray(lon_deg, dtype=np.float64) - self.lon_deg) * s_lon
        d = self.alt_m - np.asarray(alt_m, dtype=np.float64)
        return n, e, d
