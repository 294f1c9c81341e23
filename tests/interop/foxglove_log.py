"""A railfuse log as a Foxglove SDK log would carry the same GNSS receiver: /gnss/fix rewritten
by the official Python writer as /gps in foxglove.LocationFix, the other channels as they are.
In JSON by default; with --protobuf in protobuf, the schema registered by
mcap-protobuf-support from the foxglove-schemas-protobuf classes (a FileDescriptorSet, as the
Foxglove SDK writes it). --bad-schema replaces that schema's data by bytes that do not parse.

    foxglove_log.py IN.mcap OUT.mcap [--protobuf [--bad-schema]]"""

import json
import sys

from mcap.reader import make_reader
from railfuse_messages import json_form
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


def json_fix(fix):
    return json.dumps(fix).encode()


def protobuf_fix(fix):
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix

    m = LocationFix(
        frame_id=fix["frame_id"],
        latitude=fix["latitude"],
        longitude=fix["longitude"],
        altitude=fix["altitude"],
        position_covariance=fix["position_covariance"],
        position_covariance_type=fix["position_covariance_type"],
    )
    m.timestamp.seconds = fix["timestamp"]["sec"]
    m.timestamp.nanos = fix["timestamp"]["nsec"]
    return m.SerializeToString()


def main():
    protobuf = "--protobuf" in sys.argv
    bad_schema = "--bad-schema" in sys.argv
    with open(sys.argv[1], "rb") as f, open(sys.argv[2], "wb") as out:
        reader = make_reader(f)
        w = Writer(out)
        w.start()
        summary = reader.get_summary()
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        if protobuf:
            from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
            from mcap_protobuf.schema import build_file_descriptor_set

            data = build_file_descriptor_set(LocationFix).SerializeToString()
            fix_schema = w.register_schema("foxglove.LocationFix", "protobuf", b"\xff\x07not" if bad_schema else data)
            fix_encoding, encode = "protobuf", protobuf_fix
        else:
            fix_schema = w.register_schema("foxglove.LocationFix", "jsonschema", json.dumps(LOCATION_FIX_SCHEMA).encode())
            fix_encoding, encode = "json", json_fix
        channels, gps = {}, None
        for cid, c in summary.channels.items():
            if c.topic == "/gnss/fix":
                gps = cid
                channels[cid] = w.register_channel("/gps", fix_encoding, fix_schema)
            elif not c.topic.startswith("/foxglove"):
                channels[cid] = w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id], dict(c.metadata))
        n = 0
        for s, c, m in reader.iter_messages():
            if c.id not in channels:
                continue
            data = m.data
            if c.id == gps:
                d = json_form(s, c, data)
                if d.get("latitude_deg") is None:
                    continue  # a LocationFix is a position: no fix, no message
                cov = d.get("position_covariance_enu_m2")
                data = encode({
                    "timestamp": {"sec": d["stamp_ns"] // 10**9, "nsec": d["stamp_ns"] % 10**9},
                    "frame_id": "gps",
                    "latitude": d["latitude_deg"],
                    "longitude": d["longitude_deg"],
                    "altitude": d.get("altitude_m") or 0.0,
                    "position_covariance": cov or [0.0] * 9,
                    "position_covariance_type": 3 if cov else 0,
                })
                n += 1
            w.add_message(channels[c.id], m.log_time, data, m.publish_time)
        w.finish()
    print(json.dumps({"location_fixes": n}))


if __name__ == "__main__":
    main()
