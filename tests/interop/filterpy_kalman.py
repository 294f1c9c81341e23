"""Re-runs each railfuse Kalman pipeline of a fused MCAP file with filterpy's KalmanFilter on
the same measurements (taken from the pipeline's diagnostics channel, in the order the filter
processed them) and compares every state and covariance; where the pipeline has an RTS
smoother, runs filterpy's rts_smoother over the same epochs and compares every smoothed state
and covariance too. Chainage-bias sensor states (a Gauss-Markov bias b of a position sensor,
z = s + b + v) are appended to the state here as railfuse appends them, and their value and
standard deviation compared too; pipelines with other sensor states are not compared.
Exits 1 on a mismatch."""
import json
import sys
import tomllib

import numpy as np
from filterpy.kalman import KalmanFilter, rts_smoother
from mcap.reader import make_reader
from railfuse_messages import json_form

POSITION_SCHEMAS = {"railfuse.LoopPosition", "railfuse.BalisePassage"}


def model(motion, dt, biases):
    n = 3 + len(biases)
    F, Q = np.eye(n), np.zeros((n, n))
    F[:3, :3] = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    if "jerk_psd" in motion:
        q = motion["jerk_psd"]
        Q[:3, :3] = q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2], [dt**3 / 6, dt**2 / 2, dt]])
    else:
        g = np.array([[dt**3 / 6], [dt**2 / 2], [dt]])
        Q[:3, :3] = motion["jerk_variance"] * g @ g.T
    for k, b in enumerate(biases):
        F[3 + k, 3 + k] = np.exp(-dt / b["time_constant_s"])
        Q[3 + k, 3 + k] = b["std_m"] ** 2 * -np.expm1(-2 * dt / b["time_constant_s"])
    return F, Q


def chainage_biases(cfg):
    """The pipeline's chainage-bias states in state order as (topic, table); None when it has
    sensor states this script does not model."""
    out = []
    for sensor in cfg.get("sensor", []):
        if "scale_factor" in sensor or "acceleration_bias" in sensor:
            return None
        if "chainage_bias" in sensor:
            out.append((sensor["topic"], sensor["chainage_bias"]))
    return out


def full_state(s, n):
    """A railfuse state as [s, v, a, biases…] and its compared numbers: the motion states, their
    3x3 covariance and each bias's value and standard deviation."""
    return [s["chainage_m"], s["speed_mps"], s["acceleration_mps2"]] + s["covariance"] + [x for b in s.get("sensor_states", []) for x in (b["value"], b["std"])]


def compared(x, P, n):
    return list(x.ravel()[:3]) + list(P[:3, :3].ravel()) + [v for k in range(3, n) for v in (x.ravel()[k], np.sqrt(P[k, k]))]


def read_fused(path):
    """The pipelines' configurations, each topic's schema name, and per pipeline its states,
    diagnostics and smoothed states, from a fused log."""
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
        for schema, channel, message in reader.iter_messages():
            parts = channel.topic.split("/")
            kinds = {"state": states, "diagnostics": diags, "smoothed": smoothed}
            if len(parts) == 4 and parts[1] == "fused" and parts[3] in kinds:
                d = json_form(schema, channel, message.data)
                kinds[parts[3]].setdefault(parts[2], []).append(d)
    return configs, schema_of, states, diags, smoothed


