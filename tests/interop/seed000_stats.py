"""Checks statistically that seed000 logs carry source 000's noise: loop position variance,
radar speed variance and process (jerk) variance, against the truth in the same files.
Each sample variance must lie within 4 standard errors of the stated value."""
import json
import sys

from mcap.reader import make_reader
from railfuse_messages import json_form

STATED = {"loop": 0.01, "radar": 0.01, "jerk": 0.001}


def residuals(path):
    truth, loop, radar = {}, [], []
    with open(path, "rb") as f:
        for schema, ch, m in make_reader(f).iter_messages(topics=["/truth", "/loop/position", "/radar/speed"]):
            d = json_form(schema, ch, m.data)
            if ch.topic == "/truth":
                truth[d["stamp_ns"]] = d
            elif ch.topic == "/loop/position":
                loop.append(d)
            else:
                radar.append(d)
    out = {"loop": [], "radar": [], "jerk": []}
    for d in loop:
        out["loop"].append(d["chainage_m"] - truth[d["stamp_ns"]]["chainage_m"])
    for d in radar:
        out["radar"].append(d["speed_mps"] - truth[d["stamp_ns"]]["speed_mps"])
    # Acceleration at the sample instants (1 s apart): a_k − a_{k−1} = T·w_k with T = 1.
    samples = [truth[d["stamp_ns"]]["acceleration_mps2"] for d in loop]
    out["jerk"] = [b - a for a, b in zip(samples, samples[1:])]
    return out


def main(paths):
    pooled = {"loop": [], "radar": [], "jerk": []}
    for p in paths:
        for k, v in residuals(p).items():
            pooled[k] += v
    report = {}
    ok = True
    for k, xs in pooled.items():
        n = len(xs)
        mean = sum(xs) / n
        var = sum((x - mean) ** 2 for x in xs) / (n - 1)
        se = STATED[k] * (2.0 / (n - 1)) ** 0.5
        z = (var - STATED[k]) / se
        report[k] = {"n": n, "variance": var, "stated": STATED[k], "z": z, "mean": mean}
        ok &= abs(z) < 4.0 and abs(mean) < 4.0 * (STATED[k] / n) ** 0.5
    print(json.dumps(report))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main(sys.argv[1:])
