"""Re-runs each railfuse Kalman pipeline of a fused MCAP file with filterpy's KalmanFilter on
the same measurements (taken from the pipeline's diagnostics channel, in the order the filter
processed them) and compares every state and covariance; where the pipeline has an RTS
smoother, runs filterpy's rts_smoother over the same epochs and compares every smoothed state
and covariance too. Exits 1 on a mismatch."""
import json
import sys
import tomllib

import numpy as np
from filterpy.kalman import KalmanFilter, rts_smoother
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
        states, diags, smoothed = {}, {}, {}
        for _, channel, message in reader.iter_messages():
            parts = channel.topic.split("/")
            if len(parts) == 4 and parts[1] == "fused":
                d = json.loads(message.data)
                {"state": states, "diagnostics": diags, "smoothed": smoothed}[parts[3]].setdefault(parts[2], []).append(d)
    assert configs, "no railfuse.pipeline metadata"
    worst = 0.0
    compared = 0
    smoothed_compared = 0

    def check(name, stamp, ours, theirs):
        nonlocal worst
        for a, b in zip(ours, theirs):
            err = abs(a - b) / max(1.0, abs(b))
            worst = max(worst, err)
            if err > tol:
                print(f"{path}: pipeline {name} at {stamp}: railfuse {a!r} filterpy {b!r}", file=sys.stderr)
                sys.exit(1)

    # Kalman pipelines that emit a state per accepted measurement (output ticks would need the
    # tick grid replayed here too).
    kalman = {n: c for n, c in configs.items() if c["filter"] == "kalman" and "output_rate_hz" not in c}
    for name, cfg in kalman.items():
        # The filter advances to every measurement that reached the gate, used or not.
        reached = [d for d in diags[name] if d["decision"] in ("accepted", "rejected_gate")]
        st = states[name]
        assert sum(d["decision"] == "accepted" for d in reached) == len(st), f"{name}: accepted measurements and states differ"
        kf = KalmanFilter(dim_x=3, dim_z=1)
        kf.x = np.array([[st[0]["chainage_m"]], [st[0]["speed_mps"]], [st[0]["acceleration_mps2"]]])
        kf.P = np.array(st[0]["covariance"]).reshape(3, 3)
        t = st[0]["stamp_ns"]
        states_left = iter(st[1:])
        # Epochs for the smoother: every filter time, with its filtered estimate and the
        # transition into it.
        ep_x, ep_p, ep_f, ep_q, ep_t = [kf.x.copy()], [kf.P.copy()], [np.eye(3)], [np.zeros((3, 3))], [t]
        for d in reached[1:]:
            dt = (d["stamp_ns"] - t) / 1e9
            if dt > 0:
                kf.F, kf.Q = model(cfg["motion"], dt)
                kf.predict()
                ep_x.append(None), ep_p.append(None), ep_f.append(kf.F.copy()), ep_q.append(kf.Q.copy()), ep_t.append(d["stamp_ns"])
            t = d["stamp_ns"]
            if d["decision"] != "accepted":
                ep_x[-1], ep_p[-1] = kf.x.copy(), kf.P.copy()
                continue
            s = next(states_left)
            kf.H = np.array([[1.0, 0.0, 0.0]]) if schema_of[d["source"]] in POSITION_SCHEMAS else np.array([[0.0, 1.0, 0.0]])
            kf.R = np.array([[d["measurement_variance"]]])
            kf.update(np.array([[d["measurement"]]]))
            ours = [s["chainage_m"], s["speed_mps"], s["acceleration_mps2"]] + s["covariance"]
            check(name, d["stamp_ns"], ours, list(kf.x.ravel()) + list(kf.P.ravel()))
            ep_x[-1], ep_p[-1] = kf.x.copy(), kf.P.copy()
            compared += 1
        if cfg.get("smoother"):
            sm = smoothed.get(name, [])
            assert len(sm) == len(ep_x), f"{name}: {len(sm)} smoothed states for {len(ep_x)} epochs"
            # filterpy's Fs[k], Qs[k] take epoch k to k+1.
            fs, qs = np.array(ep_f[1:] + [np.eye(3)]), np.array(ep_q[1:] + [np.zeros((3, 3))])
            xs, ps, _, _ = rts_smoother(np.array([x.ravel() for x in ep_x]), np.array(ep_p), fs, qs)
            for k, s in enumerate(sm):
                assert s["stamp_ns"] == ep_t[k], f"{name}: smoothed epoch {k} at {s['stamp_ns']}, expected {ep_t[k]}"
                ours = [s["chainage_m"], s["speed_mps"], s["acceleration_mps2"]] + s["covariance"]
                check(name + " (smoothed)", s["stamp_ns"], ours, list(xs[k]) + list(ps[k].ravel()))
                smoothed_compared += 1
    print(json.dumps({"pipelines": sorted(kalman), "not_compared": sorted(set(configs) - set(kalman)), "updates_compared": compared, "smoothed_compared": smoothed_compared, "worst_relative_difference": worst}))


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 1e-9)
