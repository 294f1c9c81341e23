"""Frames of an MDF4 bus log as asammdf reads them, and its signals as asammdf's
extract_bus_logging decodes them with a DBC.

    python tests/interop/mdf4_frames.py frames FILE.MF4 OUT.json
        every CAN_DataFrame: [time_ns, bus, id, extended, data hex], in asammdf's order
    python tests/interop/mdf4_frames.py save FILE.MF4 OUT.mf4 COMPRESSION
        the file as asammdf writes it again (sorted; 1 deflate, 2 transposed deflate)
    python tests/interop/mdf4_frames.py signals FILE.MF4 DBC BUS OUT.json
        every signal asammdf decodes from bus BUS's frames with the DBC: {name: [[time_ns, value], …]}
    python tests/interop/mdf4_frames.py measured OUT.mf4 COMPRESSION
        writes a measurement system's MDF4 with asammdf: a GNSS group at 10 Hz (Latitude and
        Longitude in deg, Height in mm, Speed in km/h as raw counts with a linear conversion)
        and an IMU group at 100 Hz (Acc in g, Gyro in deg/s), 20 s; prints each group's
        samples as asammdf reads them back ({channel: [[time_ns, value], ...]}, JSON)
"""

import json
import sys

import numpy as np
from asammdf import MDF


def start_ns(mdf):
    return int(round(mdf.header.start_time.timestamp() * 1e6)) * 1000


def measured(out, compression):
    from asammdf import Signal

    t_gnss = np.arange(0, 20, 0.1)
    t_imu = np.arange(0, 20, 0.01)
    speed_counts = (600 + 10 * t_gnss).astype(np.uint16)  # 0.1 km/h per count
    gnss = [
        Signal(44.6551 + 1e-5 * t_gnss, t_gnss, name="Latitude", unit="deg"),
        Signal(10.9297 + 2e-5 * t_gnss, t_gnss, name="Longitude", unit="deg"),
        Signal((40000 + 10 * t_gnss).astype(np.int32), t_gnss, name="Height", unit="mm"),
        Signal(speed_counts, t_gnss, name="Speed", unit="km/h",
               conversion={"a": 0.1, "b": 0.0}),
    ]
    imu = [Signal(0.01 * np.sin(t_imu + k), t_imu, name=f"Acc{a}", unit="g") for k, a in enumerate("XY")]
    imu.append(Signal(1.0 + 0.01 * np.cos(t_imu), t_imu, name="AccZ", unit="g"))
    imu += [Signal(0.5 * np.sin(t_imu * (k + 1)), t_imu, name=f"Gyro{a}", unit="deg/s") for k, a in enumerate("XYZ")]
    mdf = MDF(version="4.10")
    mdf.header.start_time = __import__("datetime").datetime(2026, 6, 1, 8, 0, 0, tzinfo=__import__("datetime").timezone.utc)
    mdf.append(gnss, comment="GNSS")
    mdf.append(imu, comment="IMU")
    mdf.save(out, overwrite=True, compression=int(compression))
    back = MDF(out)
    t0 = start_ns(back)
    values = {}
    for name in ["Latitude", "Longitude", "Height", "Speed", "AccX", "AccY", "AccZ", "GyroX", "GyroY", "GyroZ"]:
        sig = back.get(name)
        values[name] = [[t0 + int(round(float(t) * 1e9)), float(v)] for t, v in zip(sig.timestamps, sig.samples)]
    print(json.dumps(values))


def frames(path, out):
    mdf = MDF(path)
    t0 = start_ns(mdf)
    get = lambda name: mdf.get(name, raw=True)
    ids = get("CAN_DataFrame.ID")
    t = ids.timestamps
    bus = get("CAN_DataFrame.BusChannel").samples
    ide = get("CAN_DataFrame.IDE").samples
    length = get("CAN_DataFrame.DataLength").samples
    data = get("CAN_DataFrame.DataBytes").samples
    rows = []
    for k in range(len(t)):
        raw = bytes(data[k])[: int(length[k])]
        rows.append([t0 + int(round(float(t[k]) * 1e9)), f"CAN{int(bus[k])}", int(ids.samples[k]) & 0x1FFFFFFF,
                     bool(ide[k]), raw.hex().upper()])
    json.dump({"start_ns": t0, "frames": rows}, open(out, "w"))
    print(json.dumps({"frames": len(rows)}))


def signals(path, dbc, bus, out):
    mdf = MDF(path)
    t0 = start_ns(mdf)
    decoded = mdf.extract_bus_logging({"CAN": [(dbc, int(bus))]})
    result = {}
    for group in decoded.groups:
        for ch in group.channels:
            if ch.name in ("time", "t") or ch.name.startswith("CAN"):
                continue
            sig = decoded.get(ch.name, raw=False)
            if sig.samples.dtype.kind not in "fiub":
                continue
            result[ch.name] = [[t0 + int(round(float(ts) * 1e9)), float(v)]
                               for ts, v in zip(sig.timestamps, sig.samples.astype(np.float64))]
    json.dump(result, open(out, "w"))
    print(json.dumps({"signals": len(result)}))


def save(path, out, compression):
    MDF(path).save(out, compression=int(compression), overwrite=True)


if __name__ == "__main__":
    {"frames": frames, "signals": signals, "save": save, "measured": measured}[sys.argv[1]](*sys.argv[2:])
