"""Loggers' CSV tables, written and read back by pandas (the reference railfuse's CSV mapping
is checked against).

    python tests/interop/logger_csv.py sample-logger RUN.mcap OUT.csv
        writes a railfuse log's GNSS fixes as a u-blox GNSS logger writes them: the date and
        time in six columns (whole seconds only), Lon/Lat in 1e-7 deg, heights and
        accuracies in mm, speed in mm/s, PDOP x 100, five rows a second
        (samples/loggers/gnss-logger.csv).
    python tests/interop/logger_csv.py sample-phone RUN.mcap OUT.csv
        writes a phone sensor-logger export (SensorLog's columns): one row per IMU sample at
        25 Hz, the phone's local time with its offset, acceleration in G with iOS's sign
        (at rest face up z = -1), rotation in rad/s, and the latest 1 Hz location fix
        (its own time since 1970) repeated on every row (samples/loggers/phone-sensorlog.csv).
    python tests/interop/logger_csv.py european IN.csv OUT.csv
        rewrites a table as a European spreadsheet saves it: ';' between cells, a decimal
        comma, a BOM and CRLF line ends.
    python tests/interop/logger_csv.py read-logger FILE.csv [--european]
    python tests/interop/logger_csv.py read-phone FILE.csv
        reads a table with pandas and prints the fixes (and IMU samples) it holds, in
        railfuse's units, with their times in ns since the epoch (JSON).
"""

import datetime as dt
import json
import math
import sys

G = 9.80665


