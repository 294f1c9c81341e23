"""railfuse on a local Ray cluster (ray.init(num_cpus=2)): refuse and evaluate as Ray tasks,
and a grid search as a Ray Tune experiment beside the same search run locally. Usage:
ray_fleet.py DIR CONFIG LOG...; prints a JSON summary."""
import json
import os
import sys

import ray

import railfuse
import railfuse.ray

out_dir, config, *logs = sys.argv[1:]
# Ray Tune prints its progress on stdout: keep stdout for the summary.
real_stdout = sys.stdout
sys.stdout = sys.stderr
ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
summary = {}

reports = railfuse.ray.refuse_many(
    logs, config, [os.path.join(out_dir, f"ray{i}.fused.mcap") for i in range(len(logs))]
)
summary["refuse_rmse"] = [r["eval"]["pipelines"][0]["position_error_m"]["rmse"] for r in reports]
evals = railfuse.ray.evaluate_many([os.path.join(out_dir, f"ray{i}.fused.mcap") for i in range(len(logs))])
summary["evaluate_rmse"] = [e["pipelines"][0]["position_error_m"]["rmse"] for e in evals]
# The second door beside Ray's: the package's own refuse of the first log.
railfuse.refuse(logs[0], config, os.path.join(out_dir, "py0.fused.mcap"))

params = ["motion.jerk_psd=0.001..10,steps=3", "sensor[/radar/speed].variance=1e-4..1,steps=3"]
local = railfuse.tune(logs, config, "kalman", params=params, optimiser="grid")
summary["local"] = {p["name"]: p["after"] for p in local["report"]["params"]}
summary["local_objective"] = local["report"]["objective_after"]
remote = railfuse.ray.tune(
    logs, config, "kalman", params=params, storage_path=os.path.join(out_dir, "ray-results")
)
summary["ray"] = remote["values"]
summary["ray_objective"] = remote["objective"]
summary["trials"] = remote["trials"]
try:
    railfuse.ray.tune(
        [os.path.join(out_dir, "missing.mcap")], config, "kalman", params=params,
        storage_path=os.path.join(out_dir, "ray-results"),
    )
    summary["missing_log"] = None
except railfuse.RailfuseError as e:
    summary["missing_log"] = str(e)
ray.shutdown()
print(json.dumps(summary), file=real_stdout)