def main(path, tol):
    configs, schema_of, states, diags, smoothed = read_fused(path)
    assert configs, "no railfuse.pipeline metadata"
    worst = 0.0
    compared_updates = 0
    resets_compared = 0
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
    kalman = {n: c for n, c in configs.items() if c["filter"] == "kalman" and "output_rate_hz" not in c and chainage_biases(c) is not None}
    for name, cfg in kalman.items():
        biased = chainage_biases(cfg)
        bias_index = {topic: 3 + k for k, (topic, _) in enumerate(biased)}
        tables = [b for _, b in biased]
        n = 3 + len(biased)
        # The filter advances to every measurement that reached the gate, used or not.
        reached = [d for d in diags[name] if d["decision"] in ("accepted", "rejected_gate", "reset_to_fix")]
        st = states[name]
        assert sum(d["decision"] != "rejected_gate" for d in reached) == len(st), f"{name}: accepted measurements and states differ"
        kf = KalmanFilter(dim_x=n, dim_z=1)
        first = st[0]
        kf.x = np.array([[first["chainage_m"]], [first["speed_mps"]], [first["acceleration_mps2"]]] + [[b["value"]] for b in first.get("sensor_states", [])])
        kf.P = np.zeros((n, n))
        kf.P[:3, :3] = np.array(first["covariance"]).reshape(3, 3)
        for k, b in enumerate(first.get("sensor_states", [])):
            kf.P[3 + k, 3 + k] = b["std"] ** 2
        t = first["stamp_ns"]
        states_left = iter(st[1:])
        # Epochs for the smoother: every filter time, with its filtered estimate and the
        # transition into it.
        ep_x, ep_p, ep_f, ep_q, ep_t = [kf.x.copy()], [kf.P.copy()], [np.eye(n)], [np.zeros((n, n))], [t]
        for d in reached[1:]:
            dt = (d["stamp_ns"] - t) / 1e9
            if dt > 0:
                kf.F, kf.Q = model(cfg["motion"], dt, tables)
                kf.predict()
                ep_x.append(None), ep_p.append(None), ep_f.append(kf.F.copy()), ep_q.append(kf.Q.copy()), ep_t.append(d["stamp_ns"])
            t = d["stamp_ns"]
            if d["decision"] == "rejected_gate":
                ep_x[-1], ep_p[-1] = kf.x.copy(), kf.P.copy()
                continue
            s = next(states_left)
            H = np.zeros((1, n))
            if schema_of[d["source"]] in POSITION_SCHEMAS:
                H[0, 0] = 1.0
                if d["source"] in bias_index:
                    H[0, bias_index[d["source"]]] = 1.0
            else:
                H[0, 1] = 1.0
            z, r = d["measurement"], d["measurement_variance"]
            if d["decision"] == "reset_to_fix":
                # The position reset to the fix from the prediction, as PX4 resets: chainage
                # onto the fix, its variance the fix's, uncorrelated; the smoother is told the
                # jump was unpredictable (a prior of 1e6 times its scale on chainage).
                nu = z - (H @ kf.x)[0, 0]
                ep_q[-1] = ep_q[-1].copy()
                ep_q[-1][0, 0] += 1e6 * (nu * nu + kf.P[0, 0] + r)
                kf.x[0, 0] += nu / H[0, 0]
                kf.P[0, :] = 0.0
                kf.P[:, 0] = 0.0
                kf.P[0, 0] = r / H[0, 0] ** 2
                resets_compared += 1
            else:
                kf.H = H
                kf.R = np.array([[r]])
                kf.update(np.array([[z]]))
            check(name, d["stamp_ns"], full_state(s, n), compared(kf.x, kf.P, n))
            ep_x[-1], ep_p[-1] = kf.x.copy(), kf.P.copy()
            compared_updates += 1
        if cfg.get("smoother"):
            sm = smoothed.get(name, [])
            assert len(sm) == len(ep_x), f"{name}: {len(sm)} smoothed states for {len(ep_x)} epochs"
            # filterpy's Fs[k], Qs[k] take epoch k to k+1.
            fs, qs = np.array(ep_f[1:] + [np.eye(n)]), np.array(ep_q[1:] + [np.zeros((n, n))])
            xs, ps, _, _ = rts_smoother(np.array([x.ravel() for x in ep_x]), np.array(ep_p), fs, qs)
            for k, s in enumerate(sm):
                assert s["stamp_ns"] == ep_t[k], f"{name}: smoothed epoch {k} at {s['stamp_ns']}, expected {ep_t[k]}"
                check(name + " (smoothed)", s["stamp_ns"], full_state(s, n), compared(xs[k], ps[k], n))
                smoothed_compared += 1
    print(json.dumps({"pipelines": sorted(kalman), "not_compared": sorted(set(configs) - set(kalman)), "updates_compared": compared_updates, "resets_compared": resets_compared, "smoothed_compared": smoothed_compared, "worst_relative_difference": worst}))


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 1e-9)
