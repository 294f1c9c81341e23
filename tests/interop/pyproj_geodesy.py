"""railfuse's WGS-84 conversions against pyproj (PROJ). Usage: pyproj_geodesy.py POINTS.json,
where each point holds an origin, a geodetic point, railfuse's ECEF of it, railfuse's
geodetic of that ECEF, an ENU offset and railfuse's geodetic of it. Prints the largest
differences, in metres."""
import json
import math
import sys

from pyproj import Transformer

points = json.load(open(sys.argv[1]))
to_ecef = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
to_geodetic = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)


def metres(lat, lon, dlat, dlon, dh):
    """A geodetic difference as a distance (m), near (lat, lon)."""
    north = math.radians(dlat) * 6_378_137.0
    east = math.radians(dlon) * 6_378_137.0 * math.cos(math.radians(lat))
    return math.sqrt(north * north + east * east + dh * dh)


worst = {"geodetic_to_ecef": 0.0, "ecef_to_geodetic": 0.0, "enu_to_geodetic": 0.0, "geodetic_to_enu": 0.0}
for p in points:
    lat, lon, h = p["geodetic"]
    x, y, z = to_ecef.transform(lon, lat, h)
    rx, ry, rz = p["ecef"]
    worst["geodetic_to_ecef"] = max(worst["geodetic_to_ecef"], math.dist((x, y, z), (rx, ry, rz)))
    glon, glat, gh = to_geodetic.transform(rx, ry, rz)
    blat, blon, bh = p["geodetic_of_ecef"]
    worst["ecef_to_geodetic"] = max(
        worst["ecef_to_geodetic"], metres(glat, glon, blat - glat, blon - glon, bh - gh)
    )
    olat, olon, oh = p["origin"]
    topo = Transformer.from_pipeline(
        "+proj=pipeline +step +proj=cart +ellps=WGS84 "
        f"+step +proj=topocentric +ellps=WGS84 +lat_0={olat!r} +lon_0={olon!r} +h_0={oh!r}"
    )
    e, n, u = p["enu"]
    elon, elat, eh = topo.transform(e, n, u, direction="INVERSE")
    rlat, rlon, rh = p["geodetic_of_enu"]
    worst["enu_to_geodetic"] = max(
        worst["enu_to_geodetic"], metres(elat, elon, rlat - elat, rlon - elon, rh - eh)
    )
    te, tn, tu = topo.transform(lon, lat, h)
    worst["geodetic_to_enu"] = max(worst["geodetic_to_enu"], math.dist((te, tn, tu), p["enu_of_geodetic"]))
print(json.dumps({"points": len(points), "worst_m": worst}))
