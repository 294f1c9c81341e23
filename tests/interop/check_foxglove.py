"""Validates the Foxglove twins of an MCAP file against Foxglove's published JSON schemas (the
@foxglove/schemas npm package, pinned, in the directory given): every foxglove.* channel's
schema must be the package's own, and every message must validate against it. Prints a JSON
summary; exits 1 on failure."""
import json
import sys
from pathlib import Path

import jsonschema
from mcap.reader import make_reader


def main(path, schema_dir):
    published = {}
    for f in Path(schema_dir).glob("*.json"):
        s = json.loads(f.read_text())
        published[s["title"]] = s
    counts, geojson = {}, None
    with open(path, "rb") as f:
        validators = {}
        for schema, channel, message in make_reader(f).iter_messages():
            if not schema.name.startswith("foxglove."):
                continue
            if channel.id not in validators:
                assert schema.name in published, f"{channel.topic}: {schema.name} is not a published schema"
                assert json.loads(schema.data) == published[schema.name], f"{channel.topic}: the schema differs from the package's"
                validators[channel.id] = jsonschema.Draft202012Validator(published[schema.name])
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
    print(json.dumps({"topics": counts, "geojson_type": geojson and geojson["type"],
                      "geometries": kinds, "track_points": len(track)}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
