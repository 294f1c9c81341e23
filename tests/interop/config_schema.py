"""Validate every sample configuration against railfuse's configuration schema with the
`jsonschema` package (a validator not written here), and show that the schema refuses a
misspelt key, a key of another kind's table and a wrong type.

usage: config_schema.py SCHEMA.json SAMPLES_DIR
"""
import copy
import json
import pathlib
import sys
import tomllib

import jsonschema

schema = json.loads(pathlib.Path(sys.argv[1]).read_text())
validator = jsonschema.Draft202012Validator(schema)
jsonschema.Draft202012Validator.check_schema(schema)

configs = sorted(pathlib.Path(sys.argv[2]).glob("*.toml"))
assert len(configs) >= 8, configs
kinds_seen = set()
for path in configs:
    doc = tomllib.loads(path.read_text())
    errors = sorted(validator.iter_errors(doc), key=str)
    assert not errors, f"{path.name}: {errors[0].message} at {list(errors[0].path)}"
    for p in doc["pipeline"]:
        kinds_seen.add(p["filter"])
print(f"{len(configs)} sample configs valid; filters {sorted(kinds_seen)}")
assert {"kalman", "ekf_safety", "gnss_ins", "eddy_current"} <= kinds_seen, kinds_seen

base = tomllib.loads((pathlib.Path(sys.argv[2]) / "kalman.toml").read_text())
bad = copy.deepcopy(base)
bad["pipeline"][0]["reorder_windw_s"] = 1.0
assert not validator.is_valid(bad), "a misspelt key passes"
bad = copy.deepcopy(base)
bad["pipeline"][0]["sensor"][0]["gate_nis"] = "large"
assert not validator.is_valid(bad), "a string gate passes"
bad = copy.deepcopy(base)
bad["pipeline"][0]["safety"] = {"no_such_threshold": 1}
assert not validator.is_valid(bad), "an unknown key in [pipeline.safety] passes"
print("misspelt key, wrong type and unknown kind setting refused")
