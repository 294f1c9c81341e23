"""GPX in, GIS files out, each side done by the ecosystem's own libraries.

    python tests/interop/gpx_gis.py ride OUT.gpx
        writes a phone-style GPX 1.0 ride with gpxpy (zone offsets, two tracks, three
        segments, speed/course, hdop/sat/fix, a point without time) and prints its points
        as gpxpy reads them back (JSON).
    python tests/interop/gpx_gis.py sample RUN.mcap OUT.gpx
        writes a railfuse log's GNSS fixes (JSON channels) as a phone app writes a ride: 1 Hz,
        GPX 1.1, speed and course in Garmin's TrackPointExtension (samples/ride.gpx).
    python tests/interop/gpx_gis.py read FILE.gpx|.kml|.geojson|.csv
        reads an export: gpxpy (GPX), fastkml (KML), geojson (validity), pandas (CSV), and
        prints what each found (JSON).
"""

import datetime as dt
import json
import math
import sys


EPOCH = dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc)


def ride(out):
    import gpxpy.gpx

    gpx = gpxpy.gpx.GPX()
    gpx.version = "1.0"
    gpx.creator = "a phone logger"
    zones = [dt.timezone(dt.timedelta(hours=2)), dt.timezone.utc, dt.timezone(dt.timedelta(hours=-5, minutes=-30))]
    start = dt.datetime(2021, 7, 1, 8, 54, 23, tzinfo=dt.timezone.utc)
    k = 0
    for t in range(2):
        track = gpxpy.gpx.GPXTrack(name=f"ride {t}")
        gpx.tracks.append(track)
        for s in range(2 if t == 0 else 1):
            seg = gpxpy.gpx.GPXTrackSegment()
            track.segments.append(seg)
            for i in range(40):
                when = (start + dt.timedelta(seconds=k * 1.0 + (5 if s or t else 0) * (s + t))).astimezone(zones[k % 3])
                p = gpxpy.gpx.GPXTrackPoint(
                    latitude=47.3769 + 1e-4 * k,
                    longitude=8.5417 + 2e-4 * math.sin(k / 10),
                    elevation=408.0 + 0.1 * k,
                    time=when,
                    speed=12.0 + 0.05 * k,
                )
                p.course = (15.0 * k) % 360
                p.horizontal_dilution = 0.8 + 0.01 * k
                p.satellites = 7 + k % 5
                p.type_of_gpx_fix = ["3d", "2d", "dgps"][k % 3]
                if k == 17:
                    p.time = None
                seg.points.append(p)
                k += 1
    open(out, "w").write(gpx.to_xml(version="1.0"))
    back = gpxpy.parse(open(out))
    points = []
    for track in back.tracks:
        for seg in track.segments:
            for p in seg.points:
                points.append({
                    "time_ns": None if p.time is None else (p.time - EPOCH) // dt.timedelta(microseconds=1) * 1000,
                    "lat": p.latitude, "lon": p.longitude, "ele": p.elevation,
                    "speed": p.speed, "course": p.course, "hdop": p.horizontal_dilution,
                    "sat": p.satellites, "fix": p.type_of_gpx_fix,
                })
    print(json.dumps({"version": back.version, "points": points}))