def channel(path, topic):
    """The JSON messages of one topic of a railfuse log, in log order."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for _, ch, message in make_reader(f).iter_messages(topics=[topic]):
            if ch.message_encoding == "json":
                yield json.loads(message.data)


def sample_logger(run, out):
    import pandas as pd

    rows = []
    fixes = [f for f in channel(run, "/gnss/fix") if f.get("latitude_deg") is not None]
    for f in fixes[::2]:  # 10 Hz to the logger's 5
        t = dt.datetime.fromtimestamp(f["stamp_ns"] // 10**9, dt.timezone.utc)
        sigma = math.sqrt(f["position_covariance_enu_m2"][0]) if f.get("position_covariance_enu_m2") else 1.5
        rows.append(
            {
                "Year": t.year,
                "Month": t.month,
                "Day": t.day,
                "Hour": t.hour,
                "Minute": t.minute,
                "Second": t.second,
                "nSAT": f["satellites"],
                "Lon": round(f["longitude_deg"] * 1e7),
                "Lat": round(f["latitude_deg"] * 1e7),
                "Alt1": round(f["altitude_m"] * 1000),
                "Alt2": round((f["altitude_m"] - 47.3) * 1000),
                "hAcc": round(sigma * 1000),
                "vAcc": round(2 * sigma * 1000),
                "speed": round((f.get("speed_mps") or 0.0) * 1000),
                "speedAcc": 120,
                "PDOP": round((f.get("hdop") or 1.0) * 180),
            }
        )
    pd.DataFrame(rows).to_csv(out, index=False)


def sample_phone(run, out):
    import pandas as pd

    zone = dt.timezone(dt.timedelta(hours=2))
    fixes = [f for f in channel(run, "/gnss/fix") if f.get("latitude_deg") is not None][::10]
    imu = list(channel(run, "/imu"))[::8]  # 200 Hz to the phone's 25
    rows, k = [], -1
    for n, s in enumerate(imu):
        while k + 1 < len(fixes) and fixes[k + 1]["stamp_ns"] <= s["stamp_ns"]:
            k += 1
        t = dt.datetime.fromtimestamp(s["stamp_ns"] / 1e9, zone)
        row = {
            "loggingTime(txt)": t.strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " +0200",
            "loggingSample(N)": n,
        }
        f = fixes[k] if k >= 0 else None
        sigma = math.sqrt(f["position_covariance_enu_m2"][0]) if f and f.get("position_covariance_enu_m2") else 3.0
        # A phone states a 68 % radius: sigma * sqrt(-2 ln 0.32).
        radius = sigma * math.sqrt(-2 * math.log(0.32))
        row.update(
            {
                "locationTimestamp_since1970(s)": f"{f['stamp_ns'] / 1e9:.3f}" if f else "",
                "locationLatitude(WGS84)": f"{f['latitude_deg']:.8f}" if f else "",
                "locationLongitude(WGS84)": f"{f['longitude_deg']:.8f}" if f else "",
                "locationAltitude(m)": f"{f['altitude_m']:.2f}" if f else "",
                "locationSpeed(m/s)": f"{f.get('speed_mps') or 0.0:.3f}" if f else "",
                "locationCourse(°)": f"{math.degrees(f.get('course_rad') or 0.0) % 360:.2f}" if f else "",
                "locationHorizontalAccuracy(m)": f"{radius:.2f}" if f else "",
                "locationVerticalAccuracy(m)": f"{2 * radius:.2f}" if f else "",
                "accelerometerTimestamp_sinceReboot(s)": f"{s['stamp_ns'] / 1e9 - 1780300000:.4f}",
                "accelerometerAccelerationX(G)": f"{-s['specific_force_mps2'][0] / G:.6f}",
                "accelerometerAccelerationY(G)": f"{-s['specific_force_mps2'][1] / G:.6f}",
                "accelerometerAccelerationZ(G)": f"{-s['specific_force_mps2'][2] / G:.6f}",
                "gyroRotationX(rad/s)": f"{s['angular_rate_radps'][0]:.6f}",
                "gyroRotationY(rad/s)": f"{s['angular_rate_radps'][1]:.6f}",
                "gyroRotationZ(rad/s)": f"{s['angular_rate_radps'][2]:.6f}",
            }
        )
        rows.append(row)
    pd.DataFrame(rows).to_csv(out, index=False)


def european(src, out):
    import pandas as pd

    table = pd.read_csv(src)
    table.to_csv(out, sep=";", decimal=",", index=False, encoding="utf-8-sig", lineterminator="\r\n")
    print(json.dumps({"rows": len(table)}))


def read_logger(path, european_style):
    import pandas as pd

    if european_style:
        t = pd.read_csv(path, sep=";", decimal=",", encoding="utf-8-sig")
    else:
        t = pd.read_csv(path)
    when = pd.to_datetime(t[["Year", "Month", "Day", "Hour", "Minute", "Second"]].rename(columns=str.lower), utc=True)
    whole = when.dt.as_unit("ns").astype("int64")
    # The logger writes the second; its 5 Hz rows are placed at k / 5 s within it.
    k = t.groupby(whole).cumcount()
    fixes = []
    for i in range(len(t)):
        fixes.append(
            {
                "stamp_ns": int(whole.iloc[i] + k.iloc[i] * 200_000_000),
                "latitude_deg": t["Lat"].iloc[i] * 1e-7,
                "longitude_deg": t["Lon"].iloc[i] * 1e-7,
                "altitude_m": t["Alt1"].iloc[i] / 1000,
                "speed_mps": t["speed"].iloc[i] / 1000,
                "satellites": int(t["nSAT"].iloc[i]),
                "sigma_h_m": t["hAcc"].iloc[i] / 1000,
            }
        )
    print(json.dumps({"fixes": fixes}))


def read_phone(path):
    import pandas as pd

    t = pd.read_csv(path)
    logged = pd.to_datetime(t["loggingTime(txt)"], format="%Y-%m-%d %H:%M:%S.%f %z").dt.as_unit("ns").astype("int64")
    imu = [
        {
            "stamp_ns": int(logged.iloc[i]),
            "specific_force_mps2": [-t[f"accelerometerAcceleration{a}(G)"].iloc[i] * G for a in "XYZ"],
            "angular_rate_radps": [t[f"gyroRotation{a}(rad/s)"].iloc[i] for a in "XYZ"],
        }
        for i in range(len(t))
    ]
    loc = t.dropna(subset=["locationTimestamp_since1970(s)"]).drop_duplicates(subset=["locationTimestamp_since1970(s)"])
    fixes = [
        {
            "stamp_ns": round(row["locationTimestamp_since1970(s)"] * 1e9),
            "latitude_deg": row["locationLatitude(WGS84)"],
            "longitude_deg": row["locationLongitude(WGS84)"],
            "course_rad": math.radians(row["locationCourse(°)"]),
            "sigma_h_m": row["locationHorizontalAccuracy(m)"] / math.sqrt(-2 * math.log(0.32)),
        }
        for _, row in loc.iterrows()
    ]
    print(json.dumps({"fixes": fixes, "imu": imu}))


if __name__ == "__main__":
    what = sys.argv[1]
    if what == "sample-logger":
        sample_logger(sys.argv[2], sys.argv[3])
    elif what == "sample-phone":
        sample_phone(sys.argv[2], sys.argv[3])
    elif what == "european":
        european(sys.argv[2], sys.argv[3])
    elif what == "read-logger":
        read_logger(sys.argv[2], "--european" in sys.argv)
    elif what == "read-phone":
        read_phone(sys.argv[2])
    else:
        sys.exit(f"unknown command {what}")
