"""Read a candump log (or a Vector ASC log, .asc) with python-can and decode its frames with
cantools.

    python tests/interop/can_check.py vehicle.dbc frames.log|frames.asc out.json

An ASC log's date is read as UTC (python-can reads it in the local zone).

Writes, frame by frame as python-can's CanutilsLogReader reads them: the time, id, flags
and data, and for frames whose id the DBC has, cantools' signals (scaled, multiplexing
resolved) and the value tables' names. tests/can.rs compares railfuse's reading with it.
"""

import json
import math
import os
import sys
import time

import can
import cantools


def main():
    dbc, log, out = sys.argv[1:4]
    db = cantools.database.load_file(dbc)
    frames = []
    if log.endswith(".asc"):
        os.environ["TZ"] = "UTC"
        time.tzset()
        reader = can.io.ASCReader(log, relative_timestamp=False)
    else:
        reader = can.io.CanutilsLogReader(log)
    for m in reader:
        frame = {
            "stamp": m.timestamp,
            "bus": m.channel,
            "id": m.arbitration_id,
            "extended": m.is_extended_id,
            "rtr": m.is_remote_frame,
            "error": m.is_error_frame,
            "fd": m.is_fd,
            "brs": m.bitrate_switch,
            "esi": m.error_state_indicator,
            "data": bytes(m.data).hex(),
            "signals": None,
            "labels": {},
        }
        if not (m.is_remote_frame or m.is_error_frame):
            try:
                message = db.get_message_by_frame_id(m.arbitration_id)
            except KeyError:
                message = None
            if message is not None and message.is_extended_frame == m.is_extended_id:
                values = db.decode_message(m.arbitration_id, m.data, decode_choices=False)
                named = db.decode_message(m.arbitration_id, m.data, decode_choices=True)
                # JSON has no NaN or infinity: a float signal's are written as their names.
                frame["signals"] = {k: float(v) if math.isfinite(v) else str(float(v))
                                    for k, v in values.items()}
                frame["labels"] = {k: str(v) for k, v in named.items()
                                   if isinstance(v, cantools.database.namedsignalvalue.NamedSignalValue)}
        frames.append(frame)
    json.dump(frames, open(out, "w"))


if __name__ == "__main__":
    main()
