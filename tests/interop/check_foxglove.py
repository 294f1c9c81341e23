"""Validates the Foxglove twins of an MCAP file against Foxglove's published JSON schemas (the
@foxglove/schemas npm package, pinned, in the directory given): a JSON foxglove.* channel's
schema must be the package's own; a protobuf one's messages are decoded with Foxglove's own
generated classes (foxglove-schemas-protobuf), must read the same through the file's own
descriptors, and must then validate against the JSON schema. Prints a JSON summary; exits 1
on failure."""
import json
import sys
from pathlib import Path

import jsonschema
from foxglove_schemas_protobuf.GeoJSON_pb2 import GeoJSON
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.Log_pb2 import Log
from mcap.reader import make_reader
from railfuse_messages import as_json_form, json_form

OFFICIAL = {"foxglove.LocationFix": LocationFix, "foxglove.GeoJSON": GeoJSON, "foxglove.Log": Log}


def main(path, schema_dir):
    published = {}
    for f in Path(schema_dir).glob("*.json"):
        s = json.loads(f.read_text())
        published[s["title"]] = s
    counts, encodings, geojson = {}, {}, None
    with open(path, "rb") as f:
        validators = {}
        for schema, channel, message in make_reader(f).iter_messages():
            if not schema.name.startswith("foxglove."):
                continue
            if channel.id not in validators:
                assert schema.name in published, f"{channel.topic}: {schema.name} is not a published schema"
                if channel.message_encoding == "json":
                    assert json.loads(schema.data) == published[schema.name], f"{channel.topic}: the schema differs from the package's"
                validators[channel.id] = jsonschema.Draft202012Validator(published[schema.name])
                encodings[channel.topic] = channel.message_encoding
            if channel.message_encoding == "protobuf":
                doc = as_json_form(OFFICIAL[schema.name].FromString(message.data))
                ours = json_form(schema, channel, message.data)
                assert doc == ours, f"{channel.topic}: Foxglove's classes read {doc}, the file's descriptors {ours}"
            else:
                doc = json.loads(message.data)
            errors = list(validators[channel.id].iter_errors(doc))
            if errors:
                print(f"{path}: {channel.topic} at {message.log_time}: {errors[0].message}", file=sys.stderr)
                sys.exit(1)
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if schema.name == "foxglove.GeoJSON":
                geojson = json.loads(doc["geojson"])
            if schema.name == "foxglove.LocationFix":
                assert -90 <= doc["latitude"] <= 90 and -180 <= doc["longitude"] <= 180, doc
    kinds = sorted({f["geometry"]["type"] for f in geojson["features"]}) if geojson else []
    track = geojson["features"][0]["geometry"]["coordinates"] if geojson else []
    print(json.dumps({"topics": counts, "encodings": encodings, "geojson_type": geojson and geojson["type"],
                      "geometries": kinds, "track_points": len(track)}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
