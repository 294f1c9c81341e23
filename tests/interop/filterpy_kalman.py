"""Re-runs each railfuse Kalman pipeline of a fused MCAP file with filterpy's KalmanFilter on
the same measurements (taken from the pipeline's diagnostics channel, in the order the filter
processed them) and compares every state and covariance. Exits 1 on a mismatch."""
import json
import sys
import tomllib

import numpy as np
from filterpy.kalman import KalmanFilter
from mcap.reader import make_reader

POSITION_SCHEMAS = {"railfuse.LoopPosition", "railfuse.BalisePassage"}


def model(motion, dt):
    F = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    if "jerk_psd" in motion:
        q = motion["jerk_psd"]
        Q = q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2], [dt**3 / 6, dt**2 / 2, dt]])
    else:
        g = np.array([[dt**3 / 6], [dt**2 / 2], [dt]])
        Q = motion["jerk_variance"] * g @ g.T
    return F, Q


def main(path, tol):
    with open(path, "rb") as f:
        reader = make_reader(f)
        configs = {}
        for m in reader.iter_metadata():
            if m.name == "railfuse.pipeline":
                configs[m.metadata["pipeline"]] = tomllib.loads(m.metadata["config_toml"])["pipeline"][0]
        schema_of = {}
        summary = reader.get_summary()
        for ch in summary.channels.values():
            schema_of[ch.topic] = summary.schemas[ch.schema_id].name
        states, diags = {}, {}
        for _, channel, message in reader.iter_messages():
            parts = channel.topic.split("/")
            if len(parts) == 4 and parts[1] == "fused":
                d = json.loads(message.data)
                (states if parts[3] == "state" else diags).setdefault(parts[2], []).append(d)
    assert configs, "no railfuse.pipeline metadata"
    worst = 0.0
    compared = 0
    for name, cfg in configs.items():
        # The filter advances to every measurement that reached the gate, used or not.
        reached = [d for d in diags[name] if d["decision"] in ("accepted", "rejected_gate")]
        st = states[name]
        assert sum(d["decision"] == "accepted" for d in reached) == len(st), f"{name}: accepted measurements and states differ"
        kf = KalmanFilter(dim_x=3, dim_z=1)
        kf.x = np.array([[st[0]["chainage_m"]], [st[0]["speed_mps"]], [st[0]["acceleration_mps2"]]])
        kf.P = np.array(st[0]["covariance"]).reshape(3, 3)
        t = st[0]["stamp_ns"]
        states_left = iter(st[1:])
        for d in reached[1:]:
            dt = (d["stamp_ns"] - t) / 1e9
            if dt > 0:
                kf.F, kf.Q = model(cfg["motion"], dt)
                kf.predict()
            t = d["stamp_ns"]
            if d["decision"] != "accepted":
                continue
            s = next(states_left)
            kf.H = np.array([[1.0, 0.0, 0.0]]) if schema_of[d["source"]] in POSITION_SCHEMAS else np.array([[0.0, 1.0, 0.0]])
            kf.R = np.array([[d["measurement_variance"]]])
            kf.update(np.array([[d["measurement"]]]))
            ours = np.array([s["chainage_m"], s["speed_mps"], s["acceleration_mps2"]])
            theirs = kf.x.ravel()
            for a, b in list(zip(ours, theirs)) + list(zip(s["covariance"], kf.P.ravel())):
                err = abs(a - b) / max(1.0, abs(b))
                worst = max(worst, err)
                if err > tol:
                    print(f"{path}: pipeline {name} at {d['stamp_ns']}: railfuse {a!r} filterpy {b!r}", file=sys.stderr)
                    sys.exit(1)
            compared += 1
    print(json.dumps({"pipelines": sorted(configs), "updates_compared": compared, "worst_relative_difference": worst}))


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 1e-9)
