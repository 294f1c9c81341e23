"""Reads every message of an MCAP file with the official Python reader and validates each
JSON message against its channel's JSON schema; protobuf messages are decoded through the
file's own descriptors by mcap-protobuf-support. Prints a JSON summary; exits 1 on failure."""
import json
import sys

import jsonschema
from mcap.reader import make_reader
from railfuse_messages import json_form


def main(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        validators = {}
        counts = {}
        protobuf = {}
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "protobuf":
                assert schema.encoding == "protobuf", f"{channel.topic}: schema encoding {schema.encoding}"
                doc = json_form(schema, channel, message.data)
                t = doc.get("timestamp")
                stamp = doc["stamp_ns"] if "stamp_ns" in doc else t and t["sec"] * 10**9 + t["nsec"]
                assert message.publish_time == (stamp or message.publish_time), f"{channel.topic}: publish_time != stamp_ns"
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
                protobuf[channel.topic] = schema.name
                continue
            if channel.id not in validators:
                assert schema.encoding == "jsonschema", f"{channel.topic}: schema encoding {schema.encoding}"
                assert channel.message_encoding == "json", f"{channel.topic}: message encoding"
                s = json.loads(schema.data)
                jsonschema.Draft202012Validator.check_schema(s)
                validators[channel.id] = jsonschema.Draft202012Validator(s)
            doc = json.loads(message.data)
            errors = list(validators[channel.id].iter_errors(doc))
            if errors:
                print(f"{path}: {channel.topic} at {message.log_time}: {errors[0].message}", file=sys.stderr)
                sys.exit(1)
            assert message.publish_time == doc.get("stamp_ns", message.publish_time), f"{channel.topic}: publish_time != stamp_ns"
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        stats = summary.statistics
        total = sum(counts.values())
        assert stats.message_count == total, f"summary says {stats.message_count}, read {total}"
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        print(json.dumps({"messages": total, "topics": counts, "chunks": len(summary.chunk_indexes),
                          "compression": sorted({c.compression for c in summary.chunk_indexes}),
                          "metadata": sorted(metadata), "protobuf": protobuf}))


if __name__ == "__main__":
    main(sys.argv[1])