def sample(run, out):
    from mcap.reader import make_reader
    import gpxpy.gpx

    gpx = gpxpy.gpx.GPX()
    gpx.creator = "railfuse tests/interop/gpx_gis.py from a simulated run"
    gpx.nsmap["gpxtpx"] = "http://www.garmin.com/xmlschemas/TrackPointExtension/v2"
    track = gpxpy.gpx.GPXTrack(name="a simulated ride, 1 Hz")
    gpx.tracks.append(track)
    seg = gpxpy.gpx.GPXTrackSegment()
    track.segments.append(seg)
    last = None
    with open(run, "rb") as f:
        for _, _, m in make_reader(f).iter_messages(topics=["/gnss/fix"]):
            fix = json.loads(m.data)
            second = fix["stamp_ns"] // 1_000_000_000
            if fix.get("latitude_deg") is None or second == last:
                continue
            last = second
            p = gpxpy.gpx.GPXTrackPoint(
                latitude=round(fix["latitude_deg"], 7), longitude=round(fix["longitude_deg"], 7),
                elevation=round(fix["altitude_m"], 1),
                time=EPOCH + dt.timedelta(microseconds=fix["stamp_ns"] // 1000))
            p.horizontal_dilution = round(fix["hdop"], 1)
            p.satellites = fix["satellites"]
            import xml.etree.ElementTree as ET
            ns = "{http://www.garmin.com/xmlschemas/TrackPointExtension/v2}"
            ext = ET.Element(ns + "TrackPointExtension")
            if fix.get("speed_mps") is not None:
                ET.SubElement(ext, ns + "speed").text = f"{fix['speed_mps']:.2f}"
            if fix.get("course_rad") is not None:
                ET.SubElement(ext, ns + "course").text = f"{math.degrees(fix['course_rad']) % 360:.1f}"
            p.extensions.append(ext)
            seg.points.append(p)
    open(out, "w").write(gpx.to_xml(version="1.1"))
    print(json.dumps({"points": len(seg.points)}))


def read(path):
    if path.endswith(".gpx"):
        import gpxpy

        g = gpxpy.parse(open(path))
        tracks = []
        for t in g.tracks:
            pts = [p for s in t.segments for p in s.points]
            ext = pts[0].extensions if pts else []
            names = sorted({e.tag.split("}")[-1] for e in ext})
            tracks.append({
                "name": t.name, "points": len(pts),
                "first_time_ms": (pts[0].time - EPOCH) // dt.timedelta(milliseconds=1) if pts else None,
                "first_lat": pts[0].latitude if pts else None,
                "extensions": names,
            })
        print(json.dumps({"tracks": tracks}))
    elif path.endswith(".kml"):
        from fastkml import kml, validator
        from fastkml.gx import Track

        # Against OGC's KML 2.2 schema (with Google's extensions), as fastkml ships it.
        assert validator.validate(file_to_validate=path), "not valid KML 2.2"
        doc = kml.KML.parse(path, strict=True)
        tracks = []
        for f in doc.features[0].features:
            g = f.kml_geometry
            assert isinstance(g, Track), type(g)
            items = g.track_items
            arrays = {}
            for sd in g.extended_data.elements[0].array_data:
                arrays[sd.name] = len(sd.data)
            tracks.append({
                "name": f.name, "points": len(items),
                "first_time": items[0].when.dt.isoformat() if items else None,
                "first_lon": items[0].coord.x if items else None,
                "arrays": arrays,
            })
        print(json.dumps({"tracks": tracks}))
    elif path.endswith(".geojson"):
        import geojson

        fc = geojson.load(open(path))
        pipelines = {}
        for f in fc["features"]:
            pipelines.setdefault(f["properties"]["pipeline"], 0)
            pipelines[f["properties"]["pipeline"]] += 1
        print(json.dumps({"valid": fc.is_valid, "errors": fc.errors(), "type": fc["type"],
                          "pipelines": pipelines,
                          "first": fc["features"][0]["properties"] if fc["features"] else None}))
    elif path.endswith(".csv"):
        import pandas as pd

        df = pd.read_csv(path)
        print(json.dumps({"columns": list(df.columns), "rows": len(df),
                          "pipelines": df["pipeline"].value_counts().to_dict(),
                          "nan": int(df.isna().sum().sum()),
                          "sigma_east_max": float(df["sigma_east_m"].max()),
                          "span_s": float(df["stamp_ns"].max() - df["stamp_ns"].min()) / 1e9}))
    else:
        raise SystemExit(f"{path}: unknown ending")


if __name__ == "__main__":
    {"ride": ride, "read": read, "sample": sample}[sys.argv[1]](*sys.argv[2:])
