"""asammdf reading MDF 4 bus logs to frames, timed: what `railfuse bench --mdf4` runs beside
railfuse. Each file is opened and its CAN_DataFrame members read (time, bus, id, IDE, data
length and bytes), as a frame list needs; the median of REPEAT passes over all files.

    python bench/peer_mdf4.py REPEAT FILE.MF4...
"""

import json
import sys
import time

from asammdf import MDF


def read(path):
    mdf = MDF(path)
    names = ["CAN_DataFrame.BusChannel", "CAN_DataFrame.ID", "CAN_DataFrame.IDE",
             "CAN_DataFrame.DataLength", "CAN_DataFrame.DataBytes"]
    sigs = [mdf.get(n, raw=True) for n in names]
    n = len(sigs[1].timestamps)
    mdf.close()
    return n


def main():
    repeat, files = int(sys.argv[1]), sys.argv[2:]
    times, frames = [], 0
    for _ in range(repeat):
        t = time.perf_counter()
        frames = sum(read(f) for f in files)
        times.append(time.perf_counter() - t)
    times.sort()
    print(json.dumps({"seconds": times[len(times) // 2], "frames": frames}))


if __name__ == "__main__":
    main()
