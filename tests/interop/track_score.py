"""Score a line `railfuse track` fitted against a simulated run's true centre line.

    python tests/interop/track_score.py line.geojson run.mcap [--against truth|map]

The true line is where the run's train was (`/truth`, a vertex every metre; seed002's map
carries its survey's error, the truth does not), or its `/track/map` (exact on the default
line). The fitted line is sampled every metre of its chainage between the true line's ends
and projected on it with pyproj's transverse Mercator about the map's origin (not railfuse's
own geodesy). Prints the lateral RMS and maximum over the whole line, where the fit had
fixes and in its gaps (the GeoJSON's own `gaps`, set-aside stretches included), and the
chainage's largest relative error beyond 1 km once the start offset is removed. The book's
tables for `railfuse track` come from this script.
"""

import argparse
import json

import numpy as np
import pyproj
import railfuse


def true_line(run, against):
    """(vertices east/north, chainage) of the run's true line, in its map's plane."""
    if against == "map":
        m = railfuse.read(run, "/track/map").to_pylist()[0]
        v = m["vertices"]
        return (np.array([[x["east_m"], x["north_m"]] for x in v]),
                np.array([x["chainage_m"] for x in v]))
    t = railfuse.read(run, "/truth").to_pydict()
    chainage = np.array(t["chainage_m"])
    keep, last = np.zeros(len(chainage), bool), -np.inf
    for i, c in enumerate(chainage):
        if c - last >= 1.0:
            keep[i], last = True, c
    east, north = np.array(t["east_m"])[keep], np.array(t["north_m"])[keep]
    return np.c_[east, north], chainage[keep]


def project(points, line, chainage):
    """Each point's chainage on `line` and its signed distance (left positive)."""
    a, b = line[:-1], line[1:]
    d = b - a
    len2 = (d ** 2).sum(1)
    at, off = np.empty(len(points)), np.empty(len(points))
    for i, p in enumerate(points):
        t = np.clip(((p - a) * d).sum(1) / len2, 0, 1)
        q = a + t[:, None] * d
        dist = np.hypot(*(p - q).T)
        k = dist.argmin()
        side = np.sign(d[k, 0] * (p - q[k])[1] - d[k, 1] * (p - q[k])[0])
        off[i] = side * dist[k]
        at[i] = chainage[k] + t[k] * (chainage[k + 1] - chainage[k])
    return at, off


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fitted")
    ap.add_argument("run")
    ap.add_argument("--against", choices=["truth", "map"], default="truth")
    args = ap.parse_args()
    origin = railfuse.read(args.run, "/track/map").to_pylist()[0]["origin"]
    plane = pyproj.Transformer.from_crs(
        "EPSG:4326",
        pyproj.CRS.from_proj4(
            f"+proj=tmerc +lat_0={origin['latitude_deg']} +lon_0={origin['longitude_deg']}"
            " +k=1 +x_0=0 +y_0=0 +ellps=WGS84"),
        always_xy=True)
    line, line_chainage = true_line(args.run, args.against)
    feature = json.load(open(args.fitted))["features"][0]
    lonlat = np.array(feature["geometry"]["coordinates"])
    fitted_chainage = np.array(feature["properties"]["chainage_m"])
    east, north = plane.transform(lonlat[:, 0], lonlat[:, 1])
    s = np.arange(fitted_chainage[0], fitted_chainage[-1], 1.0)
    points = np.c_[np.interp(s, fitted_chainage, east), np.interp(s, fitted_chainage, north)]
    at, lateral = project(points, line, line_chainage)
    inside = (at > line_chainage[0] + 0.01) & (at < line_chainage[-1] - 0.01)
    s, at, lateral = s[inside], at[inside], lateral[inside]
    in_gap = np.zeros(len(s), bool)
    for g in feature["properties"]["railfuse_track"]["gaps"]:
        in_gap |= (s >= g["from_m"]) & (s <= g["to_m"])

    def stats(x):
        return (f"{np.sqrt(np.mean(x ** 2)):.4f} m RMS, {np.abs(x).max():.3f} m at most"
                if len(x) else "none")

    print(f"across the track, whole line ({s[-1] - s[0]:.0f} m): {stats(lateral)}")
    print(f"  where there are fixes: {stats(lateral[~in_gap])}")
    print(f"  in the gaps ({in_gap.sum()} m): {stats(lateral[in_gap])}")
    error = s - at
    beyond = at > 1000
    relative = np.abs(error - error[0])[beyond] / at[beyond]
    print(f"chainage: start offset {error[0]:+.3f} m, then at most {100 * relative.max():.4f} % "
          "of the chainage beyond 1 km")


if __name__ == "__main__":
    main()
