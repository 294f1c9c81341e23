"""The railfuse Python package, as a notebook user calls it: simulate, refuse, evaluate, read,
tune, and errors. Usage: python_package.py DIR CONFIG CLI_FUSED RAW; prints a JSON summary for
the Rust test to check (it compares the files byte for byte itself)."""
import json
import os
import sys

import pyarrow as pa

import railfuse

out_dir, config, cli_fused, raw = sys.argv[1:5]
summary = {}

summary["simulate"] = railfuse.simulate(os.path.join(out_dir, "py.mcap"), seed=4, duration_s=30)
py_fused = os.path.join(out_dir, "py.fused.mcap")
refused = railfuse.refuse(raw, config, py_fused)
summary["refuse_rmse"] = refused["eval"]["pipelines"][0]["position_error_m"]["rmse"]
summary["evaluate_rmse"] = railfuse.evaluate(py_fused)["pipelines"][0]["position_error_m"]["rmse"]
summary["outages"] = railfuse.evaluate(
    py_fused, withhold="/gnss/fix", outages="5:every=10:from=5"
)["pipelines"][0]["outages"]
summary["gnss_all"] = railfuse.evaluate(
    py_fused, reference="/gnss/fix", reference_quality="all"
)["pipelines"][0]["reference_fixes"]

states = railfuse.read(py_fused, "/fused/kalman/state")
assert isinstance(states, pa.Table)
summary["state_rows"] = states.num_rows
summary["pandas_rows"] = len(states.to_pandas())
summary["state_columns"] = states.column_names
summary["first_chainage"] = states.column("chainage_m")[0].as_py()
summary["covariance_type"] = str(states.schema.field("covariance").type)
summary["radar_rows"] = railfuse.read(raw, "/radar/speed").num_rows
# Other tools' files are runs to the package too: a GPX ride, an MDF 4 bus log.
here = os.path.dirname(os.path.abspath(__file__))
ride = railfuse.read(os.path.join(here, "../../samples/ride.gpx"), "/gnss/fix")
summary["gpx_rows"] = ride.num_rows
summary["gpx_first_latitude"] = ride.column("latitude_deg")[0].as_py()
logger = railfuse.read(
    os.path.join(here, "../../samples/loggers/gnss-logger.csv"),
    "/gnss/fix",
    mapping=os.path.join(here, "../../samples/loggers/gnss-logger.toml"),
)
summary["csv_rows"] = logger.num_rows
mf4 = os.path.join(here, "../fuzz/corpus/mdf4/cut-sorted.mf4")
summary["mdf4_frames"] = railfuse.read(mf4, "/can/CAN2/frames").num_rows

errors = {}
for name, call in {
    "missing_config": lambda: railfuse.refuse(raw, os.path.join(out_dir, "nope.toml"), py_fused),
    "missing_topic": lambda: railfuse.read(raw, "/nope"),
    "unknown_param": lambda: railfuse.Tuner(
        [raw], config, "kalman", params={"motion.jerk_pds": (0.01, 1)}
    ),
    "unknown_scenario": lambda: railfuse.simulate(os.path.join(out_dir, "x.mcap"), "nope"),
    "unknown_reference": lambda: railfuse.evaluate(py_fused, reference="/nothere"),
    "withhold_unfused": lambda: railfuse.refuse(
        raw, config, py_fused + ".w", withhold="/gnss/fix", outages="10"
    ),
    "unknown_quality": lambda: railfuse.evaluate(
        py_fused, reference="/gnss/fix", reference_quality="rtk"
    ),
}.items():
    try:
        call()
        errors[name] = None
    except railfuse.RailfuseError as e:
        errors[name] = str(e)
summary["errors"] = errors

tuned = railfuse.tune(
    [raw],
    config,
    "kalman",
    output=os.path.join(out_dir, "py-tuned.toml"),
    reference="/truth",
    params={"motion.jerk_psd": (0.001, 10)},
    optimiser="grid",
)
summary["tuned"] = {p["name"]: p["after"] for p in tuned["report"]["params"]}
summary["tuned_objective"] = tuned["report"]["objective_after"]
print(json.dumps(summary))
