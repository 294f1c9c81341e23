"""A railfuse log as a Foxglove SDK log would carry the same GNSS receiver: /gnss/fix rewritten
by the official Python writer as /gps in foxglove.LocationFix (JSON), the other channels as
they are.

    foxglove_log.py IN.mcap OUT.mcap"""

import json
import sys

from mcap.reader import make_reader
from mcap.writer import Writer

LOCATION_FIX_SCHEMA = {
    "type": "object",
    "properties": {
        "timestamp": {"type": "object"},
        "frame_id": {"type": "string"},
        "latitude": {"type": "number"},
        "longitude": {"type": "number"},
        "altitude": {"type": "number"},
        "position_covariance": {"type": "array"},
        "position_covariance_type": {"type": "integer"},
    },
}


def main():
    with open(sys.argv[1], "rb") as f, open(sys.argv[2], "wb") as out:
        reader = make_reader(f)
        w = Writer(out)
        w.start()
        summary = reader.get_summary()
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        fix_schema = w.register_schema("foxglove.LocationFix", "jsonschema", json.dumps(LOCATION_FIX_SCHEMA).encode())
        channels, gps = {}, None
        for cid, c in summary.channels.items():
            if c.topic == "/gnss/fix":
                gps = cid
                channels[cid] = w.register_channel("/gps", "json", fix_schema)
            elif not c.topic.startswith("/foxglove"):
                channels[cid] = w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id], dict(c.metadata))
        n = 0
        for _, c, m in reader.iter_messages():
            if c.id not in channels:
                continue
            data = m.data
            if c.id == gps:
                d = json.loads(data)
                if d.get("latitude_deg") is None:
                    continue  # a LocationFix is a position: no fix, no message
                cov = d.get("position_covariance_enu_m2")
                data = json.dumps({
                    "timestamp": {"sec": d["stamp_ns"] // 10**9, "nsec": d["stamp_ns"] % 10**9},
                    "frame_id": "gps",
                    "latitude": d["latitude_deg"],
                    "longitude": d["longitude_deg"],
                    "altitude": d.get("altitude_m") or 0.0,
                    "position_covariance": cov or [0.0] * 9,
                    "position_covariance_type": 3 if cov else 0,
                }).encode()
                n += 1
            w.add_message(channels[c.id], m.log_time, data, m.publish_time)
        w.finish()
    print(json.dumps({"location_fixes": n}))


if __name__ == "__main__":
    main()
