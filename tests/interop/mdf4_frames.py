"""Frames of an MDF4 bus log as asammdf reads them, and its signals as asammdf's
extract_bus_logging decodes them with a DBC.

    python tests/interop/mdf4_frames.py frames FILE.MF4 OUT.json
        every CAN_DataFrame: [time_ns, bus, id, extended, data hex], in asammdf's order
    python tests/interop/mdf4_frames.py save FILE.MF4 OUT.mf4 COMPRESSION
        the file as asammdf writes it again (sorted; 1 deflate, 2 transposed deflate)
    python tests/interop/mdf4_frames.py signals FILE.MF4 DBC BUS OUT.json
        every signal asammdf decodes from bus BUS's frames with the DBC: {name: [[time_ns, value], …]}
"""

import json
import sys

import numpy as np
from asammdf import MDF


def start_ns(mdf):
    return int(round(mdf.header.start_time.timestamp() * 1e6)) * 1000


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
    {"frames": frames, "signals": signals, "save": save}[sys.argv[1]](*sys.argv[2:])
