"""Write a candump log's frames as Vector BLF with python-can's BLFWriter, then read the BLF
back with python-can's BLFReader.

    python tests/interop/can_blf.py frames.log out.blf theirs.json

theirs.json holds the frames as BLFReader reads them (time, channel, id, flags, data), for
tests/can.rs to compare railfuse's BLF reading with.
"""

import json
import sys

import can


def main():
    log, blf, out = sys.argv[1:4]
    with can.BLFWriter(blf) as writer:
        for m in can.io.CanutilsLogReader(log):
            writer.on_message_received(m)
    frames = []
    for m in can.BLFReader(blf):
        frames.append({
            "stamp": m.timestamp,
            "channel": m.channel,
            "id": m.arbitration_id,
            "extended": m.is_extended_id,
            "rtr": m.is_remote_frame,
            "error": m.is_error_frame,
            "fd": m.is_fd,
            "brs": m.bitrate_switch,
            "esi": m.error_state_indicator,
            "data": bytes(m.data).hex().upper(),
        })
    json.dump(frames, open(out, "w"))


if __name__ == "__main__":
    main()
